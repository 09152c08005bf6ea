"""The sandbox's memory and CPUs are capped for its whole process tree, not per process (issue 35; the CPUs, the
shared memory and System V IPC after a red-team batch in which one submission's busy loops cost a classmate
points)."""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time

import pytest

from autograder.core import tree_guard
from autograder.sandbox.config import Limits
from conftest import FIXTURE_COURSE, with_cells

FORK_AND_HOLD = '''
import os, time
def scaled_sum(x):
    for _ in range(6):
        ready, done = os.pipe()
        if os.fork() == 0:
            held = bytearray(300 * 2**20)   # touched: zero-filled
            os.write(done, b"1")
            time.sleep(60)
            os._exit(0)
        os.read(ready, 1)   # one child fills its memory at a time: six at once trip the CPU rule first on a busy machine
    time.sleep(20)
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


@contextlib.contextmanager
def _ready_process(code: str):
    """A Python process running ``code`` in a session of its own, once it has printed ``ready``; killed with
    everything it started afterwards."""
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == b"ready"
        yield proc
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def test_tree_bytes_counts_every_descendant():
    code = ("import os, time\nheld = bytearray(64 * 2**20)\n"
            "for _ in range(2):\n    if os.fork() == 0:\n        more = bytearray(64 * 2**20)\n        time.sleep(30)\n"
            "print('ready', flush=True)\ntime.sleep(30)\n")
    with _ready_process(code) as proc:
        time.sleep(0.3)
        assert len(tree_guard.tree(proc.pid)) == 3
        held = tree_guard.tree_bytes(proc.pid)
        assert 3 * 64 * 2**20 <= held < 3 * 64 * 2**20 + 200 * 2**20, held
        assert tree_guard.private_bytes(proc.pid) < held - 100 * 2**20, "the children are counted too"


def _grade_fx(tmp_path, monkeypatch, code: str, **limits):
    """Grade the fixture course's solution with ``scaled_sum`` replaced by ``code``: (stubs by name, seconds, the
    worker's isolation level)."""
    from autograder.core import course
    from autograder.core.grader import Grader

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    grader = Grader("fx", limits=Limits(**{"call_seconds": 30, "test_seconds": 60, "exec_seconds": 10,
                                           "submission_seconds": 120, **limits}))
    try:
        nb = with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", tmp_path / "probe.ipynb", {"scaled_sum": code})
        start = time.monotonic()
        result = grader.grade(nb)
        seconds = time.monotonic() - start
    finally:
        grader.close()
    assert result.status == "graded", result.notes
    return {s.name: s for s in result.stubs}, seconds, result.isolation


def _assert_stopped_for(stubs, words: str) -> None:
    assert stubs["scaled_sum"].score == 0
    assert any(words in t.message for t in stubs["scaled_sum"].tests), [t.message for t in stubs["scaled_sum"].tests]
    assert stubs["mean_of"].score == stubs["mean_of"].max_score, "the next stub is graded in a fresh worker"


@pytest.mark.slow
def test_forked_children_together_cannot_pass_the_limit(tmp_path, monkeypatch):
    stubs, seconds, _ = _grade_fx(tmp_path, monkeypatch, FORK_AND_HOLD, memory_bytes=int(1.5 * 2**30))
    _assert_stopped_for(stubs, "GB of memory, counting every process")
    assert seconds < 60, "the tree is stopped when it passes the limit, not when its call times out"


SHARED_AND_MEMORY_FILES = '''
import mmap, os, time
def scaled_sum(x):
    if os.fork() == 0:  # shared anonymous memory: resident, but "shared" to a count of resident - shared pages
        m = mmap.mmap(-1, 600 * 2**20)
        for _ in range(600):
            m.write(b"x" * 2**20)
        time.sleep(60)
        os._exit(0)
    files = []
    for i in range(60):  # memory files held open, mapped by no one: in no process's resident memory at all
        fd = os.memfd_create(f"held{i}")
        os.write(fd, b"x" * (15 * 2**20))
        files.append(fd)
    time.sleep(20)
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


@pytest.mark.slow
def test_shared_memory_and_memory_files_count_against_the_limit(tmp_path, monkeypatch):
    """600 MB of shared anonymous memory in a child and 900 MB in memory files held open, against a 1.2 GB cap:
    before, the guard saw neither (the red team held 7.4 GB under a 4 GB cap)."""
    stubs, seconds, _ = _grade_fx(tmp_path, monkeypatch, SHARED_AND_MEMORY_FILES, memory_bytes=int(1.2 * 2**30))
    _assert_stopped_for(stubs, "GB of memory, counting every process")
    assert seconds < 40


def test_memory_files_and_shared_mappings_are_counted():
    code = ("import mmap, os, time\nm = mmap.mmap(-1, 96 * 2**20)\nm.write(b'\\1' * len(m))\n"
            "fd = os.memfd_create('held')\nos.write(fd, b'\\1' * (80 * 2**20))\n"
            "print('ready', flush=True)\ntime.sleep(30)\n")
    with _ready_process(code) as proc:
        assert tree_guard.private_bytes(proc.pid) >= 96 * 2**20, "the shared mapping"
        assert tree_guard.memory_file_bytes([proc.pid]) >= 80 * 2**20, "the memory file nothing maps"
        assert tree_guard.tree_bytes(proc.pid) >= 176 * 2**20


def test_pages_a_fork_shares_with_its_parent_are_counted_once_before_stopping_a_tree():
    """Red team C: 60 forked children that only slept were stopped, since each one's RssAnon counts the pages it
    shares with its parent. A tree over the limit by that count is stopped only if it still is when each shared
    page counts once (Pss): here 9 processes sharing 160 MB against a 600 MB cap go on; writing the pages in
    each child (private copies, 1.4 GB) is stopped."""
    def guard_on(children_write: bool) -> str | None:
        code = ("import os, time\nheld = bytearray(160 * 2**20)\nheld[::4096] = b'\\1' * len(held[::4096])\n"
                "for _ in range(8):\n    if os.fork() == 0:\n"
                + ("        held[::4096] = b'\\2' * len(held[::4096])\n" if children_write else "")
                + "        time.sleep(30)\nprint('ready', flush=True)\ntime.sleep(30)\n")
        with _ready_process(code) as proc:
            time.sleep(0.5)
            assert tree_guard.tree_bytes(proc.pid) > 600 * 2**20, "the resident count puts the tree over the cap"
            guard = tree_guard.TreeGuard(proc.pid, 600 * 2**20, kill=lambda: None, max_busy=64)
            time.sleep(1.0)
            guard.stop()
            return guard.exceeded

    assert guard_on(children_write=False) is None
    assert guard_on(children_write=True) == "memory"


def test_a_process_that_hides_its_share_counts_as_resident(monkeypatch):
    """A process may hide its smaps_rollup from a grader of its own user (it makes itself undumpable): its resident
    count stands for it, so hiding never lets a tree keep more than the cap."""
    code = "import time\nheld = bytearray(200 * 2**20)\nprint('ready', flush=True)\ntime.sleep(30)\n"
    with _ready_process(code) as proc:
        guard = tree_guard.TreeGuard(proc.pid, 100 * 2**20, kill=lambda: None, max_busy=64, interval=3600)
        try:
            assert guard._confirmed([proc.pid])
            real_open = open

            def refuse_rollup(path, *args, **kwargs):  # what a grader of the worker's own user meets (EACCES)
                if str(path).endswith("/smaps_rollup"):
                    raise PermissionError(13, "Permission denied", str(path))
                return real_open(path, *args, **kwargs)

            monkeypatch.setattr(tree_guard, "open", refuse_rollup, raising=False)
            assert tree_guard.proportional_bytes(proc.pid) is None
            assert guard._confirmed([proc.pid]), "hidden: counted by its resident pages, still over the cap"
        finally:
            guard.stop()


def test_busy_tasks_counts_processes_and_threads_that_want_a_cpu():
    code = ("import os, threading, time\n"
            "for _ in range(2):\n    if os.fork() == 0:\n        while True: pass\n"
            "threading.Thread(target=time.sleep, args=(30,), daemon=True).start()\n"
            "print('ready', flush=True)\ntime.sleep(30)\n")
    with _ready_process(code) as proc:
        time.sleep(0.2)
        pids = tree_guard.tree(proc.pid)
        looks = [tree_guard.busy_tasks(pids) for _ in range(20)]
        assert max(looks) == 2 and min(looks) >= 1, looks  # two loops; the sleeping parent and thread are not busy


BUSY_LOOPS = '''
import subprocess, time
def scaled_sum(x):
    for _ in range(4):  # each in a session of its own, as the red team's were
        subprocess.Popen(["/bin/sh", "-c", "while :; do :; done"], start_new_session=True)
    time.sleep(20)
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


@pytest.mark.slow
def test_a_tree_that_keeps_several_cpus_busy_is_stopped(tmp_path, monkeypatch):
    """Four busy loops started by a stub that then waits: the tree is stopped within seconds, well before the
    test's time limit, and the next stub is graded in a fresh worker."""
    stubs, seconds, _ = _grade_fx(tmp_path, monkeypatch, BUSY_LOOPS)
    _assert_stopped_for(stubs, "several processes or threads computing at once")
    assert seconds < 30


SYSTEM_V_SEGMENT = '''
import ctypes
def scaled_sum(x):
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.shmget(0, ctypes.c_size_t(2**20), 0o1600) < 0:
        raise OSError(ctypes.get_errno(), "no segment")
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


@pytest.mark.slow
def test_no_system_v_shared_memory_in_a_namespace(tmp_path, monkeypatch):
    """A System V segment keeps its memory when every process has unmapped it, out of the guard's sight: in its
    own IPC namespace the worker may create none (where there are no namespaces, there is nothing to close)."""
    stubs, _, isolation = _grade_fx(tmp_path, monkeypatch, SYSTEM_V_SEGMENT)
    if isolation == "none":
        pytest.skip("no namespaces here (isolation 'none'): the worker shares the machine's IPC")
    messages = [t.message for t in stubs["scaled_sum"].tests]
    assert stubs["scaled_sum"].score == 0 and any("no segment" in m for m in messages), messages


FLOOD = '''
import sys
def scaled_sum(x):
    line = "x" * 65535 + "\\n"
    for _ in range(2000):                  # 128 MB of output, then the right answer
        sys.stdout.write(line)
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


def test_a_worker_that_floods_its_output_stops_being_read_and_times_out(tmp_path, monkeypatch):
    """Red team C: reading a worker's output costs the grader's process about the CPU writing costs the worker, out
    of the worker's limits (3.2 s of the grader's CPU in 6.1 s). Past 64 MB the grader stops reading: the worker's
    next write blocks, its time runs out, and the message says why."""
    from autograder.core import supervisor

    monkeypatch.setattr(supervisor, "OUTPUT_READ_BYTES", 8 * 2**20)  # the same rule, reached sooner
    stubs, _, _ = _grade_fx(tmp_path, monkeypatch, FLOOD, call_seconds=3, test_seconds=4)
    _assert_stopped_for(stubs, "which the grader stopped reading")
