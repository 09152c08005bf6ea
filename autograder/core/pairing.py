"""Keep a worker and the grader's thread on one CPU while they trade messages quickly. Runs in the grader.

A lent object's round trips (hw3's duels: about a thousand in one call) are a ping-pong: at any moment one side
computes and the other waits. Left to the scheduler, each side sleeps on its own CPU and every message wakes
an idle CPU on the other core; on a small VM that costs more than the protocol itself (measured by
``bench/bench_channel.py``: a bare pipe ping-pong costs 3-6 us of CPU a round trip on one CPU and 20-30 us
across two). While the round trips are quick, :class:`CpuPair` pins both to the CPU the grader is on, and lets
go as soon as the worker keeps the grader waiting longer than :data:`IDLE_SECONDS` (it is computing, so the
pair no longer needs one CPU), at the end of the request, and every :data:`REPAIR_EVERY` round trips (so the
scheduler chooses again, and two graders that pinned to one CPU part). Only the worker's main thread is pinned;
a thread the student starts while it is inherits the CPU.

Pinning only narrows where the two may run, so it loosens no limit: a worker waiting for a busy CPU is forgiven
that time as always (``FairDeadline``), up to the same cap. Where the kernel refuses (a grader whose root lacks
``CAP_SYS_NICE`` pinning a worker of another uid, a CPU set that excludes the CPU), nothing is pinned.
"""
from __future__ import annotations

import ctypes
import os

PAIR_AFTER = 16
"""Callbacks in one request before the pair is pinned: a test's few reference stand-in calls are not pinned."""
IDLE_SECONDS = 0.002
"""The worker took longer than this to send its next message: it is computing, let go."""
REPAIR_EVERY = 1024
"""Round trips pinned before letting go (to pin again, on whichever CPU the grader is then on, after
:data:`PAIR_AFTER` more)."""


def _sched_getcpu() -> int | None:
    try:
        cpu = ctypes.CDLL(None, use_errno=True).sched_getcpu
    except (OSError, AttributeError):
        return None
    cpu.restype = ctypes.c_int
    return cpu if cpu() >= 0 else None


_getcpu = _sched_getcpu()
"""libc's ``sched_getcpu`` (the CPU the calling thread runs on), or None where there is none."""


class CpuPair:
    """The pinning of one worker (``pid``, its main thread) and the calling grader thread."""

    def __init__(self, pid: int | None) -> None:
        self.pid = pid
        self.callbacks = 0  # in the current request
        self.pinned_trips = 0
        self._saved: tuple[set[int], set[int]] | None = None  # (grader's, worker's) masks while pinned
        self.pinnings = 0  # how many times it pinned (for tests and accounts)

    @property
    def pinned(self) -> bool:
        return self._saved is not None

    def callback(self) -> None:
        """The worker called back (a round trip is under way): pin after :data:`PAIR_AFTER` of them in this
        request, let go every :data:`REPAIR_EVERY` pinned ones."""
        self.callbacks += 1
        if self._saved is not None:
            self.pinned_trips += 1
            if self.pinned_trips >= REPAIR_EVERY:
                self.release()
        elif self.callbacks >= PAIR_AFTER:
            self._pin()

    def _pin(self) -> None:
        self.callbacks = 0
        if _getcpu is None or not isinstance(self.pid, int):
            return
        cpu = _getcpu()
        try:
            mine, theirs = os.sched_getaffinity(0), os.sched_getaffinity(self.pid)
            if cpu not in mine or cpu not in theirs:
                return
            os.sched_setaffinity(self.pid, {cpu})
        except OSError:
            return
        try:
            os.sched_setaffinity(0, {cpu})
        except OSError:
            self._restore(mine, theirs)
            return
        self._saved, self.pinned_trips = (mine, theirs), 0
        self.pinnings += 1

    def release(self) -> None:
        """Let both run anywhere they could before (the worker only if it still exists)."""
        self.callbacks = 0
        if self._saved is not None:
            saved, self._saved = self._saved, None
            self._restore(*saved)

    def _restore(self, mine: set[int], theirs: set[int]) -> None:
        for pid, mask in ((0, mine), (self.pid, theirs)):
            try:
                os.sched_setaffinity(pid, mask)
            except OSError:  # the worker is gone
                pass
