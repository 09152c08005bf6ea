"""The only format in which values cross between the grader and a sandbox worker.

A message is one frame of UTF-8 JSON followed by the frames of its binary
blobs; every frame is a 4-byte big-endian length and its bytes. Values are a
small closed set: ``None``, ``bool``, ``int``, ``float``, ``str``, lists,
tuples, string-keyed dicts, numpy arrays and scalars (as ``.npy`` with
``allow_pickle=False``), torch tensors (as ``.npy``), *handles* to objects
that stay inside the worker, and *lent* objects: trusted objects that stay in
the grader (an environment whose hidden parameters a stub must learn), whose
named methods the worker calls back through the channel. Decoding builds only those types, so nothing a
student sends can run code or masquerade as another type on the trusted side:
an object whose ``__eq__`` always returns True never leaves the worker.
There is no pickle anywhere in this module.
"""
from __future__ import annotations

import io
import json
import os
import select
import struct
import time
from typing import Any, Callable

import numpy as np

MAX_FRAME = 256 * 1024 * 1024
"""No single frame may exceed this (a value of 256 MB is far beyond any test)."""

MAX_DEPTH = 64
"""Values nest at most this deep: far beyond any test's data, and well inside Python's recursion limit
on both sides (a student's value nested 10,000 deep must fail cleanly, not crash the grader)."""
MAX_BLOBS = 10_000
"""Arrays in one message at most."""
TYPE_NAME_CHARS, QUOTED_CHARS = 100, 80
"""A type name crossing the wire is cut here (a student may name a class anything), and so is the piece of
a malformed value an error message quotes."""
ALLOWED_DTYPE_KINDS = set("biufc")


class ProtocolError(RuntimeError):
    """The peer sent something that is not a well-formed message."""


class ChannelTimeout(TimeoutError):
    """The peer did not answer within the time limit."""


class ChannelClosed(EOFError):
    """The peer closed its end (for a worker: it died)."""


class HandleRef:
    """A reference to an object living in a worker (``id``), with its type name for messages."""

    __slots__ = ("id", "type_name", "text")

    def __init__(self, id: int, type_name: str = "object", text: str = "") -> None:
        self.id, self.type_name, self.text = int(id), str(type_name)[:TYPE_NAME_CHARS], str(text)[:200]

    def __repr__(self) -> str:
        return f"<{self.type_name} in the sandbox #{self.id}>"


class LentRef:
    """A trusted object lent to the worker: its ``id`` in the grader, the ``methods`` the worker may call,
    and ``attrs``, plain values copied when it was sent (``n_arms``, say)."""

    __slots__ = ("id", "type_name", "methods", "attrs")

    def __init__(self, id: int, type_name: str, methods: list[str], attrs: dict[str, Any]) -> None:
        self.id, self.type_name, self.methods, self.attrs = int(id), str(type_name)[:TYPE_NAME_CHARS], list(methods), dict(attrs)


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def _npy_array(blob: bytes) -> np.ndarray:
    try:
        array = np.load(io.BytesIO(blob), allow_pickle=False)
    except Exception as err:  # malformed npy or an object array
        raise ProtocolError(f"bad array data: {err}") from None
    if type(array) is not np.ndarray or array.dtype.kind not in ALLOWED_DTYPE_KINDS:
        raise ProtocolError("arrays must be numeric numpy arrays")
    return array


def encode(value: Any, to_handle: Callable[[Any], HandleRef] | None = None, depth: int = 0) -> tuple[Any, list[bytes]]:
    """``value`` as a JSON-able tree plus blobs; objects outside the closed set go to ``to_handle``."""
    blobs: list[bytes] = []

    def enc(v: Any, d: int) -> Any:
        if d > MAX_DEPTH:
            raise ValueError("value nested too deeply")
        if v is None or type(v) in (bool, str):
            return v
        if type(v) is int:
            return v if abs(v) < 2**63 else {"$bigint": str(v)}
        if type(v) is float:
            return {"$float": repr(v)} if not np.isfinite(v) else v
        if type(v) is list:
            return [enc(x, d + 1) for x in v]
        if type(v) is tuple:
            return {"$tuple": [enc(x, d + 1) for x in v]}
        if type(v) is dict and all(type(k) is str for k in v):
            return {"$dict": {k: enc(x, d + 1) for k, x in v.items()}}
        if type(v) is np.ndarray and v.dtype.kind in ALLOWED_DTYPE_KINDS:
            blobs.append(_npy_bytes(v))
            return {"$ndarray": len(blobs) - 1}
        if isinstance(v, np.generic) and type(v).__module__ == "numpy" and v.dtype.kind in ALLOWED_DTYPE_KINDS:
            blobs.append(_npy_bytes(np.asarray(v)))
            return {"$npscalar": len(blobs) - 1}
        if type(v) is HandleRef:
            return {"$handle": v.id}
        if _is_plain_tensor(v):
            blobs.append(_npy_bytes(v.detach().cpu().resolve_conj().resolve_neg().numpy()))
            return {"$tensor": len(blobs) - 1}
        if to_handle is None:
            raise TypeError(f"cannot send a {type(v).__name__} to the sandbox")
        ref = to_handle(v)
        if type(ref) is LentRef:  # only the grader's side lends (a LentRef inside a value is just an object)
            return {"$lent": {"id": ref.id, "type": ref.type_name, "methods": [str(m) for m in ref.methods],
                              "attrs": enc(ref.attrs, d + 1)}}
        return {"$handle": ref.id, "type": type(v).__name__[:TYPE_NAME_CHARS]}

    return enc(value, depth), blobs


def _is_plain_tensor(v: Any) -> bool:
    torch = __import__("sys").modules.get("torch")
    return torch is not None and type(v) is torch.Tensor and v.layout == torch.strided


def decode(tree: Any, blobs: list[bytes], from_handle: Callable[[int, str], Any],
           from_lent: Callable[[LentRef], Any] | None = None) -> Any:
    """Rebuild a value from :func:`encode`'s output; anything unexpected raises :class:`ProtocolError`.

    Lent objects are accepted only where ``from_lent`` is given (in the worker): the grader never
    takes one from the sandbox.
    """

    def blob(i: Any) -> bytes:
        if type(i) is not int or not 0 <= i < len(blobs):
            raise ProtocolError("bad blob index")
        return blobs[i]

    def dec(t: Any, d: int) -> Any:
        if d > MAX_DEPTH + 2:  # the wrappers of a value at MAX_DEPTH
            raise ProtocolError("value nested too deeply")
        if t is None or type(t) in (bool, int, float, str):
            return t
        if type(t) is list:
            return [dec(x, d + 1) for x in t]
        if type(t) is not dict or len(t) not in (1, 2):
            raise ProtocolError(f"unexpected value in message: {str(t)[:QUOTED_CHARS]}")
        (tag, body), *rest = t.items()
        if tag == "$tuple" and type(body) is list and not rest:
            return tuple(dec(x, d + 1) for x in body)
        if tag == "$dict" and type(body) is dict and not rest:
            return {str(k): dec(x, d + 1) for k, x in body.items()}
        if tag == "$float" and body in ("nan", "inf", "-inf") and not rest:
            return float(body)
        if tag == "$bigint" and type(body) is str and not rest:
            try:
                return int(body[:5000])
            except ValueError:
                raise ProtocolError("bad integer") from None
        if tag == "$ndarray" and not rest:
            return _npy_array(blob(body))
        if tag == "$npscalar" and not rest:
            array = _npy_array(blob(body))
            if array.ndim != 0:
                raise ProtocolError("a numpy scalar must be 0-dimensional")
            return array[()]
        if tag == "$tensor" and not rest:
            import torch

            return torch.from_numpy(_npy_array(blob(body)).copy())
        if tag == "$lent" and from_lent is not None and not rest and type(body) is dict:
            methods, attrs = body.get("methods"), dec(body.get("attrs"), d + 1)
            if type(body.get("id")) is not int or type(methods) is not list or type(attrs) is not dict:
                raise ProtocolError("malformed lent object")
            return from_lent(LentRef(body["id"], str(body.get("type", "object")), [str(m) for m in methods], attrs))
        if tag == "$handle" and type(body) is int:
            type_name = rest[0][1] if rest and rest[0][0] == "type" and type(rest[0][1]) is str else "object"
            return from_handle(body, type_name)
        raise ProtocolError(f"unexpected value in message: {str(t)[:QUOTED_CHARS]}")

    return dec(tree, 0)


# ---------------------------------------------------------------- framing


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def send_message(fd: int, header: dict[str, Any], blobs: list[bytes] = ()) -> None:
    """Write one message (header, then its blobs) to ``fd``."""
    head = json.dumps(dict(header, nblobs=len(blobs)), allow_nan=False).encode()
    _write_all(fd, b"".join([struct.pack(">I", len(head)), head, *(struct.pack(">I", len(b)) + b for b in blobs)]))


class FrameReader:
    """Reads messages from ``fd`` with an overall deadline per message."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.buffer = bytearray()

    def _read_exact(self, n: int, deadline: float | None) -> bytes:
        while len(self.buffer) < n:
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([self.fd], [], [], timeout)
            if not ready:
                raise ChannelTimeout("no answer in time")
            chunk = os.read(self.fd, max(65536, n - len(self.buffer)))
            if not chunk:
                raise ChannelClosed("the other side closed the channel")
            self.buffer += chunk
        data = bytes(self.buffer[:n])
        del self.buffer[:n]
        return data

    def _frame(self, deadline: float | None) -> bytes:
        (size,) = struct.unpack(">I", self._read_exact(4, deadline))
        if size > MAX_FRAME:
            raise ProtocolError(f"frame of {size} bytes is over the limit")
        return self._read_exact(size, deadline)

    def read_message(self, timeout: float | None = None) -> tuple[dict[str, Any], list[bytes]]:
        """One message's header and blobs; raises on timeout, closed channel or malformed data."""
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            header = json.loads(self._frame(deadline).decode())
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            raise ProtocolError("message header is not JSON") from None
        if type(header) is not dict or type(header.get("nblobs")) is not int or not 0 <= header["nblobs"] < MAX_BLOBS:
            raise ProtocolError("message header is malformed")
        return header, [self._frame(deadline) for _ in range(header["nblobs"])]
