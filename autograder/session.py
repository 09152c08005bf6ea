"""The trusted side's view of a submission: cells run in a sandbox, called through proxies.

A :class:`Session` owns one sandbox worker at a time. It runs the trusted setup
cells and the submission's stub cells in notebook order, remembers which stubs
ran, and restarts the worker (replaying the cells that ran) whenever a call
times out, crashes it or garbles the channel, so one stub's failure never
spreads to another. :class:`Namespace` is the proxy the suites see as
``student``; the same class over a :class:`LocalTransport` is ``reference``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from autograder.sandbox import Limits, SpawnConfig, WorkerProcess, Zygote
from autograder.wire import (ChannelClosed, ChannelTimeout, HandleRef, ProtocolError, decode, encode,
                             send_message)


class StudentError(Exception):
    """The submission's code raised an exception (``kind`` is its type name)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class SandboxFailure(Exception):
    """The worker timed out, died, or sent something malformed."""


@dataclass
class Cell:
    """A cell to run in the worker: trusted setup (``stub`` is None) or a submission's stub cell."""

    label: str
    source: str
    stub: str | None = None


@dataclass
class CellStatus:
    ok: bool
    message: str = ""


class Transport(Protocol):
    generation: int

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float | None = None) -> Any: ...


class Handle:
    """An object living on the other side; attributes and calls go through the transport."""

    def __init__(self, transport: Transport, id: int, type_name: str, generation: int) -> None:
        self._transport, self._id, self._type, self._generation = transport, id, type_name, generation
        self._attrs: dict[str, Any] = {}

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if name in self._attrs:
            return self._attrs[name]
        value = self._transport.request({"op": "getattr", "handle": self._ref().id, "attr": name}, [])
        if isinstance(value, Handle):  # a method or sub-object: its identity is stable, remember it
            self._attrs[name] = value
        return value

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return _call(self._transport, self._ref().id, args, kwargs)

    def _ref(self) -> HandleRef:
        if self._generation != self._transport.generation:
            raise SandboxFailure("this object was lost when the sandbox restarted after an earlier failure")
        return HandleRef(self._id, self._type)

    def __repr__(self) -> str:
        return f"<{self._type} (in the sandbox)>"


def _call(transport: Transport, target: str | int, args: tuple, kwargs: dict, timeout: float | None = None) -> Any:
    tree_args, blobs = encode(list(args), _handle_ref)
    tree_kwargs, more = encode(kwargs, _handle_ref)
    tree_kwargs = _shift_blobs(tree_kwargs, len(blobs))
    return transport.request({"op": "call", "target": target, "args": tree_args, "kwargs": tree_kwargs},
                             blobs + more, timeout)


def _handle_ref(value: Any) -> HandleRef:
    if isinstance(value, Handle):
        return value._ref()
    raise TypeError(f"cannot send a {type(value).__name__} to the sandbox")


def _shift_blobs(tree: Any, offset: int) -> Any:
    """Renumber blob indices of a tree encoded separately, so two trees can share one blob list."""
    if isinstance(tree, list):
        return [_shift_blobs(t, offset) for t in tree]
    if isinstance(tree, dict):
        if len(tree) == 1 and next(iter(tree)) in ("$ndarray", "$npscalar", "$tensor"):
            key = next(iter(tree))
            return {key: tree[key] + offset}
        return {k: _shift_blobs(v, offset) for k, v in tree.items()}
    return tree


class Namespace:
    """What a suite sees: ``ns.f(x)`` calls ``f`` on the other side, ``ns.eval("expr", a=x)`` evaluates."""

    def __init__(self, transport: Transport, label: str) -> None:
        self._transport, self._label = transport, label

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)

        def remote_function(*args: Any, timeout: float | None = None, **kwargs: Any) -> Any:
            return _call(self._transport, name, args, kwargs, timeout)

        remote_function.__name__ = name
        return remote_function

    def eval(self, expr: str, timeout: float | None = None, **bindings: Any) -> Any:
        tree, blobs = encode(bindings, _handle_ref)
        return self._transport.request({"op": "eval", "expr": expr, "bindings": tree}, blobs, timeout)

    def defined(self, *names: str) -> list[str]:
        return self._transport.request({"op": "defined", "names": list(names)}, [])

    def __repr__(self) -> str:
        return f"<{self._label} namespace>"


def _decode_reply(transport: Transport, header: dict[str, Any], blobs: list[bytes]) -> Any:
    if header.get("ok") is not True:
        raise StudentError(str(header.get("kind", "Error"))[:80], str(header.get("error", "unknown error"))[:3000])
    return decode(header.get("value"), blobs,
                  lambda id, type_name: Handle(transport, id, type_name, transport.generation))


class LocalTransport:
    """Runs requests against an in-process namespace (the reference), through the same encoding."""

    generation = 0

    def __init__(self, namespace: dict[str, Any]) -> None:
        from autograder.worker import Worker

        self.worker = Worker()
        self.worker.namespace = namespace

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float | None = None) -> Any:
        from autograder.wire import encode as enc

        # Round-trip the request as the worker would receive it, then the answer as the grader would.
        value = self.worker.run(header, blobs)
        tree, out = enc(value, self.worker.to_handle)
        return _decode_reply(self, {"ok": True, "value": tree}, out)


class Session:
    """One submission's sandbox: runs its cells, serves calls, restarts after failures."""

    def __init__(self, zygote: Zygote, cells: list[Cell], hidden_paths: list[str], readonly_paths: list[str],
                 limits: Limits | None = None):
        self.zygote, self.cells = zygote, cells
        self.config = SpawnConfig(hidden_paths, readonly_paths, limits or Limits())
        self.limits = self.config.limits
        self.status: dict[str, CellStatus] = {}
        self.worker: WorkerProcess | None = None
        self.generation = 0
        self.time_used = 0.0
        self.isolation = "unknown"
        self.restarts = 0
        self.reference_call: Callable[[str, Any, list[bytes]], tuple[dict, list[bytes]]] | None = None
        """Answers the worker's requests to run a reference stub (see ``Worker.reference_stand_in``)."""

    # -------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Start a worker and run every cell; a cell that fails is recorded (stubs) and skipped later."""
        self._spawn()
        for cell in self.cells:
            if cell.label in self.status and not self.status[cell.label].ok:
                continue
            self.status[cell.label] = self._exec(cell)

    def _spawn(self) -> None:
        self.close()
        self.generation += 1
        self.worker = self.zygote.spawn(self.config)
        try:
            self.worker.start(timeout=30)
        except (ChannelTimeout, ChannelClosed, ProtocolError, RuntimeError) as err:
            self.worker.kill()
            raise SandboxFailure(f"the sandbox could not start: {err}") from None
        self.isolation = self.worker.isolation

    def _exec(self, cell: CellStatus | Cell) -> CellStatus:
        try:
            self._raw({"op": "exec", "label": cell.label, "source": cell.source}, [], self.limits.exec_seconds)
            return CellStatus(True)
        except StudentError as err:
            if err.kind == "NotImplementedError":
                return CellStatus(False, "not implemented yet: the cell still raises NotImplementedError")
            return CellStatus(False, f"the cell `{cell.label}` failed when run: {err}")
        except SandboxFailure as err:
            message = f"running the cell `{cell.label}` {err}"
            self._spawn()  # a fresh worker for the cells after this one
            self._replay(upto=cell.label)
            return CellStatus(False, message)

    def _replay(self, upto: str) -> None:
        """Re-run, in a fresh worker, the cells before ``upto`` that ran before."""
        for cell in self.cells:
            if cell.label == upto:
                return
            if self.status.get(cell.label, CellStatus(False)).ok:
                self.status[cell.label] = self._exec(cell)

    def _restart(self) -> None:
        self.restarts += 1
        self._spawn()
        for cell in self.cells:
            if self.status.get(cell.label, CellStatus(False)).ok:
                self.status[cell.label] = self._exec(cell)

    def close(self) -> None:
        if self.worker is not None:
            self.worker.kill()
            self.worker = None

    # -------------------------------------------------------------- requests

    def _raw(self, header: dict[str, Any], blobs: list[bytes], timeout: float) -> Any:
        if self.time_used > self.limits.submission_seconds:
            raise SandboxFailure(f"stopped: the submission used up its total time of {self.limits.submission_seconds:.0f} s")
        timeout = min(timeout, self.limits.submission_seconds - self.time_used + 1)
        start = time.monotonic()
        try:
            reply, reply_blobs = self.worker.request(header, blobs, timeout)
            while "callback" in reply:  # the student's code called a stand-in: run the reference, answer
                answer, answer_blobs = self._answer(reply, reply_blobs)
                send_message(self.worker.to_fd, answer, answer_blobs)
                reply, reply_blobs = self.worker.reader.read_message(max(0.1, start + timeout - time.monotonic()))
            return _decode_reply(self, reply, reply_blobs)
        except ChannelTimeout:
            self.worker.kill()
            raise SandboxFailure(f"timed out after {timeout:.0f} s (an infinite loop, or far too slow)") from None
        except (ChannelClosed, BrokenPipeError, OSError):
            tail = self.worker.tail().strip()
            self.worker.kill()
            raise SandboxFailure("crashed the sandbox (the process exited or was killed: out of memory, "
                                 "os._exit, a signal, or a resource limit)"
                                 + (f"; its last output: {tail[-300:]}" if tail else "")) from None
        except ProtocolError as err:
            self.worker.kill()
            raise SandboxFailure(f"sent malformed data back to the grader ({err})") from None
        finally:
            self.time_used += time.monotonic() - start

    def _answer(self, reply: dict[str, Any], blobs: list[bytes]) -> tuple[dict[str, Any], list[bytes]]:
        name = reply.get("callback")
        if self.reference_call is None or name not in self.standing_in:
            return {"ok": False, "error": f"`{name}` is not available from the grader now"}, []
        return self.reference_call(str(name), reply.get("args"), blobs)

    standing_in: frozenset[str] = frozenset()

    def stand_in(self, names: list[str]) -> None:
        """Replace these stubs by reference stand-ins in the worker (for the test about to run)."""
        self.standing_in = frozenset(names)
        if names:
            self.request({"op": "stand_in", "names": sorted(names)}, [])

    def restore(self) -> None:
        """Put the student's own versions back after a test."""
        if self.standing_in and self.worker is not None and self.worker.alive:
            self.standing_in = frozenset()
            self._raw({"op": "restore"}, [], self.limits.call_seconds)
        self.standing_in = frozenset()

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float | None = None) -> Any:
        """A call from a test: restarts a dead worker first, so one test's crash does not fail the next."""
        if self.worker is None or not self.worker.alive:
            self._restart()
        return self._raw(header, blobs, timeout or self.limits.call_seconds)
