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
