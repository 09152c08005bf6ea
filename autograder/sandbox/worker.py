"""The worker: executes cells of one submission and answers calls about them. Runs in the sandbox.

Runs inside the isolated process that :mod:`autograder.sandbox.zygote` starts, next to student
code; it never sees the suites, the solutions or the results. Requests and answers are
:mod:`autograder.sandbox.wire` messages on dedicated pipes (student prints go to stdout/stderr,
which the grader reads separately and keeps only as context). The grader's trusted side also
uses :class:`Worker`, in its own process, to run the reference through the same encoding.
"""
from __future__ import annotations

import builtins
import linecache
import traceback
from typing import Any, Callable

from autograder.sandbox.wire import FrameReader, HandleRef, LentRef, decode, encode, send_message

CELL_PREFIX, CELL_SUFFIX = "<cell ", ">"
"""A cell's code is compiled under the file name ``<cell LABEL>``, so tracebacks name the cell."""
MESSAGE_CHARS = 1500
"""An exception's own text is cut here: enough for any real error, not a flood from a hostile one."""
FRAMES_SHOWN = 4
"""The innermost student-cell frames of a traceback that the feedback shows."""
KIND_CHARS = 80
"""An exception's type name is cut here (a student may name a class anything)."""


def cell_filename(label: str) -> str:
    return f"{CELL_PREFIX}{label}{CELL_SUFFIX}"


def cell_label(filename: str | None) -> str | None:
    """The label of a cell from its compiled file name, or None for a file that is not a cell."""
    if filename and filename.startswith(CELL_PREFIX) and filename.endswith(CELL_SUFFIX):
        return filename[len(CELL_PREFIX):-len(CELL_SUFFIX)]
    return None


def format_error(err: BaseException) -> str:
    """One readable message: the exception and the student-cell frames that led to it."""
    frames = [f for f in traceback.extract_tb(err.__traceback__) if cell_label(f.filename) is not None]
    lines = [f"  {cell_label(f.filename)}, line {f.lineno}: {(f.line or '').strip()}" for f in frames[-FRAMES_SHOWN:]]
    text = f"{type(err).__name__}: {err}"[:MESSAGE_CHARS]
    if isinstance(err, SyntaxError) and cell_label(err.filename) is not None:
        text = f"SyntaxError in {cell_label(err.filename)}, line {err.lineno}: {err.msg}\n    {(err.text or '').rstrip()}"
    return text + ("\n" + "\n".join(lines) if lines else "")


_UNDEFINED = object()


class NotDefined(NameError):
    """A test called a stub that the submission's namespace does not hold."""

    def __init__(self, name: str) -> None:
        super().__init__(f"your notebook does not define `{name}` (was its cell renamed or deleted?)")


def _undefined(name: str) -> Any:
    def missing(*args: Any, **kwargs: Any) -> Any:
        raise NameError(f"name '{name}' is not defined")
    return missing


class Lent:
    """A trusted object lent by the grader: calling one of its methods runs it there, on plain data.

    Student code sees the method names and the plain attributes copied when it was sent, nothing
    of the object itself (an environment's hidden parameters stay in the grader).
    """

    __slots__ = ("_lent",)

    def __init__(self, ref: LentRef, call: Callable[[int, str, tuple, dict], Any]) -> None:
        object.__setattr__(self, "_lent", (ref, call, {}))

    def __getattr__(self, name: str) -> Any:
        ref, call, methods = object.__getattribute__(self, "_lent")
        if name in ref.attrs:
            return ref.attrs[name]
        if name in methods:  # made once per method: a loop of ``env.duel(...)`` builds no function per call
            return methods[name]
        if name in ref.methods:
            def method(*args: Any, **kwargs: Any) -> Any:
                return call(ref.id, name, args, kwargs)
            method.__name__ = name
            methods[name] = method
            return method
        raise AttributeError(f"{ref.type_name} has no attribute {name!r} that the grader lends")

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a lent object cannot be changed")

    def __repr__(self) -> str:
        return f"<{object.__getattribute__(self, '_lent')[0].type_name} (lent by the grader)>"


class Worker:
    """The namespace of one submission and a table of the objects handed out as handles."""

    def __init__(self, channel: tuple[FrameReader, int] | None = None,
                 lent_call: Callable[[int, str, tuple, dict], Any] | None = None) -> None:
        self.namespace: dict[str, Any] = {"__name__": "__main__", "__builtins__": builtins}
        self.handles: dict[int, Any] = {}
        self.next_handle = 1
        self.channel = channel
        self.lent_call = lent_call or self._call_the_grader
        self.replaced: dict[str, Any] = {}
        self.modules: dict[str, dict[str, Any]] = {}
        """Trusted suite helper modules run here, each in its own namespace (``notebook`` is the submission's)."""

    def _ask_grader(self, request: dict[str, Any], blobs: list[bytes], failure: str) -> Any:
        reader, write_fd = self.channel
        send_message(write_fd, request, blobs)
        header, reply_blobs = reader.read_message()
        if header.get("ok") is not True:
            raise RuntimeError(f"{failure}: {header.get('error')}")
        return decode(header.get("value"), reply_blobs, self.from_handle)

    def _call_the_grader(self, id: int, method: str, args: tuple, kwargs: dict) -> Any:
        tree, blobs = encode([list(args), kwargs])
        return self._ask_grader({"callback": {"lent": id, "method": method}, "args": tree}, blobs,
                                f"the grader's `{method}` refused these arguments")

    def from_lent(self, ref: LentRef) -> Lent:
        return Lent(ref, self.lent_call)

    def reference_stand_in(self, name: str, own: Any) -> Any:
        """A function that asks the grader to run the reference ``name`` on plain data.

        While a stub is tested, the other stubs it calls are replaced by these, so a mistake in one
        stub does not fail the stubs that use it. Calls whose arguments cannot cross as data (a
        network, a tensor that needs gradients) run the student's own version instead.
        """
        def stand_in(*args: Any, **kwargs: Any) -> Any:
            try:
                if any(getattr(a, "requires_grad", False) for a in (*args, *kwargs.values())):
                    raise TypeError("needs gradients")
                tree, blobs = encode([list(args), kwargs])
            except (TypeError, ValueError):
                return own(*args, **kwargs)
            return self._ask_grader({"callback": {"reference": name}, "args": tree}, blobs,
                                    f"the grader's reference `{name}` failed on these arguments")

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
        return decode(header.get(key), blobs, self.from_handle, self.from_lent)

    def run(self, header: dict, blobs: list[bytes]) -> Any:
        op = header.get("op")
        if op == "exec":
            label, source, module = str(header["label"]), str(header["source"]), header.get("module")
            filename = cell_filename(label)
            linecache.cache[filename] = (len(source), None, source.splitlines(True), filename)
            scope = self.namespace if module is None else self.modules.setdefault(
                str(module), {"__name__": f"suite_{module}", "__builtins__": builtins, "notebook": self.namespace})
            exec(compile(source, filename, "exec"), scope)
            return None
        if op == "defined":
            return [name for name in header["names"] if name in self.namespace]
        if op == "call":
            target = header["target"]
            if type(target) is int:
                fn = self.handles[target]
            elif "." in str(target):  # module.function: a suite helper (no notebook name has a dot)
                module, name = str(target).split(".", 1)
                fn = self.modules[module][name]
            elif str(target) in self.namespace:
                fn = self.namespace[str(target)]
            else:
                raise NotDefined(str(target))
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
            send_message(write_fd, {"ok": False, "kind": type(err).__name__[:KIND_CHARS], "error": message})
