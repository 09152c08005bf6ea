"""The channel's cheaper paths (issue 37) are exact and give nothing away: ``.npy`` written and read without
numpy's file machinery, numpy scalars as tagged JSON, frames read ahead, and a fair deadline that reads the
kernel's CPU-wait count only when its time is up."""
from __future__ import annotations

import io
import json
import os
import struct
import threading
import time

import numpy as np
import pytest

from autograder.core.session import FairDeadline
from autograder.sandbox.wire import (READ_AHEAD, ChannelTimeout, FrameReader, LentRef, ProtocolError, _npy_array,
                                     _npy_bytes, decode, encode, send_message)
from autograder.sandbox.worker import Lent

ARRAYS = [np.arange(8.0), np.zeros((0, 4)), np.array(True), np.ones(3, np.float32), np.arange(6).reshape(2, 3)[:, ::2],
          np.asfortranarray(np.arange(6).reshape(2, 3)), np.array(3 + 4j), np.ones(4, ">f8"), np.zeros((2,) * 9, np.int8),
          np.arange(5, dtype=np.uint64), np.array(1.5, np.float16), np.ones((1, 2), np.longdouble),
          np.arange(40_000, dtype=np.int32).reshape(200, 200)]


@pytest.mark.parametrize("array", ARRAYS, ids=lambda a: f"{a.dtype}{a.shape}")
def test_npy_blobs_are_what_np_save_writes_and_read_back_exactly(array):
    saved = io.BytesIO()
    np.save(saved, array, allow_pickle=False)
    assert _npy_bytes(array) == saved.getvalue()
    got = _npy_array(bytearray(saved.getvalue()))
    assert got.dtype == array.dtype and got.shape == array.shape and np.array_equal(got, array)
    assert got.flags.writeable


def test_npy_headers_of_another_form_still_go_through_numpys_reader():
    array = np.arange(3.0)
    saved = io.BytesIO()
    np.lib.format.write_array(saved, array, version=(2, 0), allow_pickle=False)
    assert np.array_equal(_npy_array(bytearray(saved.getvalue())), array)
    odd = bytearray(_npy_bytes(array)).replace(b"'fortran_order': False", b"'fortran_order':False ")
    assert np.array_equal(_npy_array(odd), array)


@pytest.mark.parametrize("blob", [
    _npy_bytes(np.arange(3.0))[:-1],                                    # data cut short
    _npy_bytes(np.arange(3.0)).replace(b"'<f8'", b"'<i3'"),             # a dtype numpy does not know
    _npy_bytes(np.arange(3.0)).replace(b"'<f8'", b"'|O8'"),             # objects
    _npy_bytes(np.arange(3.0)).replace(b"(3,)", b"(9,)"),               # shape larger than the data
    b"\x93NUMPY\x01\x00\xff\xff{",                                       # header past the blob's end
])
def test_malformed_npy_blobs_are_protocol_errors(blob):
    with pytest.raises(ProtocolError):
        _npy_array(bytearray(blob))


SCALARS = [np.int64(5), np.int8(-128), np.uint64(2**64 - 1), np.float32(0.1), np.float64(-0.0), np.float64("nan"),
           np.float16(np.inf), np.float64("-inf"), np.bool_(False), np.complex128(1 + 2j), np.longdouble(1.5)]


@pytest.mark.parametrize("value", SCALARS, ids=repr)
def test_numpy_scalars_keep_their_type_and_exact_value(value):
    tree, blobs = encode(value)
    got = decode(json.loads(json.dumps(tree)), [bytearray(b) for b in blobs], lambda i, t: None)
    assert type(got) is type(value)
    assert repr(got) == repr(value)
    if value.dtype.kind in "biuf" and value.dtype.itemsize <= 8:
        assert blobs == [], "a numpy number this small crosses as JSON"


@pytest.mark.parametrize("tree", [{"$npnum": ["object", 1]}, {"$npnum": ["int8", 300]}, {"$npnum": ["uint8", -1]},
                                  {"$npnum": ["int64", 1.5]}, {"$npnum": ["int64", True]}, {"$npnum": ["bool", 1]},
                                  {"$npnum": ["float64", "1e3"]}, {"$npnum": ["float64", [1]]}, {"$npnum": ["int64"]},
                                  {"$npnum": "int64"}, {"$npnum": [["int64"], 1]}])
def test_malformed_numpy_numbers_are_protocol_errors(tree):
    with pytest.raises(ProtocolError):
        decode(tree, [], lambda i, t: None)


def test_read_ahead_keeps_what_follows_for_the_next_messages():
    r, w = os.pipe()
    big = np.arange(3 * READ_AHEAD, dtype=np.uint8).tobytes()
    messages = [({"op": "a", "value": 1}, []), ({"op": "b"}, [b"xyz", b""]), ({"op": "c"}, [big]), ({"op": "d"}, [])]

    def write():
        for header, blobs in messages:
            send_message(w, header, blobs)
    writer = threading.Thread(target=write)
    writer.start()
    reader = FrameReader(r, max_message=4 * READ_AHEAD)
    got = [reader.read_message(timeout=20) for _ in messages]
    writer.join()
    assert [h["op"] for h, _ in got] == ["a", "b", "c", "d"]
    assert got[1][1] == [b"xyz", b""] and got[2][1] == [big] and got[3][1] == []
    os.close(r), os.close(w)


@pytest.mark.parametrize("blocking", [True, False])
def test_a_reader_with_a_deadline_is_not_held_past_it_by_a_steady_drip(blocking):
    r, w = os.pipe()
    os.set_blocking(r, blocking)
    head = json.dumps({"ok": True, "nblobs": 1}).encode()
    data = struct.pack(">I", len(head)) + head + struct.pack(">I", 10_000) + b"x" * 10_000
    stop = threading.Event()

    def drip():
        for i in range(len(data)):
            if stop.is_set():
                return
            os.write(w, data[i:i + 1])
            time.sleep(0.005)
    threading.Thread(target=drip, daemon=True).start()
    start = time.monotonic()
    with pytest.raises(ChannelTimeout):
        FrameReader(r).read_message(deadline=time.monotonic() + 0.5)
    stop.set()
    assert time.monotonic() - start < 2
    time.sleep(0.05)
    os.close(r), os.close(w)


class _Worker:
    """A worker whose run delay grows by ``step`` seconds at every look, counting the looks."""

    def __init__(self, step: float) -> None:
        self.step, self.looks = step, 0

    def cpu_wait(self) -> float:
        self.looks += 1
        return self.looks * self.step


def test_a_fair_deadline_reads_the_cpu_wait_only_when_its_time_is_up():
    worker = _Worker(step=10.0)
    deadline = FairDeadline(0.2, worker, max_credit=0.4)
    assert worker.looks == 1
    for _ in range(1000):
        assert deadline.left() > 0
    assert worker.looks == 1, "the kernel's count was read while time was left anyway"
    time.sleep(0.25)
    left = deadline.left()
    assert worker.looks == 2 and 0.3 < left <= 0.4, "past the plain deadline, the credit was not taken"
    time.sleep(0.4)
    assert deadline.left() <= 0, "the credit grew past its cap"


def test_a_fair_deadline_without_a_wait_count_is_plain_wall_time():
    class Silent:
        looks = 0

        def cpu_wait(self):
            self.looks += 1
            return None
    worker = Silent()
    deadline = FairDeadline(0.05, worker, max_credit=10.0)
    time.sleep(0.08)
    assert deadline.left() < 0 and worker.looks == 1


def test_a_lent_method_is_made_once_and_nothing_else_is_reachable():
    calls = []
    lent = Lent(LentRef(3, "Env", ["duel"], {"n_arms": 4}), lambda id, name, args, kwargs: calls.append((id, name, args)))
    assert lent.duel is lent.duel
    lent.duel(0, 1)
    assert calls == [(3, "duel", (0, 1))] and lent.n_arms == 4
    for name in ("reset", "_P", "__dict__"):
        with pytest.raises(AttributeError):
            getattr(lent, name)
    with pytest.raises(AttributeError):
        lent.duel = None
