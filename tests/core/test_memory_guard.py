"""The sandbox's memory is capped for its whole process tree, not per process (issue 35)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from autograder.core import memory
from autograder.sandbox.config import Limits
from conftest import FIXTURE_COURSE, with_cells

FORK_AND_HOLD = '''
import os, time
def scaled_sum(x):
    for _ in range(6):
        if os.fork() == 0:
            held = bytearray(300 * 2**20)   # touched: zero-filled
            time.sleep(60)
            os._exit(0)
    time.sleep(20)
    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)
'''


def test_tree_bytes_counts_every_descendant():
    code = ("import os, time\nheld = bytearray(64 * 2**20)\n"
            "for _ in range(2):\n    if os.fork() == 0:\n        more = bytearray(64 * 2**20)\n        time.sleep(30)\n"
            "print('ready', flush=True)\ntime.sleep(30)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == b"ready"
        time.sleep(0.3)
        assert len(memory.tree(proc.pid)) == 3
        held = memory.tree_bytes(proc.pid)
        assert 3 * 64 * 2**20 <= held < 3 * 64 * 2**20 + 200 * 2**20, held
        assert memory.private_bytes(proc.pid) < held - 100 * 2**20, "the children are counted too"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


@pytest.mark.slow
def test_forked_children_together_cannot_pass_the_limit(tmp_path, monkeypatch):
    from autograder.core import course
    from autograder.core.grader import Grader

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    grader = Grader("fx", limits=Limits(call_seconds=30, test_seconds=60, exec_seconds=10, submission_seconds=120,
                                        memory_bytes=int(1.5 * 2**30)))
    try:
        nb = with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", tmp_path / "forks.ipynb", {"scaled_sum": FORK_AND_HOLD})
        start = time.monotonic()
        result = grader.grade(nb)
        seconds = time.monotonic() - start
    finally:
        grader.close()
    stubs = {s.name: s for s in result.stubs}
    assert stubs["scaled_sum"].score == 0
    assert any("GB of memory, counting every process" in t.message for t in stubs["scaled_sum"].tests), \
        [t.message for t in stubs["scaled_sum"].tests]
    assert stubs["mean_of"].score == stubs["mean_of"].max_score, "the next stub is graded in a fresh worker"
    assert seconds < 60, "the tree is stopped when it passes the limit, not when its call times out"
