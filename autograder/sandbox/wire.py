"""The only format in which values cross between the grader and a sandbox worker.

A message is one frame of UTF-8 JSON followed by the frames of its binary
blobs; every frame is a 4-byte big-endian length and its bytes. Values are a
small closed set: ``None``, ``bool``, ``int``, ``float``, ``str``, lists,
tuples, string-keyed dicts, numpy arrays (as ``.npy`` with ``allow_pickle=False``),
numpy scalars (as a JSON number tagged with its dtype, or a 0-d ``.npy``), torch
tensors (as ``.npy``), *handles* to objects
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
import math
import os
import re
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


NPY_MAGIC = b"\x93NUMPY\x01\x00"
"""The ``.npy`` format's version 1.0, which :func:`_npy_bytes` writes (the arrays it writes have short headers)."""
NPY_ALIGN = 64
"""numpy pads a header so that the data starts at a multiple of this (as ``np.save`` does)."""
_NPY_HEADER = re.compile(rb"\{'descr': '([<>|=]?[biufc][0-9]{1,2})', 'fortran_order': (True|False), "
                         rb"'shape': \((|[0-9]{1,19},|[0-9]{1,19}(?:, [0-9]{1,19})+)\), \} *\n")
"""The header ``np.save`` writes for a numeric array, read without ``ast.literal_eval`` (which costs tens of
microseconds a blob). A header of another form is read by numpy's own reader, as before."""
_DTYPES: dict[bytes, np.dtype] = {}
"""Dtypes by the ``descr`` text of a header that matched :data:`_NPY_HEADER` (a few dozen at most)."""
NPNUM_TYPES = {np.dtype(name).type: name for name in ("bool", "int8", "int16", "int32", "int64", "uint8", "uint16",
                                                      "uint32", "uint64", "float16", "float32", "float64")}
"""numpy scalars that cross as JSON (``{"$npnum": [dtype name, value]}``) rather than as an ``.npy`` blob: each
of their values is exactly a JSON bool, integer or double (a float32's value is one double exactly). Others
(complex, ``longdouble``) cross as 0-d ``.npy`` blobs."""
NPNUM_BY_NAME = {name: type_ for type_, name in NPNUM_TYPES.items()}
_NPNUM_KIND = {name: np.dtype(name).kind for name in NPNUM_BY_NAME}
NON_FINITE = ("nan", "inf", "-inf")
_JSON_SCALARS = frozenset((type(None), bool, int, float, str))
"""What JSON parsing gives and :func:`decode` returns unchanged."""
_INT64 = 2**63


def _npy_bytes(array: np.ndarray) -> bytes:
    """``array`` in the ``.npy`` format, byte for byte what ``np.save(..., allow_pickle=False)`` writes for it
    (version 1.0), without going through a file object."""
    dtype = array.dtype
    if dtype.kind not in ALLOWED_DTYPE_KINDS or dtype.fields is not None or dtype.subdtype is not None:
        buffer = io.BytesIO()
        np.save(buffer, array, allow_pickle=False)
        return buffer.getvalue()
    fortran = bool(array.flags.f_contiguous and not array.flags.c_contiguous)
    shape = tuple(int(n) for n in array.shape)
    header = "{'descr': '%s', 'fortran_order': %s, 'shape': %r, }" % (dtype.str, fortran, shape)
    pad = -(len(NPY_MAGIC) + 2 + len(header) + 1) % NPY_ALIGN
    header = (header + " " * pad + "\n").encode("latin1")
    return b"".join([NPY_MAGIC, struct.pack("<H", len(header)), header, array.tobytes("F" if fortran else "C")])


def _npy_layout(blob: bytes | bytearray) -> tuple[tuple[int, ...], bool, np.dtype, int]:
    """Shape, Fortran order, dtype and data offset of an ``.npy`` blob; raises :class:`ProtocolError`."""
    if len(blob) >= 10 and blob[:8] == NPY_MAGIC:
        end = 10 + (blob[8] | blob[9] << 8)
        match = _NPY_HEADER.fullmatch(bytes(memoryview(blob)[10:end])) if end <= len(blob) else None
        if match is not None:
            dtype = _DTYPES.get(match[1])
            if dtype is None:
                try:
                    dtype = np.dtype(match[1].decode())
                except TypeError:
                    raise ProtocolError("bad array data: unknown dtype") from None
                if len(_DTYPES) < 512:
                    _DTYPES[match[1]] = dtype
            shape = tuple(int(n) for n in match[3].split(b",") if n.strip())
            return shape, match[2] == b"True", dtype, end
    try:
        head = io.BytesIO(bytes(memoryview(blob)[:NPY_HEADER_BYTES]))
        major, _ = np.lib.format.read_magic(head)
        read_header = {1: np.lib.format.read_array_header_1_0, 2: np.lib.format.read_array_header_2_0}.get(major)
        if read_header is None:
            raise ValueError(f"npy version {major}")
        shape, fortran, dtype = read_header(head, max_header_size=NPY_HEADER_BYTES)
    except Exception as err:  # noqa: BLE001 - any malformed header
        raise ProtocolError(f"bad array data: {str(err)[:QUOTED_CHARS]}") from None
    return shape, fortran, dtype, head.tell()


def _npy_array(blob: bytes | bytearray) -> np.ndarray:
    """The array in an ``.npy`` blob, without copying its data where the blob is writable (the grader reads
    frames into ``bytearray``s): only the header is parsed apart, so a blob costs its own size in memory once."""
    shape, fortran, dtype, offset = _npy_layout(blob)
    if dtype.kind not in ALLOWED_DTYPE_KINDS or dtype.hasobject or dtype.fields is not None or dtype.subdtype:
        raise ProtocolError("arrays must be numeric numpy arrays")
    count = 1
    for n in shape:
        count *= int(n)
    if len(blob) - offset != count * dtype.itemsize:
        raise ProtocolError("bad array data: its size does not match its shape")
    try:
        array = np.frombuffer(blob, dtype=dtype, count=count, offset=offset).reshape(shape, order="F" if fortran else "C")
    except ValueError as err:  # more dimensions than numpy allows, say
        raise ProtocolError(f"bad array data: {str(err)[:QUOTED_CHARS]}") from None
    return array if array.flags.writeable else array.copy()


def _npnum(name: Any, value: Any) -> np.generic:
    """The numpy scalar of a ``$npnum`` value; raises :class:`ProtocolError` on anything but an exact one."""
    type_ = NPNUM_BY_NAME.get(name) if type(name) is str else None
    if type_ is None:
        raise ProtocolError(f"unexpected value in message: a numpy scalar of type {str(name)[:QUOTED_CHARS]}")
    kind = _NPNUM_KIND[name]
    if not ((kind == "b" and type(value) is bool) or (kind in "iu" and type(value) is int)
            or (kind == "f" and (type(value) is float or value in NON_FINITE))):
        raise ProtocolError(f"unexpected value in message: {str(value)[:QUOTED_CHARS]} as a numpy {name}")
    try:
        return type_(value)
    except (OverflowError, ValueError):
        raise ProtocolError(f"a numpy {name} cannot hold {str(value)[:QUOTED_CHARS]}") from None


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
            return v if math.isfinite(v) else {"$float": repr(v)}
        name = NPNUM_TYPES.get(type(v))
        if name is not None:  # a numpy scalar that JSON holds exactly (an ``np.argmax``, say)
            kind = _NPNUM_KIND[name]
            if kind == "b":
                return {"$npnum": ["bool", bool(v)]}
            if kind == "f":
                x = float(v)
                return {"$npnum": [name, x if math.isfinite(x) else repr(x)]}
            return {"$npnum": [name, int(v)]}
        if type(v) is list or type(v) is tuple:  # strings and 64-bit ints inline: most lists hold only those
            items = ([x if type(x) is str or (type(x) is int and -_INT64 < x < _INT64) else enc(x, d + 1) for x in v]
                     if d < MAX_DEPTH else [enc(x, d + 1) for x in v])
            return items if type(v) is list else {"$tuple": items}
        if type(v) is dict and (not v or all(type(k) is str for k in v)):
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
        if type(t) in _JSON_SCALARS:
            return t
        if type(t) is list:  # JSON's own scalars inline: most lists hold only those
            if d < MAX_DEPTH + 2:
                return [x if type(x) in _JSON_SCALARS else dec(x, d + 1) for x in t]
            return [dec(x, d + 1) for x in t]
        if type(t) is not dict or len(t) not in (1, 2):
            raise ProtocolError(f"unexpected value in message: {str(t)[:QUOTED_CHARS]}")
        if len(t) == 1:
            ((tag, body),), rest = t.items(), ()
        else:
            (tag, body), *rest = t.items()
        if tag == "$npnum" and not rest and type(body) is list and len(body) == 2:  # the commonest tags first
            return _npnum(*body)
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

            try:
                return torch.from_numpy(_npy_array(blob(body)).copy())
            except (TypeError, ValueError) as err:  # a dtype or byte order torch does not take
                raise ProtocolError(f"bad tensor data: {str(err)[:QUOTED_CHARS]}") from None
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


def _wait(fd: int, event: int, deadline: Any, poller: Any = None) -> None:
    """Block until ``fd`` is ready for ``event`` (``select.POLLIN`` or ``POLLOUT``), or raise at ``deadline``.
    ``poller``: a ``select.poll`` object with ``fd`` registered for ``event`` already."""
    if poller is None:
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
    try:
        done = os.write(fd, data)
    except BlockingIOError:
        done = 0
    if done == len(data):  # the usual case, a small message: one write, no deadline to look at
        return
    view = memoryview(data)[done:]
    while view:
        if deadline is not None and seconds_left(deadline) < 0:
            raise ChannelTimeout("the other side stopped reading")
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            _wait(fd, select.POLLOUT, deadline)
            continue
        view = view[n:]


def _not_json(value: Any) -> Any:
    raise TypeError(f"a {type(value).__name__} is not JSON")


_JSON = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
_C_ENCODER = getattr(json.encoder, "c_make_encoder", None)
_encode_header: Callable[[Any], str] = (
    _JSON.encode if _C_ENCODER is None else
    lambda value, encoder=_C_ENCODER(None, _not_json, json.encoder.encode_basestring_ascii, None, ":", ",", False, False,
                                     False): "".join(encoder(value, 0)))
"""A header as JSON text, ASCII, no NaN, by one encoder made once (``json.dumps`` makes one per call). Headers are
trees that :func:`encode` built (never circular), so the encoder keeps no record of the containers it is in."""


def send_message(fd: int, header: dict[str, Any], blobs: list[bytes] = (), deadline: float | None = None) -> None:
    """Write one message (header, then its blobs) to ``fd``.

    ``deadline`` (a ``time.monotonic()`` value) bounds the write: a peer that stops reading cannot block the
    writer for longer. The grader writes with one, on a non-blocking descriptor; a worker writes without.
    """
    head = _encode_header(dict(header, nblobs=len(blobs))).encode()
    if not blobs:
        _write_all(fd, _LENGTH.pack(len(head)) + head, deadline)
        return
    _write_all(fd, b"".join([_LENGTH.pack(len(head)), head, *(_LENGTH.pack(len(b)) + b for b in blobs)]), deadline)


_LENGTH = struct.Struct(">I")
"""A frame's length prefix."""
_scan_json = json.JSONDecoder().raw_decode


def _decode_header(text: str) -> Any:
    """``json.loads`` for a header as :func:`send_message` writes it (no white space before or after the value),
    without the per-call steps that allow for other texts."""
    value, end = _scan_json(text)
    if end != len(text):
        raise json.JSONDecodeError("extra data", text, end)
    return value


READ_AHEAD = 64 * 1024
"""Bytes a :class:`FrameReader` may read past the end of the frame it is reading, in the same system call, and
keep for the next frames: a small message then costs one read, not one per frame (and, with a deadline, one
``poll`` rather than two)."""


class FrameReader:
    """Reads messages from ``fd``, each within a deadline and a size cap.

    Frames are read straight into buffers of their announced size, allocated only after the size is known
    to fit in what is left of the message's cap; the bytes a read brings past a frame's end (at most
    :data:`READ_AHEAD`, in a buffer allocated once) are kept for the frames after it. So what a peer sends
    costs at most ``max_message`` bytes plus that buffer, and a JSON header is parsed only when its count of
    values is within bounds.

    A read with a deadline never blocks past it: it waits in ``poll`` (which looks at the deadline first) before
    every read, so a peer that keeps the pipe full cannot hold the reader past it either; the grader's end of a
    worker's channel is non-blocking besides. A read without a deadline (the worker's) just blocks in the read.
    """

    def __init__(self, fd: int, max_message: int = MAX_MESSAGE_BYTES) -> None:
        self.fd, self.max_message = fd, max_message
        self._spare = bytearray(READ_AHEAD)
        self._spare_view = memoryview(self._spare)
        self._pending = memoryview(b"")
        """Bytes read but not yet taken: a view into the spare buffer, which a read refills only once they are
        all taken (or copied out)."""
        self._poller = select.poll()
        self._poller.register(fd, select.POLLIN)

    def ready(self, seconds: float) -> bool:
        """Whether a message has begun to arrive, waiting ``seconds`` at most (a millisecond's resolution)."""
        return bool(self._pending) or bool(self._poller.poll(max(0, round(seconds * 1000))))

    def _read_into(self, buffers: list, deadline: Any) -> int:
        """Read at least one byte into ``buffers`` (filled in order): the count."""
        while True:
            if deadline is not None:
                _wait(self.fd, select.POLLIN, deadline, self._poller)
            try:
                k = os.readv(self.fd, buffers)
            except BlockingIOError:
                _wait(self.fd, select.POLLIN, deadline, self._poller)
                continue
            if not k:
                raise ChannelClosed("the other side closed the channel")
            return k

    def _read_exact(self, n: int, deadline: Any) -> bytearray:
        """The next ``n`` bytes in a buffer of their own."""
        pending = self._pending
        if len(pending) >= n:  # read ahead already: the next frames of a small message
            self._pending = pending[n:]
            return bytearray(pending[:n])
        out = bytearray(n)
        view = memoryview(out)
        got = len(pending)
        view[:got] = pending
        self._pending = memoryview(b"")
        while got < n:
            k = self._read_into([view[got:], self._spare], deadline)
            if k > n - got:  # the read went on past this frame: keep the rest for the next ones
                self._pending = self._spare_view[:k - (n - got)]
                k = n - got
            got += k
        return out

    def _frame(self, deadline: Any, room: int, what: str) -> bytearray:
        (size,) = _LENGTH.unpack(self._read_exact(4, deadline))
        if size > room:
            raise ProtocolError(f"{what} of {size} bytes is over the limit")
        return self._read_exact(size, deadline)

    def _header_text(self, deadline: Any, room: int) -> tuple[str, int]:
        """The next frame, a message's JSON header, as text, and its size in bytes. A small message usually came
        whole in one read: its header is then decoded straight from the read buffer."""
        if not self._pending:
            self._pending = self._spare_view[:self._read_into([self._spare], deadline)]
        pending = self._pending
        if len(pending) >= 4:
            (size,) = _LENGTH.unpack_from(pending)
            if size > room:
                raise ProtocolError(f"a message header of {size} bytes is over the limit")
            if len(pending) >= 4 + size:
                self._pending = pending[4 + size:]
                return str(pending[4:4 + size], "utf-8"), size
        raw = self._frame(deadline, room, "a message header")
        return raw.decode(), len(raw)

    def read_message(self, timeout: float | None = None, deadline: Any = None
                     ) -> tuple[dict[str, Any], list[bytearray]]:
        """One message's header and blobs; raises on timeout, closed channel, malformed or oversized data.

        ``deadline`` (``time.monotonic()``, or an object with ``left()``) or ``timeout`` (seconds from now)
        bounds the whole message.
        """
        if deadline is None and timeout is not None:
            deadline = time.monotonic() + timeout
        try:
            text, size = self._header_text(deadline, min(MAX_HEADER_BYTES, self.max_message))
        except UnicodeDecodeError:
            raise ProtocolError("message header is not JSON") from None
        if text.count(",") + text.count("[") + text.count("{") > MAX_HEADER_VALUES:
            raise ProtocolError(f"a message header holds more than {MAX_HEADER_VALUES} values")
        try:
            header = _decode_header(text)
        except (ValueError, RecursionError):  # JSONDecodeError, or an integer of more digits than Python parses
            raise ProtocolError("message header is not JSON") from None
        if type(header) is not dict or type(header.get("nblobs")) is not int or not 0 <= header["nblobs"] < MAX_BLOBS:
            raise ProtocolError("message header is malformed")
        room = self.max_message - size - 4
        blobs = []
        for _ in range(header["nblobs"]):
            blobs.append(self._frame(deadline, room - 4, "a message"))
            room -= 4 + len(blobs[-1])
        return header, blobs
