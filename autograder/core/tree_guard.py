"""Caps on a worker's whole process tree, enforced from the grader's side: its memory and its CPUs.

The kernel's limits set in the worker cap each process, not the sandbox: a submission that forks holds up to
``processes x memory_bytes``, and keeps as many CPUs busy as it starts processes or threads, each within its
own CPU-time limit. The control groups that would cap the tree in the kernel are not available everywhere
(version 1 only on the course's machines, none for a normal user, none in most graders' containers), so the
grader accounts for the tree itself: a thread looks at every process descended from the worker's launcher
every :data:`INTERVAL` seconds and kills the tree as soon as

- **memory**: the tree holds more than the limit: each process's anonymous and shared-memory resident pages
  (``RssAnon + RssShmem``: what it allocated, shared mappings included, but not the pages of files it read),
  plus memory files (``memfd_create``) it holds open without mapping them, each counted once, and still does
  when pages shared between its processes (a fork's) are counted once (``Pss_Anon + Pss_Shmem``, read only
  then, being dearer); or
- **CPUs**: on average over :data:`CPU_WINDOW` seconds, more than :data:`MAX_BUSY_TASKS` of its tasks
  (threads included) were running or waiting to run. A worker computes on one thread (the zygote sets
  every math library to one), so a tree that keeps several busy is taking CPU time from the submissions
  graded beside it; counting tasks that *want* a CPU, not the CPU time they got, catches it however short
  its processes live and however loaded the machine is.

Orphans stay in the tree: the launcher is a child subreaper, and in a PID namespace the worker is init.
Between two looks the tree can grow by what it allocates in :data:`INTERVAL` (a few hundred MB at most on
these machines), so the cap binds within that margin; the bench (``bench_grader_limits.py``) measures it.
System V shared memory, which outlives every mapping, is closed in the worker's own IPC namespace instead
(:func:`autograder.sandbox.isolation.close_ipc`).
"""
from __future__ import annotations

import collections
import os
import signal
import threading
from typing import Callable

INTERVAL = 0.1
"""Seconds between two looks at the tree."""
CPU_WINDOW = 2.0
"""Seconds over which the tree's busy tasks are averaged."""
MAX_BUSY_TASKS = 1.5
"""The most tasks that may, on average over :data:`CPU_WINDOW`, be running or runnable: one computing thread,
with room for a second one's short bursts (a thread that wakes up to write, say)."""
PAGE = os.sysconf("SC_PAGE_SIZE")


def _stat_fields(path: str) -> list[bytes] | None:
    """The fields of a ``/proc/.../stat`` file after the command name (state first), or None."""
    try:
        with open(path, "rb") as f:
            stat = f.read()
        return stat[stat.rindex(b")") + 2:].split()
    except (OSError, ValueError):
        return None


def _parents() -> dict[int, int]:
    """pid -> parent pid of every process this one may see (``/proc/PID/stat`` is readable by anyone)."""
    out = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            fields = _stat_fields(f"/proc/{entry}/stat")
            if fields and len(fields) > 1:
                out[int(entry)] = int(fields[1])
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
    """Resident memory ``pid`` allocated (``RssAnon + RssShmem`` in ``/proc/PID/status``): not the pages of
    files it mapped to read, but every anonymous page and every shared-memory page (``mmap(-1, ...)`` shared,
    a mapped memory file), which a count of resident minus shared pages would miss."""
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            status = f.read()
    except OSError:
        return 0
    total = 0
    for line in status.splitlines():
        if line.startswith((b"RssAnon:", b"RssShmem:")):
            try:
                total += int(line.split()[1]) * 1024
            except (IndexError, ValueError):
                pass
    return total


def proportional_bytes(pid: int) -> int | None:
    """``pid``'s share of its anonymous and shared-memory pages (``Pss_Anon + Pss_Shmem`` in ``smaps_rollup``): a
    page shared by k processes counts 1/k in each, so a tree's sum counts it once. About a thousand times dearer
    to read than ``status`` (the kernel walks the page tables), so it only confirms a tree that
    :func:`private_bytes` puts over the limit. ``None`` where the kernel does not give it or the process hides it."""
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as f:
            rollup = f.read()
    except OSError:  # gone, or hidden (a process that made itself undumpable): its resident count stands
        return None
    total, found = 0, False
    for line in rollup.splitlines():
        if line.startswith((b"Pss_Anon:", b"Pss_Shmem:")):
            try:
                total += int(line.split()[1]) * 1024
                found = True
            except (IndexError, ValueError):
                pass
    return total if found else None


def memory_file_bytes(pids: list[int]) -> int:
    """Bytes of the memory files (``memfd_create``) the processes ``pids`` hold open, each file once: such a file
    holds memory whether or not anything maps it."""
    seen: dict[tuple[int, int], int] = {}
    for pid in pids:
        folder = f"/proc/{pid}/fd"
        try:
            fds = os.listdir(folder)
        except OSError:
            continue
        for fd in fds:
            try:
                if not os.readlink(f"{folder}/{fd}").startswith("/memfd:"):
                    continue
                st = os.stat(f"{folder}/{fd}")
            except OSError:
                continue
            seen[(st.st_dev, st.st_ino)] = st.st_blocks * 512
    return sum(seen.values())


def tree_bytes(root: int) -> int:
    """The memory ``root``'s whole tree holds (see :func:`private_bytes` and :func:`memory_file_bytes`)."""
    pids = tree(root)
    return sum(private_bytes(pid) for pid in pids) + memory_file_bytes(pids)


def busy_tasks(pids: list[int]) -> int:
    """How many threads of the processes ``pids`` are running or waiting for a CPU (state ``R``) now."""
    busy = 0
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            fields = _stat_fields(f"/proc/{pid}/task/{tid}/stat")
            busy += bool(fields) and fields[0] == b"R"
    return busy


class TreeGuard:
    """Watches the tree under ``root`` (the worker's launcher) and calls ``kill`` when it holds more than ``limit``
    bytes (``exceeded == "memory"``) or keeps more than :data:`MAX_BUSY_TASKS` tasks busy (``"cpus"``)."""

    def __init__(self, root: int, limit: int, kill: Callable[[], None], interval: float = INTERVAL,
                 max_busy: float = MAX_BUSY_TASKS, window: float = CPU_WINDOW) -> None:
        self.root, self.limit, self.kill, self.interval = root, limit, kill, interval
        self.max_busy = max_busy
        self.exceeded: str | None = None
        self.peak = 0
        self.peak_busy = 0.0
        """The largest average of busy tasks over a full window."""
        self._busy: collections.deque[int] = collections.deque(maxlen=max(1, round(window / interval)))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name=f"tree-guard-{root}", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.wait(self.interval):
            pids = tree(self.root)
            if len(pids) <= 1 and not os.path.exists(f"/proc/{self.root}"):
                return
            held = sum(private_bytes(pid) for pid in pids) + memory_file_bytes(pids)
            self.peak = max(self.peak, held)
            self._busy.append(busy_tasks(pids))
            if len(self._busy) == self._busy.maxlen:
                self.peak_busy = max(self.peak_busy, sum(self._busy) / len(self._busy))
            if held > self.limit and self._confirmed(pids):
                self._stop_tree(pids, "memory")
                return
            if self.peak_busy > self.max_busy:
                self._stop_tree(pids, "cpus")
                return

    def _confirmed(self, pids: list[int]) -> bool:
        """Whether the tree still holds more than the limit counting each shared page once (:func:`proportional_bytes`):
        the children a process forks share its pages until they write them, and ``RssAnon`` counts them in each."""
        held = 0
        for pid in pids:  # a process whose share cannot be read (hidden, or an older kernel) counts as resident
            share = proportional_bytes(pid)
            held += private_bytes(pid) if share is None else share
        return held + memory_file_bytes(pids) > self.limit

    def _stop_tree(self, pids: list[int], why: str) -> None:
        self.exceeded = why
        for pid in pids:  # a process that left the process group is still in the tree
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        self.kill()

    def stop(self) -> None:
        self._stop.set()
