"""The sandbox side: executes cells of one submission and answers calls about them.

Runs inside the isolated process that :mod:`autograder.sandbox` starts; it
never sees the suites, the solutions or the results. Requests and answers are
:mod:`autograder.wire` messages on dedicated pipes (student prints go to
stdout/stderr, which the grader reads separately and keeps only as context).
"""
from __future__ import annotations

import builtins
import linecache
import traceback
from typing import Any

from autograder.wire import FrameReader, HandleRef, decode, encode, send_message

CELL_PREFIX = "<cell "


def _cell_filename(label: str) -> str:
    return f"{CELL_PREFIX}{label}>"


def format_error(err: BaseException) -> str:
    """One readable message: the exception and the student-cell frames that led to it."""
    frames = [f for f in traceback.extract_tb(err.__traceback__) if f.filename.startswith(CELL_PREFIX)]
    lines = [f"  {f.filename[6:-1]}, line {f.lineno}: {(f.line or '').strip()}" for f in frames[-4:]]
    text = f"{type(err).__name__}: {err}"[:1500]
    if isinstance(err, SyntaxError) and err.filename and err.filename.startswith(CELL_PREFIX):
        text = f"SyntaxError in {err.filename[6:-1]}, line {err.lineno}: {err.msg}\n    {(err.text or '').rstrip()}"
    return text + ("\n" + "\n".join(lines) if lines else "")


_UNDEFINED = object()


def _undefined(name: str) -> Any:
    def missing(*args: Any, **kwargs: Any) -> Any:
        raise NameError(f"name '{name}' is not defined")
    return missing


class Worker:
    """The namespace of one submission and a table of the objects handed out as handles."""

    def __init__(self, channel: tuple[FrameReader, int] | None = None) -> None:
        self.namespace: dict[str, Any] = {"__name__": "__main__", "__builtins__": builtins}
        self.handles: dict[int, Any] = {}
        self.next_handle = 1
        self.channel = channel
        self.replaced: dict[str, Any] = {}

    def reference_stand_in(self, name: str, own: Any) -> Any:
        """A function that asks the grader to run the reference ``name`` on plain data.

        While a stub is tested, the other stubs it calls are replaced by these, so a mistake in one
        stub does not fail the stubs that use it. Calls whose arguments cannot cross as data (a
        network, a tensor that needs gradients) run the student's own version instead.
        """
        reader, write_fd = self.channel

        def stand_in(*args: Any, **kwargs: Any) -> Any:
            try:
                if any(getattr(a, "requires_grad", False) for a in (*args, *kwargs.values())):
                    raise TypeError("needs gradients")
                tree, blobs = encode([list(args), kwargs])
            except (TypeError, ValueError):
                return own(*args, **kwargs)
            send_message(write_fd, {"callback": name, "args": tree}, blobs)
            header, reply_blobs = reader.read_message()
            if header.get("ok") is not True:
                raise RuntimeError(f"the grader's reference `{name}` failed on these arguments: {header.get('error')}")
            return decode(header.get("value"), reply_blobs, self.from_handle)

        stand_in.__name__ = name
        return stand_in

    def to_handle(self, obj: Any) -> HandleRef:
        self.handles[self.next_handle] = obj
        self.next_handle += 1
        return HandleRef(self.next_handle - 1, type(obj).__name__)

    def from_handle(self, id: int, type_name: str) -> Any:
        if id not in self.handles:
            raise KeyError(f"unknown handle #{id}")
        return self.handles[id]

    def args(self, header: dict, blobs: list[bytes], key: str) -> Any:
        return decode(header.get(key), blobs, self.from_handle)

    def run(self, header: dict, blobs: list[bytes]) -> Any:
        op = header.get("op")
        if op == "exec":
            label, source = str(header["label"]), str(header["source"])
            filename = _cell_filename(label)
            linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
            exec(compile(source, filename, "exec"), self.namespace)
            return None
        if op == "defined":
            return [name for name in header["names"] if name in self.namespace]
        if op == "call":
            target = header["target"]
            fn = self.handles[target] if type(target) is int else self.namespace[str(target)]
            return fn(*self.args(header, blobs, "args"), **self.args(header, blobs, "kwargs"))
        if op == "getattr":
            return getattr(self.handles[int(header["handle"])], str(header["attr"]))
        if op == "eval":
            scope = dict(self.namespace)
            scope.update(self.args(header, blobs, "bindings"))
            return eval(compile(str(header["expr"]), "<grader>", "eval"), scope)
        if op == "stand_in":  # replace the named stubs by reference stand-ins until "restore"
            for name in header["names"]:
                if name not in self.replaced:
                    self.replaced[name] = self.namespace.get(name, _UNDEFINED)
                    own = self.replaced[name] if self.replaced[name] is not _UNDEFINED else _undefined(name)
                    self.namespace[name] = self.reference_stand_in(name, own)
            return None
        if op == "restore":
            for name, value in self.replaced.items():
                if value is _UNDEFINED:
                    self.namespace.pop(name, None)
                else:
                    self.namespace[name] = value
            self.replaced.clear()
            return None
        if op == "release":
            for id in header["ids"]:
                self.handles.pop(id, None)
            return None
        raise ValueError(f"unknown operation {op!r}")


def serve(read_fd: int, write_fd: int) -> None:
    """Answer requests until the grader closes the channel."""
    reader = FrameReader(read_fd)
    worker = Worker(channel=(reader, write_fd))
    send_message(write_fd, {"ok": True, "ready": True})
    while True:
        try:
            header, blobs = reader.read_message()
        except EOFError:
            return
        try:
            value = worker.run(header, blobs)
            tree, out_blobs = encode(value, worker.to_handle)
            send_message(write_fd, {"ok": True, "value": tree}, out_blobs)
        except BaseException as err:  # noqa: BLE001 - SystemExit and KeyboardInterrupt are the student's too
            try:
                message = format_error(err)
            except BaseException:  # noqa: BLE001 - an exception whose str() itself fails
                message = f"{type(err).__name__} (its message could not be printed)"
            send_message(write_fd, {"ok": False, "kind": type(err).__name__[:80], "error": message})
