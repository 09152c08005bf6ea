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

MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""A message (its header and all its blobs together) is at most this big unless the reader is given another cap
(the grader uses its limits' ``message_bytes``): far beyond any test's values, and what bounds the memory a peer
can make the reader allocate, since a frame's buffer is allocated only once its size is known to fit."""
MAX_HEADER_BYTES = 4 * 1024 * 1024
"""A message's JSON header (numbers, strings, lists and dicts; arrays travel as blobs) is at most this big."""
MAX_HEADER_VALUES = 250_000
"""A header holds at most this many JSON values (counted by its brackets and commas before it is parsed), so the
parsed header stays within a few tens of MB: JSON like ``[[],[],...]`` would otherwise grow twenty-fold in memory."""
MAX_DEPTH = 64
"""Values nest at most this deep: far beyond any test's data, and well inside Python's recursion limit
on both sides (a student's value nested 10,000 deep must fail cleanly, not crash the grader)."""
MAX_BLOBS = 10_000
"""Arrays in one message at most."""
NPY_HEADER_BYTES = 65_536
"""An ``.npy`` header is read from at most this many leading bytes of its blob."""
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


def _npy_array(blob: bytes | bytearray) -> np.ndarray:
    """The array in an ``.npy`` blob, without copying its data where the blob is writable (the grader reads
    frames into ``bytearray``s): only the header is parsed apart, so a blob costs its own size in memory once."""
    try:
        head = io.BytesIO(bytes(memoryview(blob)[:NPY_HEADER_BYTES]))
        major, _ = np.lib.format.read_magic(head)
        read_header = {1: np.lib.format.read_array_header_1_0, 2: np.lib.format.read_array_header_2_0}.get(major)
        if read_header is None:
            raise ValueError(f"npy version {major}")
        shape, fortran, dtype = read_header(head, max_header_size=NPY_HEADER_BYTES)
    except Exception as err:  # noqa: BLE001 - any malformed header
        raise ProtocolError(f"bad array data: {str(err)[:QUOTED_CHARS]}") from None
    if dtype.kind not in ALLOWED_DTYPE_KINDS or dtype.hasobject or dtype.fields is not None or dtype.subdtype:
        raise ProtocolError("arrays must be numeric numpy arrays")
    count = 1
    for n in shape:
        count *= int(n)
    offset = head.tell()
    if len(blob) - offset != count * dtype.itemsize:
        raise ProtocolError("bad array data: its size does not match its shape")
    array = np.frombuffer(blob, dtype=dtype, count=count, offset=offset).reshape(shape, order="F" if fortran else "C")
    return array if array.flags.writeable else array.copy()


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


def seconds_left(deadline: Any) -> float | None:
    """What is left before ``deadline``: None (no limit), a ``time.monotonic()`` value, or an object whose
    ``left()`` says (the grader's deadlines that do not count a worker's wait for a busy CPU)."""
    if deadline is None:
        return None
    if isinstance(deadline, (int, float)):
        return deadline - time.monotonic()
    return deadline.left()


def _wait(fd: int, event: int, deadline: Any) -> None:
    """Block until ``fd`` is ready for ``event`` (``select.POLLIN`` or ``POLLOUT``), or raise at ``deadline``."""
    poller = select.poll()
    poller.register(fd, event)
    while True:
        if deadline is None:
            timeout_ms = None
        else:
            remaining = seconds_left(deadline)
            if remaining <= 0:
                raise ChannelTimeout("no answer in time" if event == select.POLLIN else "the other side stopped reading")
            timeout_ms = max(1, int(remaining * 1000))
        if poller.poll(timeout_ms):
            return


def _write_all(fd: int, data: bytes, deadline: float | None) -> None:
    """Write all of ``data``; with a ``deadline``, on a non-blocking ``fd``, never block past it."""
    view = memoryview(data)
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            _wait(fd, select.POLLOUT, deadline)
            continue
        view = view[n:]
        if view and deadline is not None and seconds_left(deadline) < 0:
            raise ChannelTimeout("the other side stopped reading")


def send_message(fd: int, header: dict[str, Any], blobs: list[bytes] = (), deadline: float | None = None) -> None:
    """Write one message (header, then its blobs) to ``fd``.

    ``deadline`` (a ``time.monotonic()`` value) bounds the write: a peer that stops reading cannot block the
    writer for longer. The grader writes with one, on a non-blocking descriptor; a worker writes without.
    """
    head = json.dumps(dict(header, nblobs=len(blobs)), allow_nan=False).encode()
    _write_all(fd, b"".join([struct.pack(">I", len(head)), head, *(struct.pack(">I", len(b)) + b for b in blobs)]),
               deadline)


class FrameReader:
    """Reads messages from ``fd``, each within a deadline and a size cap.

    Frames are read straight into buffers of their announced size, allocated only after the size is known
    to fit in what is left of the message's cap, and never past a frame's end: what a peer sends costs at most
    ``max_message`` bytes, and a JSON header is parsed only when its count of values is within bounds.
    """

    def __init__(self, fd: int, max_message: int = MAX_MESSAGE_BYTES) -> None:
        self.fd, self.max_message = fd, max_message

    def _read_exact(self, n: int, deadline: float | None) -> bytearray:
        out = bytearray(n)
        view, got = memoryview(out), 0
        while got < n:
            _wait(self.fd, select.POLLIN, deadline)
            try:
                k = os.readv(self.fd, [view[got:]])
            except BlockingIOError:
                continue
            if not k:
                raise ChannelClosed("the other side closed the channel")
            got += k
        return out

    def _frame(self, deadline: float | None, room: int, what: str) -> bytearray:
        (size,) = struct.unpack(">I", self._read_exact(4, deadline))
        if size > room:
            raise ProtocolError(f"{what} of {size} bytes is over the limit")
        return self._read_exact(size, deadline)

    def read_message(self, timeout: float | None = None, deadline: float | None = None
                     ) -> tuple[dict[str, Any], list[bytearray]]:
        """One message's header and blobs; raises on timeout, closed channel, malformed or oversized data.

        ``deadline`` (``time.monotonic()``) or ``timeout`` (seconds from now) bounds the whole message.
        """
        if deadline is None and timeout is not None:
            deadline = time.monotonic() + timeout
        raw = self._frame(deadline, min(MAX_HEADER_BYTES, self.max_message), "a message header")
        if raw.count(b",") + raw.count(b"[") + raw.count(b"{") > MAX_HEADER_VALUES:
            raise ProtocolError(f"a message header holds more than {MAX_HEADER_VALUES} values")
        try:
            header = json.loads(raw.decode())
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            raise ProtocolError("message header is not JSON") from None
        if type(header) is not dict or type(header.get("nblobs")) is not int or not 0 <= header["nblobs"] < MAX_BLOBS:
            raise ProtocolError("message header is malformed")
        room = self.max_message - len(raw) - 4
        blobs = []
        for _ in range(header["nblobs"]):
            blobs.append(self._frame(deadline, room - 4, "a message"))
            room -= 4 + len(blobs[-1])
        return header, blobs
