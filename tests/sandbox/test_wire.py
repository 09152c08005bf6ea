"""The value format between grader and sandbox: exact round trips, nothing else gets through."""
from __future__ import annotations

import io
import json
import os
import struct

import numpy as np
import pytest
import torch

from autograder.sandbox.wire import (FrameReader, HandleRef, ProtocolError, decode, encode, send_message)


def roundtrip(value, to_handle=None):
    tree, blobs = encode(value, to_handle)
    return decode(json.loads(json.dumps(tree)), blobs, lambda i, t: ("handle", i, t))


@pytest.mark.parametrize("value", [None, True, 3, -2**70, 2.5, float("nan"), float("inf"), "é", [1, [2.0]],
                                   (1, "a"), {"k": (1, 2)}])
def test_plain_values_round_trip_with_their_types(value):
    got = roundtrip(value)
    assert type(got) is type(value)
    assert repr(got) == repr(value)


def test_arrays_scalars_and_tensors_keep_dtype_and_shape():
    arrays = [np.arange(6, dtype=np.int16).reshape(2, 3), np.zeros((0, 4)), np.array(True), np.ones(3, np.float32)]
    for array in arrays:
        got = roundtrip(array)
        assert type(got) is np.ndarray and got.dtype == array.dtype and got.shape == array.shape
        assert np.array_equal(got, array)
    scalar = roundtrip(np.float32(1.5))
    assert type(scalar) is np.float32 and scalar == 1.5
    tensor = roundtrip(torch.arange(4.0, requires_grad=True) * 2)
    assert type(tensor) is torch.Tensor and tensor.dtype == torch.float32 and tensor.tolist() == [0, 2, 4, 6]


def test_objects_outside_the_closed_set_become_handles():
    class AlwaysEqual:
        def __eq__(self, other):
            return True

    class Sub(np.ndarray):
        pass

    refs = []

    def to_handle(obj):
        refs.append(obj)
        return HandleRef(len(refs), type(obj).__name__)

    got = roundtrip([AlwaysEqual(), np.zeros(2).view(Sub), np.array([object()])], to_handle)
    assert [g[0] for g in got] == ["handle"] * 3 and got[0][2] == "AlwaysEqual"


def test_without_a_handle_table_unknown_objects_are_refused():
    with pytest.raises(TypeError, match="cannot send"):
        encode(object())


@pytest.mark.parametrize("tree", [{"$pickle": "x"}, {"$ndarray": 5}, {"$dict": [1]}, {"a": 1}, {"$float": "1e999x"},
                                  {"$npscalar": 0}, {"$bigint": "12ab"}])
def test_malformed_trees_are_protocol_errors(tree):
    blobs = [io.BytesIO().getvalue()]
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3), allow_pickle=False)
    with pytest.raises(ProtocolError):
        decode(tree, [buffer.getvalue()] if tree == {"$npscalar": 0} else blobs, lambda i, t: None)


def test_object_arrays_and_pickles_are_refused():
    buffer = io.BytesIO()
    np.save(buffer, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(ProtocolError):
        decode({"$ndarray": 0}, [buffer.getvalue()], lambda i, t: None)


def test_frames_round_trip_and_garbage_is_rejected():
    r, w = os.pipe()
    send_message(w, {"op": "x", "value": 1}, [b"abc"])
    header, blobs = FrameReader(r).read_message(timeout=1)
    assert header["op"] == "x" and blobs == [b"abc"]
    os.write(w, struct.pack(">I", 5) + b"nojsn")
    with pytest.raises(ProtocolError):
        FrameReader(r).read_message(timeout=1)
    os.write(w, struct.pack(">I", 2**31))
    with pytest.raises(ProtocolError, match="over the limit"):
        FrameReader(r).read_message(timeout=1)
    os.close(w)
    os.close(r)


# ---------------------------------------------------------------- the grader's side of a hostile channel


def _pipe():
    r, w = os.pipe()
    os.set_blocking(w, False)
    return r, w


def test_a_frame_too_big_for_what_is_left_of_the_message_is_refused_before_it_is_read():
    from autograder.sandbox.wire import MAX_HEADER_BYTES

    r, w = _pipe()
    os.write(w, struct.pack(">I", MAX_HEADER_BYTES + 1))  # nothing follows: refusing must not wait for it
    with pytest.raises(ProtocolError, match="header of .* over the limit"):
        FrameReader(r).read_message(timeout=5)
    head = json.dumps({"ok": True, "nblobs": 3}).encode()
    os.write(w, struct.pack(">I", len(head)) + head + struct.pack(">I", 600) + b"x" * 600 + struct.pack(">I", 600))
    with pytest.raises(ProtocolError, match="over the limit"):  # the second blob would pass a 1,000-byte message
        FrameReader(r, max_message=1000).read_message(timeout=5)
    os.close(r), os.close(w)


def test_a_header_of_too_many_values_is_refused_before_it_is_parsed():
    from autograder.sandbox.wire import MAX_HEADER_VALUES

    r, w = os.pipe()
    head = b'{"ok": true, "nblobs": 0, "value": [' + b"[]," * MAX_HEADER_VALUES + b"[]]}"
    reader = FrameReader(r)
    import threading

    writer = threading.Thread(target=os.write, args=(w, struct.pack(">I", len(head)) + head))
    writer.start()
    with pytest.raises(ProtocolError, match="more than"):
        reader.read_message(timeout=10)
    writer.join()
    os.close(r), os.close(w)


def test_a_peer_that_stops_reading_cannot_block_a_write_past_its_deadline():
    import time

    from autograder.sandbox.wire import ChannelTimeout

    r, w = _pipe()
    start = time.monotonic()
    with pytest.raises(ChannelTimeout, match="stopped reading"):
        send_message(w, {"op": "exec", "source": "x" * 1_000_000}, [], deadline=time.monotonic() + 0.5)
    assert time.monotonic() - start < 3
    os.close(r), os.close(w)


def test_a_read_never_waits_past_its_deadline_even_for_a_slow_drip():
    import threading
    import time

    from autograder.sandbox.wire import ChannelTimeout

    r, w = os.pipe()
    head = json.dumps({"ok": True, "nblobs": 0}).encode()
    data = struct.pack(">I", len(head)) + head

    def drip():
        for byte in data:
            try:
                os.write(w, bytes([byte]))
            except OSError:
                return
            time.sleep(0.2)

    threading.Thread(target=drip, daemon=True).start()
    start = time.monotonic()
    with pytest.raises(ChannelTimeout):
        FrameReader(r).read_message(deadline=time.monotonic() + 1.0)
    assert time.monotonic() - start < 2
    os.close(r), os.close(w)


@pytest.mark.parametrize("array", [np.arange(12.0).reshape(3, 4), np.asfortranarray(np.arange(6).reshape(2, 3)),
                                   np.zeros((0, 5), np.float32), np.array(3 + 4j), np.ones(4, ">f8")])
def test_arrays_from_the_channel_are_exact_and_writable(array):
    tree, blobs = encode(array)
    for blob in (blobs[0], bytearray(blobs[0])):  # bytes (the reference's side) or a frame buffer (a worker's)
        got = decode(tree, [blob], lambda i, t: None)
        assert got.shape == array.shape and got.dtype == array.dtype and np.array_equal(got, array)
        assert got.flags.writeable
    blob = bytearray(blobs[0])
    with pytest.raises(ProtocolError, match="size does not match"):
        decode(tree, [blob + b"\0" * 8], lambda i, t: None)
