"""The grader's handle on sandbox workers. Runs in the grader (trusted), never in the sandbox.

:class:`Zygote` starts the sandbox's zygote (:mod:`autograder.sandbox.zygote`) and asks it for
workers; :class:`WorkerProcess` is the grader's end of one worker: its request channel, a drain
of its output, and the kill that ends it and everything it started.

Every worker inherits the zygote's memory, where student code can search (through the garbage
collector, say). So the zygote is never a fork of the grader, whose memory holds the reference
solutions once it has built them, its suites and, under pytest, every test module: it is a new
interpreter that starts from nothing but this package's sandbox room.
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import asdict
from typing import Any

from autograder.core.tree_guard import TreeGuard
from autograder.sandbox.config import ZYGOTE_READY, SpawnConfig, safe_environment
from autograder.sandbox.isolation import PR_SET_DUMPABLE, libc
from autograder.sandbox.wire import MAX_MESSAGE_BYTES, FrameReader, send_message

OUTPUT_KEEP = 4096
"""Bytes of a worker's stdout/stderr kept (the newest): enough context for a crash message."""
TAIL_CHARS = 1500
"""Characters of that output a crash message may quote."""
OUTPUT_READ_BYTES = 64 * 2**20
"""Bytes of a worker's output the grader reads at most. Reading costs the grader's process about as much CPU as
writing costs the worker, outside the worker's limits; past this the grader stops reading, the worker's next
write blocks, and its time limit ends it."""
PRELOAD_SECONDS = 600.0
"""How long the zygote may take to import the course's modules (torch, mujoco...) before its first worker.
Apart from a worker's own start deadline: on a loaded machine with a cold disk the imports alone can
take longer than a worker may take to start, and a slow machine is the grader's fault, not a student's."""


def zygote_environment() -> dict[str, str]:
    """The zygote's (so every worker's) environment: the safe variables only, with this grader's own checkout
    first on ``PYTHONPATH``, so that workers import the same sandbox and course library as the grader even
    when the Python environment was installed (editable) from another checkout."""
    from autograder.core import course

    env = safe_environment(dict(os.environ))
    rest = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join([str(course.INSTALLED), *rest])
    return env


class Zygote:
    """A pristine, pre-imported process that forks workers on request."""

    def __init__(self, preload: list[str]) -> None:
        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "autograder.sandbox.zygote", str(child.fileno()), json.dumps(preload),
             str(os.getpid())],
            pass_fds=[child.fileno()], stdin=subprocess.DEVNULL, cwd="/", env=zygote_environment())
        child.close()
        self.sock = parent
        self.lock = threading.Lock()
        self.ready = False
        libc.prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)  # workers may not read the grader's memory

    def spawn(self, config: SpawnConfig) -> "WorkerProcess":
        """A new worker isolated as ``config`` says; what it sends back is capped at its ``message_bytes``."""
        message = json.dumps(asdict(config)).encode()
        with self.lock:
            self._wait_ready()
            to_r, to_w = os.pipe()
            from_r, from_w = os.pipe()
            out_r, out_w = os.pipe()
            try:
                socket.send_fds(self.sock, [message], [to_r, from_w, out_w])
            except OSError:
                for fd in (to_w, from_r, out_r):
                    os.close(fd)
                raise
            finally:
                for fd in (to_r, from_w, out_w):
                    os.close(fd)
        return WorkerProcess(to_w, from_r, out_r, config.limits.message_bytes, config.limits.memory_bytes)

    def _wait_ready(self) -> None:
        """Wait, once, for the zygote's word that its imports are done; raises :class:`SandboxStartError`."""
        if self.ready:
            return
        self.sock.settimeout(PRELOAD_SECONDS)
        try:
            word = self.sock.recv(len(ZYGOTE_READY))
        except TimeoutError:
            raise SandboxStartError(f"the sandbox's host process did not finish importing the course's modules "
                                    f"in {PRELOAD_SECONDS:.0f} s") from None
        finally:
            self.sock.settimeout(None)
        if word != ZYGOTE_READY:
            raise SandboxStartError("the sandbox's host process ended while importing the course's modules")
        self.ready = True

    def close(self) -> None:
        self.sock.close()
        self.process.kill()
        self.process.wait()


class SandboxStartError(RuntimeError):
    """The worker reported that it could not isolate itself; no student code ran."""


class WorkerProcess:
    """The grader's end of one worker: request channel, output capture, and kill."""

    def __init__(self, to_fd: int, from_fd: int, out_fd: int, max_message: int = MAX_MESSAGE_BYTES,
                 memory_bytes: int | None = None) -> None:
        # Every write and read has a deadline: a worker that stops reading cannot hold the grader, and a read
        # tries at once and polls only when nothing has come yet.
        os.set_blocking(to_fd, False)
        os.set_blocking(from_fd, False)
        self.to_fd, self.reader, self.out_fd = to_fd, FrameReader(from_fd, max_message), out_fd
        self.memory_bytes = memory_bytes
        self.guard: TreeGuard | None = None
        self._schedstat: int | None = None  # /proc/PID/schedstat, kept open: a pread is a tenth of an open and read
        self.final_schedstat: tuple[int, int] | None = None
        """The worker's (CPU ns, run-delay ns) as it was killed, for accounts that outlive it."""
        self.output = bytearray()
        self.flooded = False
        """Whether the worker wrote more than :data:`OUTPUT_READ_BYTES` and the grader stopped reading it."""
        self.pid = self.pgid = None
        self.isolation = "unknown"
        self.alive = True
        self._drain = threading.Thread(target=self._read_output, daemon=True)
        self._drain.start()

    def _read_output(self) -> None:
        read = 0
        while True:
            try:
                chunk = os.read(self.out_fd, 65536)
            except OSError:
                return
            if not chunk:
                return
            self.output += chunk
            del self.output[:-OUTPUT_KEEP]
            read += len(chunk)
            if read > OUTPUT_READ_BYTES:
                self.flooded = True
                return

    def start(self, timeout: float) -> dict[str, Any]:
        """Read the launcher's pid report and the worker's ready message."""
        deadline = time.monotonic() + timeout
        header, _ = self.reader.read_message(deadline=deadline)
        self.pid, self.pgid, self.isolation = header.get("pid"), header.get("pgid"), header.get("isolation")
        if self.memory_bytes and isinstance(self.pgid, int) and self.pgid > 1:  # the launcher leads the group
            self.guard = TreeGuard(self.pgid, self.memory_bytes, self._signal_tree)  # the grader's thread closes
        ready, _ = self.reader.read_message(deadline=deadline)
        if not ready.get("ok"):
            raise SandboxStartError(ready.get("error", "the sandbox failed to start"))
        return header

    def schedstat(self) -> tuple[int, int] | None:
        """(CPU ns, run-delay ns) of the worker's main thread, from ``/proc/PID/schedstat``; None where the kernel
        does not say. The file is opened once and read again with ``pread``: a fair deadline may read it often."""
        if not isinstance(self.pid, int) or not self.alive:
            return None
        try:
            if self._schedstat is None:
                self._schedstat = os.open(f"/proc/{self.pid}/schedstat", os.O_RDONLY | os.O_CLOEXEC)
            run, wait, *_ = os.pread(self._schedstat, 128, 0).split()
            return int(run), int(wait)
        except (OSError, ValueError):
            return None

    def cpu_wait(self) -> float | None:
        """Seconds the worker has spent runnable but waiting for a CPU (the kernel's run delay of its main
        thread, in ``/proc/PID/schedstat``); None where the kernel does not say."""
        stat = self.schedstat()
        return None if stat is None else stat[1] / 1e9

    def send(self, header: dict[str, Any], blobs: list[bytes], deadline: Any) -> None:
        """Write a message; raises ``ChannelTimeout`` if the worker has not taken it all by ``deadline``."""
        send_message(self.to_fd, header, blobs, deadline)

    def receive(self, deadline: Any) -> tuple[dict[str, Any], list[bytearray]]:
        """Read a message, whole and within the size cap, by ``deadline``."""
        return self.reader.read_message(deadline=deadline)

    @property
    def over_limit(self) -> str | None:
        """Why the guard killed the worker's tree: "memory" (it held more than its limit), "cpus" (it kept
        several tasks busy at once), or None."""
        return None if self.guard is None else self.guard.exceeded

    def tail(self) -> str:
        return bytes(self.output[-TAIL_CHARS:]).decode("utf-8", "replace")

    def _signal_tree(self) -> None:
        """SIGKILL to the worker and its process group (the PID namespace takes the rest with its init)."""
        for target, kill in ((self.pid, os.kill), (self.pgid, os.killpg)):
            if isinstance(target, int) and target > 1:
                try:
                    kill(target, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass

    def kill(self) -> None:
        """Kill the worker and, through its PID namespace (or process group), everything it started."""
        if self.guard is not None:
            self.guard.stop()
        if not self.alive:
            return
        self.final_schedstat = self.schedstat()
        self.alive = False
        self._signal_tree()
        if self._schedstat is not None:
            try:
                os.close(self._schedstat)
            except OSError:
                pass
        for fd in (self.to_fd, self.reader.fd, self.out_fd):
            try:
                os.close(fd)
            except OSError:
                pass
