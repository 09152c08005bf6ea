"""The grader's handle on sandbox workers. Runs in the grader (trusted), never in the sandbox.

:class:`Zygote` forks the sandbox's zygote (:mod:`autograder.sandbox.zygote`) and asks it for
workers; :class:`WorkerProcess` is the grader's end of one worker: its request channel, a drain
of its output, and the kill that ends it and everything it started.

The zygote is the parent of every worker, so whatever is in the grader's memory when the zygote
forks is in every worker's memory, where student code can find it (through the garbage
collector, say). Reference namespaces hold the solutions: :func:`reference_namespace` makes them
and :class:`Zygote` refuses to fork while any is alive.
"""
from __future__ import annotations

import gc
import json
import os
import signal
import socket
import threading
import weakref
from dataclasses import asdict
from typing import Any

from autograder.sandbox.config import SpawnConfig
from autograder.sandbox.isolation import PR_SET_DUMPABLE, _libc
from autograder.sandbox.wire import FrameReader, send_message

OUTPUT_KEEP = 4096
"""Bytes of a worker's stdout/stderr kept (the newest): enough context for a crash message."""
TAIL_CHARS = 1500
"""Characters of that output a crash message may quote."""


class ReferenceLeak(RuntimeError):
    """A zygote was about to fork while a reference namespace is alive in this process."""


class ReferenceNamespace(dict):
    """The namespace a solution notebook runs in; weakly referenceable, so the grader can tell if one lives."""

    __hash__ = object.__hash__


_references: list[weakref.ref] = []


def reference_namespace() -> ReferenceNamespace:
    """A new, empty reference namespace, recorded so that no zygote forks while it is alive."""
    namespace = ReferenceNamespace(__name__="__reference__")
    _references.append(weakref.ref(namespace))
    return namespace


def live_references() -> int:
    """How many reference namespaces are alive in this process (after a garbage collection)."""
    gc.collect()
    _references[:] = [r for r in _references if r() is not None]
    return len(_references)


class Zygote:
    """A pristine, pre-imported process that forks workers on request."""

    def __init__(self, preload: list[str]) -> None:
        if live_references():
            raise ReferenceLeak("a sandbox zygote must fork before any reference namespace exists in this process "
                                f"({live_references()} alive): every worker would inherit the solutions")
        from autograder.sandbox import zygote

        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        pid = os.fork()
        if pid == 0:
            parent.close()
            try:
                zygote.main(child, preload)
            finally:
                os._exit(0)
        child.close()
        self.sock, self.pid = parent, pid
        self.lock = threading.Lock()
        _libc.prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)  # workers may not read the grader's memory

    def spawn(self, config: SpawnConfig) -> "WorkerProcess":
        to_r, to_w = os.pipe()
        from_r, from_w = os.pipe()
        out_r, out_w = os.pipe()
        message = json.dumps(asdict(config)).encode()
        with self.lock:
            socket.send_fds(self.sock, [message], [to_r, from_w, out_w])
        for fd in (to_r, from_w, out_w):
            os.close(fd)
        return WorkerProcess(to_w, from_r, out_r)

    def close(self) -> None:
        self.sock.close()
        try:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass


class SandboxStartError(RuntimeError):
    """The worker reported that it could not isolate itself; no student code ran."""


class WorkerProcess:
    """The grader's end of one worker: request channel, output capture, and kill."""

    def __init__(self, to_fd: int, from_fd: int, out_fd: int) -> None:
        self.to_fd, self.reader, self.out_fd = to_fd, FrameReader(from_fd), out_fd
        self.output = bytearray()
        self.pid = self.pgid = None
        self.isolation = "unknown"
        self.alive = True
        self._drain = threading.Thread(target=self._read_output, daemon=True)
        self._drain.start()

    def _read_output(self) -> None:
        while True:
            try:
                chunk = os.read(self.out_fd, 65536)
            except OSError:
                return
            if not chunk:
                return
            self.output += chunk
            del self.output[:-OUTPUT_KEEP]

    def start(self, timeout: float) -> dict[str, Any]:
        """Read the launcher's pid report and the worker's ready message."""
        header, _ = self.reader.read_message(timeout)
        self.pid, self.pgid, self.isolation = header.get("pid"), header.get("pgid"), header.get("isolation")
        ready, _ = self.reader.read_message(timeout)
        if not ready.get("ok"):
            raise SandboxStartError(ready.get("error", "the sandbox failed to start"))
        return header

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float) -> tuple[dict[str, Any], list[bytes]]:
        send_message(self.to_fd, header, blobs)
        return self.reader.read_message(timeout)

    def tail(self) -> str:
        return bytes(self.output[-TAIL_CHARS:]).decode("utf-8", "replace")

    def kill(self) -> None:
        """Kill the worker and, through its PID namespace (or process group), everything it started."""
        if not self.alive:
            return
        self.alive = False
        for target, kill in ((self.pid, os.kill), (self.pgid, os.killpg)):
            if isinstance(target, int) and target > 1:
                try:
                    kill(target, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
        for fd in (self.to_fd, self.reader.fd, self.out_fd):
            try:
                os.close(fd)
            except OSError:
                pass
