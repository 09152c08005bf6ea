"""Bounds on the work the grader does on a submission's behalf while one hidden test runs.

A test's calls into the sandbox have deadlines, but the grader also works for the submission: it answers
its callbacks (a reference stand-in, a lent object's method), decodes what it returns and, in the test's
own code, builds and checks objects from it. A submission that chooses those inputs can ask for hours of
work or gigabytes of memory. So each test runs inside :func:`bounded`: a timer interrupts the grader's
main thread at the test's time bound (its limit stretched as far as a fair deadline may stretch), and the
process's address space may grow by at most ``extra_bytes`` while the test runs, so an allocation beyond it
fails (``MemoryError``) instead of swelling the grader. Either ends the test as the submission's failure.

The timer needs the main thread (signals are delivered there); elsewhere only the memory bound holds.
"""
from __future__ import annotations

import contextlib
import os
import resource
import signal
import threading
from typing import Iterator

PAGE = os.sysconf("SC_PAGE_SIZE")


class TrustedWorkTimeout(Exception):
    """The grader's work for one test (its calls and callbacks included) ran past the test's bound."""


def address_space() -> int:
    """This process's current virtual size in bytes (``/proc/self/statm``)."""
    with open("/proc/self/statm", "rb") as f:
        return int(f.read().split()[0]) * PAGE


def _interrupt(signum: int, frame: object) -> None:
    raise TrustedWorkTimeout("the grader's work on this test (running your code and checking what it returned) "
                             "passed the test's time limit")


@contextlib.contextmanager
def bounded(seconds: float, extra_bytes: int) -> Iterator[None]:
    """Run the block with at most ``seconds`` of wall time and ``extra_bytes`` more address space."""
    timer = threading.current_thread() is threading.main_thread() and seconds > 0
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    cap = address_space() + extra_bytes
    limited = extra_bytes > 0 and (hard == resource.RLIM_INFINITY or cap <= hard) \
        and (soft == resource.RLIM_INFINITY or cap < soft)
    previous = None
    if timer:
        previous = signal.signal(signal.SIGALRM, _interrupt)
        signal.setitimer(signal.ITIMER_REAL, seconds)
    if limited:
        resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        if limited:
            resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
        if timer:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
