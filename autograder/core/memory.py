"""A cap on the memory of a worker's whole process tree, enforced from the grader's side.

The kernel's ``RLIMIT_AS`` (set in the worker) caps each process, not the sandbox: a submission that forks
holds up to ``processes x memory_bytes``. The control groups that would cap the tree in the kernel are not
available everywhere (version 1 only on the course's machines, none for a normal user, none in most
graders' containers), so the grader accounts for it itself: a thread sums the private resident memory of
every process descended from the worker's launcher and kills the tree as soon as the sum passes the limit.
Orphans stay in the tree: the launcher is a child subreaper, and in a PID namespace the worker is init.

Between two looks the tree can grow by what it allocates in :data:`INTERVAL` (a few hundred MB at most on
these machines), so the cap binds within that margin; the bench (``bench_grader_limits.py``) measures it.
"""
from __future__ import annotations

import os
import signal
import threading
from typing import Callable

INTERVAL = 0.1
"""Seconds between two looks at the tree."""
PAGE = os.sysconf("SC_PAGE_SIZE")


def _parents() -> dict[int, int]:
    """pid -> parent pid of every process this one may see (``/proc/PID/stat`` is readable by anyone)."""
    out = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", "rb") as f:
                    stat = f.read()
                out[int(entry)] = int(stat[stat.rindex(b")") + 2:].split(maxsplit=2)[1])
            except (OSError, ValueError, IndexError):
                pass
    return out


def tree(root: int) -> list[int]:
    """``root`` and every process descended from it."""
    children: dict[int, list[int]] = {}
    for pid, parent in _parents().items():
        children.setdefault(parent, []).append(pid)
    found, todo = [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo += children.get(pid, [])
    return found


def private_bytes(pid: int) -> int:
    """Resident memory of ``pid`` that is not a shared file mapping (``/proc/PID/statm``: resident - shared)."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as f:
            fields = f.read().split()
        return max(0, int(fields[1]) - int(fields[2])) * PAGE
    except (OSError, ValueError, IndexError):
        return 0


def tree_bytes(root: int) -> int:
    """The private resident memory of ``root``'s whole tree."""
    return sum(private_bytes(pid) for pid in tree(root))


class MemoryGuard:
    """Watches the tree under ``root`` (the worker's launcher) and calls ``kill`` when it holds over ``limit``."""

    def __init__(self, root: int, limit: int, kill: Callable[[], None], interval: float = INTERVAL) -> None:
        self.root, self.limit, self.kill, self.interval = root, limit, kill, interval
        self.exceeded = False
        self.peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name=f"memory-guard-{root}", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.wait(self.interval):
            pids = tree(self.root)
            if len(pids) <= 1 and not os.path.exists(f"/proc/{self.root}"):
                return
            held = sum(private_bytes(pid) for pid in pids)
            self.peak = max(self.peak, held)
            if held > self.limit:
                self.exceeded = True
                for pid in pids:  # a process that left the process group is still in the tree
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except (ProcessLookupError, PermissionError):
                        pass
                self.kill()
                return

    def stop(self) -> None:
        self._stop.set()
