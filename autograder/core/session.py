"""The trusted side's view of a submission: cells run in a sandbox, called through proxies. Runs in the grader.

A :class:`Session` owns one sandbox worker at a time. It runs the trusted setup
cells and the submission's stub cells in notebook order, remembers which stubs
ran, and restarts the worker (replaying the cells that ran) whenever a call
times out, crashes it or garbles the channel, so one stub's failure never
spreads to another. :class:`Namespace` is the proxy the suites see as
``student``; the same class over a :class:`LocalTransport` is ``reference``.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from autograder.core.pairing import IDLE_SECONDS, CpuPair
from autograder.core.results import SYNTAX_ERRORS, GraderError, Reason
from autograder.core.trusted_work import TrustedWorkTimeout
from autograder.sandbox.config import Limits, SpawnConfig
from autograder.sandbox.wire import (ChannelClosed, ChannelTimeout, HandleRef, LentRef, ProtocolError, decode,
                                     encode)
from autograder.sandbox.worker import NotDefined, Worker
from autograder.core.supervisor import OUTPUT_READ_BYTES, SandboxStartError, WorkerProcess, Zygote

START_SECONDS = 30.0
"""A worker that has not reported ready by then is broken (the grader's fault: no student code ran yet)."""
CPU_WAIT_STRETCH = 3.0
"""How far a time limit may stretch, as a multiple of itself, by the time the worker spent waiting for a busy
CPU. A loaded machine (a batch, other users) then does not turn an honest submission's call into a timeout,
while a submission that loads the machine itself (busy threads of its own) gains at most this much."""
KIND_CHARS, ERROR_CHARS, TAIL_QUOTED = 80, 3000, 300
"""Cuts of what the worker reports: an exception's type name, its message, and the output quoted after a crash."""
NOT_IMPLEMENTED = "NotImplementedError"


class FairDeadline:
    """A deadline ``seconds`` from now, not counting the worker's wait for a CPU (at most ``max_credit`` of it).

    Time spent computing or sleeping counts; time spent runnable while other processes held every CPU does
    not. Where the kernel does not report the wait, it is a plain wall-clock deadline.

    :meth:`left` reads the kernel's count only once the deadline is reached with the credit known so far: the
    credit only grows, so until then reading it could say there is more time left, never that there is none.
    A lent object's round trips (thousands in one call) then cost no read of ``/proc`` each.
    """

    def __init__(self, seconds: float, worker: WorkerProcess, max_credit: float) -> None:
        self.start, self.seconds, self.worker, self.max_credit = time.monotonic(), seconds, worker, max_credit
        self.end = self.start + seconds
        self.wait_at_start = worker.cpu_wait()
        self._credit = 0.0

    def credit(self) -> float:
        """Seconds of CPU wait forgiven so far (read from the kernel now)."""
        if self.wait_at_start is not None:
            now = self.worker.cpu_wait()
            if now is not None:
                self._credit = min(max(self._credit, now - self.wait_at_start), self.max_credit)
        return self._credit

    def left(self) -> float:
        left = self.end + self._credit - time.monotonic()
        if left > 0 or self.wait_at_start is None or self._credit >= self.max_credit:
            return left
        return self.end + self.credit() - time.monotonic()


class StudentError(Exception):
    """The submission's code raised an exception (``kind`` is its type name)."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind

    @property
    def not_implemented(self) -> bool:
        return self.kind == NOT_IMPLEMENTED

    @property
    def not_defined(self) -> bool:
        """The test called a name the notebook does not define (see ``NotDefined`` in the worker)."""
        return self.kind == NotDefined.__name__


class SandboxFailure(Exception):
    """The worker died, or sent something malformed, while running student code."""


class SandboxTimeout(SandboxFailure):
    """The worker did not answer in time (an infinite loop, or far too slow)."""


class ReferenceFault(GraderError):
    """The reference solution failed on a test's input: the suite's or the solution's bug, never the student's."""


@dataclass
class Cell:
    """A cell to run in the worker: trusted setup (``stub`` is None), a submission's stub cell, or a
    suite's helper module (``module`` names the namespace it runs in, apart from the notebook's)."""

    label: str
    source: str
    stub: str | None = None
    module: str | None = None


@dataclass
class CellStatus:
    ok: bool
    message: str = ""
    reason: Reason = Reason.PASSED
    """Why the cell did not run (``ok`` False): every test of its stub fails with this reason."""


def failure_reason(err: Exception) -> Reason:
    """The :class:`Reason` of a failure of student code: its exception's kind, a timeout, a crash."""
    if isinstance(err, StudentError):
        if err.not_implemented:
            return Reason.NOT_IMPLEMENTED
        if err.not_defined:
            return Reason.MISSING
        return Reason.SYNTAX if err.kind in SYNTAX_ERRORS else Reason.EXCEPTION
    if isinstance(err, SandboxTimeout):
        return Reason.TIMEOUT
    return Reason.CRASH


@dataclass(frozen=True)
class Lend:
    """A trusted object lent to student code (see :func:`autograder.suite.lend`)."""

    obj: Any
    methods: tuple[str, ...]
    attrs: tuple[str, ...] = ()


class Transport:
    """What a :class:`Namespace` talks to: requests, handles of one generation, and lent objects."""

    generation = 0

    def __init__(self) -> None:
        self.lent: dict[int, Lend] = {}
        self.lent_count = 0  # ids are never reused: a reference kept from an earlier test names nothing later

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float | None = None) -> Any:
        raise NotImplementedError

    def reference_of(self, value: Any) -> HandleRef | LentRef:
        """How a value that is not plain data crosses: a handle goes back, a lent object is registered."""
        if isinstance(value, Handle):
            return value._ref()
        if isinstance(value, Lend):
            self.lent_count += 1
            self.lent[self.lent_count] = value
            attrs = {name: getattr(value.obj, name) for name in value.attrs}
            return LentRef(self.lent_count, type(value.obj).__name__, list(value.methods), attrs)
        raise TypeError(f"cannot send a {type(value).__name__} to the sandbox")

    def call_lent(self, id: int, method: str, args: list, kwargs: dict) -> Any:
        lent = self.lent.get(id)
        if lent is None or method not in lent.methods:
            raise PermissionError(f"`{method}` is not lent")
        return getattr(lent.obj, method)(*args, **kwargs)


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
    tree_args, blobs = encode(list(args), transport.reference_of)
    tree_kwargs, more = encode(kwargs, transport.reference_of)
    if blobs and more:  # renumber only when both trees hold blobs
        tree_kwargs = _shift_blobs(tree_kwargs, len(blobs))
    return transport.request({"op": "call", "target": target, "args": tree_args, "kwargs": tree_kwargs},
                             blobs + more, timeout)


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


HELPERS = "helpers"
"""``student.helpers.f(...)`` calls ``f`` of the suite's ``sandbox_helpers.py``, run beside the notebook."""


class Namespace:
    """What a suite sees: ``ns.f(x)`` calls ``f`` on the other side, ``ns.eval("expr", a=x)`` evaluates,
    and ``ns.helpers.g(x)`` calls the suite's helper ``g`` there."""

    def __init__(self, transport: Transport, label: str, prefix: str = "") -> None:
        self._transport, self._label, self._prefix = transport, label, prefix

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if name == HELPERS and not self._prefix:
            return Namespace(self._transport, f"{self._label} helpers", prefix=f"{HELPERS}.")
        target = self._prefix + name

        def remote_function(*args: Any, timeout: float | None = None, **kwargs: Any) -> Any:
            return _call(self._transport, target, args, kwargs, timeout)

        remote_function.__name__ = name
        return remote_function

    def eval(self, expr: str, timeout: float | None = None, **bindings: Any) -> Any:
        tree, blobs = encode(bindings, self._transport.reference_of)
        return self._transport.request({"op": "eval", "expr": expr, "bindings": tree}, blobs, timeout)

    def defined(self, *names: str) -> list[str]:
        return self._transport.request({"op": "defined", "names": list(names)}, [])

    def __repr__(self) -> str:
        return f"<{self._label} namespace>"


WORKER_DATA_ERRORS = (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError, RecursionError)
"""Exceptions that reading, decoding or dispatching the worker's messages may raise on data no honest worker
sends (the wire turns what it foresees into :class:`ProtocolError`; these are the rest)."""


def _decode_reply(transport: Transport, header: dict[str, Any], blobs: list[bytes]) -> Any:
    if header.get("ok") is not True:
        raise StudentError(str(header.get("kind", "Error"))[:KIND_CHARS], str(header.get("error", "unknown error"))[:ERROR_CHARS])
    return decode(header.get("value"), blobs,
                  lambda id, type_name: Handle(transport, id, type_name, transport.generation))


class ReferenceCache:
    """Answers of the reference to calls it has seen, kept for the life of a :class:`~autograder.core.grader.Grader`.

    A hidden test asks the reference the same question for every submission (its inputs come from a seed,
    not from the student), so a batch computes each answer once. Only a call of a notebook function by name
    whose arguments and answer are plain data (arrays, numbers, containers: no handle, no lent object, so
    no generator whose state would advance) is kept; the answer is decoded afresh for every caller, so a
    test that changes what it received changes nothing kept. At most ``max_bytes`` of answers are kept.
    """

    def __init__(self, max_bytes: int = 256 * 2**20) -> None:
        self.answers: dict[str, tuple[Any, list[bytes]]] = {}
        self.max_bytes, self.bytes, self.hits = max_bytes, 0, 0

    @staticmethod
    def key(header: dict[str, Any], blobs: list[bytes]) -> str | None:
        if header.get("op") != "call" or type(header.get("target")) is not str or "." in header["target"]:
            return None
        text = json.dumps(header, sort_keys=True)
        if '"$handle"' in text or '"$lent"' in text:
            return None
        digest = hashlib.sha256(text.encode())
        for blob in blobs:
            digest.update(len(blob).to_bytes(8, "big"))
            digest.update(blob)
        return digest.hexdigest()

    def get(self, key: str | None) -> tuple[Any, list[bytes]] | None:
        answer = self.answers.get(key) if key is not None else None
        self.hits += answer is not None
        return answer

    def put(self, key: str | None, tree: Any, blobs: list[bytes]) -> None:
        size = sum(map(len, blobs))
        if key is None or self.bytes + size > self.max_bytes or '"$handle"' in json.dumps(tree):
            return
        self.answers[key] = (tree, blobs)
        self.bytes += size


class LocalTransport(Transport):
    """Runs requests against an in-process namespace (the reference), through the same encoding.

    Any exception here is the reference's: it becomes a :class:`ReferenceFault`, a grader error.
    ``cache``: where answers to plain-data calls are kept between submissions (see :class:`ReferenceCache`).
    """

    def __init__(self, namespace: dict[str, Any], helpers: str | None = None,
                 cache: ReferenceCache | None = None) -> None:
        super().__init__()
        self.worker = Worker(lent_call=self.call_lent)
        self.worker.namespace = namespace
        self.cache = cache
        if helpers is not None:
            self.worker.run({"op": "exec", "label": "suite helpers", "source": helpers, "module": HELPERS}, [])

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float | None = None) -> Any:
        key = self.cache.key(header, blobs) if self.cache is not None else None
        answer = self.cache.get(key) if key is not None else None
        if answer is None:
            try:
                value = self.worker.run(header, blobs)
                answer = encode(value, self.worker.to_handle)
            except Exception as err:  # noqa: BLE001 - whatever the reference raised, it is not the student's fault
                raise ReferenceFault(f"the reference failed on a hidden test's input ({type(err).__name__}: {err})") from err
            if key is not None:
                self.cache.put(key, *answer)
        return _decode_reply(self, {"ok": True, "value": answer[0]}, answer[1])


ReferenceCall = Callable[[str, Any, list[bytes]], tuple[dict, list[bytes]]]


def _refuse_objects(id: int, type_name: str) -> Any:
    raise ProtocolError("objects cannot be sent to a lent object")


class Session(Transport):
    """One submission's sandbox: runs its cells, serves calls, restarts after failures.

    ``reference_call`` answers the worker's requests to run a reference stub while a test stands
    it in for the student's own (see ``Worker.reference_stand_in``).
    """

    def __init__(self, zygote: Zygote, cells: list[Cell], config: SpawnConfig,
                 reference_call: ReferenceCall | None = None, missing: Iterable[str] = (),
                 unrunnable: dict[str, str] | None = None) -> None:
        super().__init__()
        self.zygote, self.cells, self.config = zygote, cells, config
        self.limits: Limits = config.limits
        self.reference_call = reference_call
        self.status: dict[str, CellStatus] = {
            name: CellStatus(False, f"no cell defines `{name}` (was its cell deleted, or the function renamed?)",
                             Reason.MISSING)
            for name in missing}
        self.status.update({name: CellStatus(False, why, Reason.UNREADABLE) for name, why in (unrunnable or {}).items()})
        self.worker: WorkerProcess | None = None
        self.pair = CpuPair(None)  # the worker's and this thread's CPU while callbacks come quickly
        self.generation = 0
        self.time_used = 0.0
        self.isolation = "unknown"
        self.restarts = 0
        self.standing_in: frozenset[str] = frozenset()
        self.test_deadline: float | None = None
        self.test_seconds = self.limits.test_seconds  # this test's limit (its own, or test_seconds)
        self.test_own_limit = False  # whether it is the test's own (then it bounds the suite's explicit timeouts too)
        self.test_credit = 0.0      # CPU wait forgiven in this test's calls so far
        self.credit_used = 0.0      # and in the whole submission's
        self.reference_calls = 0    # reference stand-in calls in this test
        self.messages = 0           # messages the grader sent to and read from its workers (a cheap counter)
        self.dead_worker_cpu_ns = 0  # CPU of the main threads of this session's workers that were killed
        self._test_start: dict[str, float] | None = None

    # -------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Start a worker and run every cell; a cell that fails is recorded (stubs) and skipped later."""
        self._spawn()
        for cell in self.cells:
            if cell.label in self.status and not self.status[cell.label].ok:
                continue
            self.status[cell.label] = self._exec(cell)

    def _spawn(self) -> None:
        """A fresh worker; raises :class:`GraderError` if it cannot start (no student code has run in it)."""
        self.close()
        self.generation += 1
        try:
            self.worker = self.zygote.spawn(self.config)
            self.worker.start(timeout=START_SECONDS)
        except (ChannelTimeout, ChannelClosed, ProtocolError, SandboxStartError, OSError) as err:
            if self.worker is not None:
                self.worker.kill()
            raise GraderError(f"the sandbox could not start: {err}") from None
        self.isolation = self.worker.isolation
        self.pair = CpuPair(self.worker.pid)

    def _exec(self, cell: Cell) -> CellStatus:
        try:
            self._raw({"op": "exec", "label": cell.label, "source": cell.source, "module": cell.module}, [],
                      self.limits.exec_seconds, explicit=True, cell=True)
            return CellStatus(True)
        except StudentError as err:
            if err.not_implemented:
                return CellStatus(False, "not implemented yet: the cell still raises NotImplementedError",
                                  Reason.NOT_IMPLEMENTED)
            return CellStatus(False, f"the cell `{cell.label}` failed when run: {err}", failure_reason(err))
        except SandboxFailure as err:
            message = f"running the cell `{cell.label}` {err}"
            self._spawn()  # a fresh worker for the cells after this one
            self._replay(upto=cell.label)
            return CellStatus(False, message, failure_reason(err))

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
        self.pair.release()
        if self.worker is not None:
            self.worker.kill()
            if self.worker.final_schedstat is not None:
                self.dead_worker_cpu_ns += self.worker.final_schedstat[0]
            self.worker = None

    def counters(self) -> dict[str, float]:
        """Cheap running totals for accounts: messages, the workers' main-thread CPU and run delay (s)."""
        stat = self.worker.schedstat() if self.worker is not None else None
        return {"messages": self.messages, "worker_cpu": (self.dead_worker_cpu_ns + (stat[0] if stat else 0)) / 1e9,
                "credit": self.credit_used, "time_used": self.time_used}

    # -------------------------------------------------------------- requests

    def begin_test(self, seconds: float | None = None) -> None:
        """A hidden test starts: from now its calls share one deadline, ``seconds`` away (the test's own limit,
        which then bounds every call of the test, those with a suite's own ``timeout`` too), else
        ``test_seconds`` away (which a suite's own ``timeout`` overrides)."""
        self.test_own_limit = seconds is not None
        self.test_seconds = float(seconds) if seconds is not None else self.limits.test_seconds
        self.test_deadline = time.monotonic() + self.test_seconds
        self.test_credit = 0.0
        self.reference_calls = 0
        self._test_start = {"wall": time.monotonic(), **self.counters()}

    def end_test(self) -> dict[str, float]:
        """The test is over; what it cost: wall seconds from its start, messages, the worker's CPU, the CPU wait
        forgiven."""
        self.test_deadline = None
        self.lent.clear()  # what a test lends is its own: code that kept a reference cannot call it in a later test
        start, self._test_start = self._test_start, None
        if start is None:
            return {}
        now = self.counters()
        return {"wall": time.monotonic() - start["wall"], "messages": now["messages"] - start["messages"],
                "worker_cpu": now["worker_cpu"] - start["worker_cpu"], "credit": self.test_credit,
                "limit": self.test_seconds}

    TIMEOUT_CALL, TIMEOUT_TOTAL, TIMEOUT_TEST = range(3)

    def _timeout_message(self, kind: int, seconds: float) -> str:
        if kind == self.TIMEOUT_CALL:
            return f"timed out after {seconds:.0f} s (an infinite loop, or far too slow)"
        if kind == self.TIMEOUT_TOTAL:
            return f"stopped: the submission used up its total time of {self.limits.submission_seconds:.0f} s"
        limit = f"{self.test_seconds:.0f} s" if self.test_seconds >= 10 else f"{self.test_seconds:.1f} s"
        return f"ran past this test's time limit of {limit} (an infinite loop, or far too slow)"

    def _deadline(self, timeout: float, explicit: bool, cell: bool = False) -> tuple[FairDeadline, str]:
        """When a request must be answered, and what the student is told if it is not.

        The earliest of: the call's own limit, the test's deadline (unless the request runs a cell, or the suite
        gave this call a ``timeout`` of its own and the test has no limit of its own), and what is left of the
        submission's total time. None of them counts the worker's wait for a busy CPU, up to
        ``CPU_WAIT_STRETCH`` times each limit.
        """
        now = time.monotonic()
        total = self.limits.submission_seconds
        left = total - self.time_used
        if left <= 0:
            raise SandboxTimeout(self._timeout_message(self.TIMEOUT_TOTAL, total))
        stretch = CPU_WAIT_STRETCH - 1
        bounds = [(timeout, stretch * timeout, self.TIMEOUT_CALL), (left, stretch * total - self.credit_used,
                                                                   self.TIMEOUT_TOTAL)]
        if self.test_deadline is not None and not cell and (self.test_own_limit or not explicit):
            test_room = stretch * self.test_seconds - self.test_credit
            bounds.append((self.test_deadline + min(self.test_credit, stretch * self.test_seconds) - now,
                           max(0.0, test_room), self.TIMEOUT_TEST))
        seconds, room, kind = min(bounds, key=lambda bound: bound[0])
        why = self._timeout_message(kind, timeout)
        if seconds <= 0:
            raise SandboxTimeout(why)
        return FairDeadline(seconds, self.worker, max(0.0, min(room, stretch * seconds))), why

    def _raw(self, header: dict[str, Any], blobs: list[bytes], timeout: float, explicit: bool = False,
             cell: bool = False) -> Any:
        """Send one request and read its answer, serving the worker's callbacks meanwhile, all by one deadline.

        Every write and read of the exchange, and the grader's own work for callbacks (a reference stand-in,
        a lent object's method), count against that deadline, so a worker that stops reading, answers
        slowly or keeps calling back is stopped when it passes.
        """
        deadline, why = self._deadline(timeout, explicit, cell)
        start = time.monotonic()
        try:
            self.messages += 2
            self.worker.send(header, blobs, deadline)
            reply, reply_blobs = self.worker.receive(deadline)
            while "callback" in reply:  # the student's code called back into the grader: answer, read on
                self.pair.callback()
                answer, answer_blobs = self._answer(reply, reply_blobs)
                del reply_blobs
                if deadline.left() <= 0:
                    raise ChannelTimeout(why)
                self.messages += 2
                self.worker.send(answer, answer_blobs, deadline)
                if self.pair.pinned and not self.worker.reader.ready(IDLE_SECONDS):
                    self.pair.release()  # the worker is computing: it no longer needs to share a CPU
                reply, reply_blobs = self.worker.receive(deadline)
            return _decode_reply(self, reply, reply_blobs)
        except ChannelTimeout:
            self.worker.kill()
            if self.worker.flooded:
                why = (f"printed more than {OUTPUT_READ_BYTES // 2**20} MB, which the grader stopped reading, so its "
                       "next print waited until its time ran out")
            raise SandboxTimeout(why) from None
        except TrustedWorkTimeout:  # interrupted mid-exchange: the channel is out of step, the worker must go
            self.worker.kill()
            raise
        except (ChannelClosed, BrokenPipeError, OSError):
            tail = self.worker.tail().strip()
            self.worker.kill()
            if self.worker.over_limit == "memory":
                raise SandboxFailure(f"used more than {self.limits.memory_bytes / 2**30:.3g} GB of memory, counting "
                                     "every process it started, and was stopped") from None
            if self.worker.over_limit == "cpus":
                raise SandboxFailure("kept several processes or threads computing at once, and was stopped: a "
                                     "submission has one CPU, which its code must not share out (the machine "
                                     "grades others beside it)") from None
            raise SandboxFailure("crashed the sandbox (the process exited or was killed: out of memory, "
                                 "os._exit, a signal, or a resource limit)"
                                 + (f"; its last output: {tail[-TAIL_QUOTED:]}" if tail else "")) from None
        except (ProtocolError, *WORKER_DATA_ERRORS) as err:
            # Everything read in this exchange came from the worker, the student's process: data the grader cannot
            # take (a malformed callback, a header it cannot parse) is the submission's failure, never a grader fault.
            self.worker.kill()
            raise SandboxFailure(f"sent malformed data back to the grader ({str(err)[:TAIL_QUOTED]})") from None
        finally:
            self.pair.release()
            credit = deadline.credit()
            self.time_used += max(0.0, time.monotonic() - start - credit)
            self.credit_used += credit
            self.test_credit += credit

    def _answer(self, reply: dict[str, Any], blobs: list[bytes]) -> tuple[dict[str, Any], list[bytes]]:
        """Answer a callback: a reference stand-in (only for the stubs standing in now) or a lent object's method."""
        callback = reply.get("callback")
        if type(callback) is not dict:
            raise ProtocolError("malformed callback")
        if "reference" in callback:
            name = callback["reference"]
            if type(name) is not str:
                raise ProtocolError("malformed callback: a reference's name must be a string")
            if self.reference_call is None or name not in self.standing_in:
                return {"ok": False, "error": f"`{name}` is not available from the grader now"}, []
            self.reference_calls += 1
            if self.reference_calls > self.limits.reference_calls:
                return {"ok": False, "error": f"`{name}` was called more than {self.limits.reference_calls} times "
                                              "in one test: the grader answers no more"}, []
            answer, answer_blobs = self.reference_call(str(name), reply.get("args"), blobs)
            if sum(len(b) for b in answer_blobs) > self.limits.message_bytes:
                return {"ok": False, "error": f"`{name}`'s answer is larger than the channel carries"}, []
            return answer, answer_blobs
        if "lent" in callback:
            return self._answer_lent(callback.get("lent"), str(callback.get("method")), reply.get("args"), blobs)
        raise ProtocolError("unknown callback")

    def _answer_lent(self, id: Any, method: str, tree: Any, blobs: list[bytes]) -> tuple[dict[str, Any], list[bytes]]:
        try:
            args, kwargs = decode(tree, blobs, _refuse_objects)
            out_tree, out_blobs = encode(self.call_lent(id, method, args, kwargs))
            return {"ok": True, "value": out_tree}, out_blobs
        except (ProtocolError, TrustedWorkTimeout):
            raise
        except Exception as err:  # noqa: BLE001 - bad arguments from student code: its exception, not the grader's
            return {"ok": False, "error": f"{type(err).__name__}: {str(err)[:TAIL_QUOTED]}"}, []

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
        return self._raw(header, blobs, timeout or self.limits.call_seconds, explicit=timeout is not None)
