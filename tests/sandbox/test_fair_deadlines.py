"""Time limits do not count a worker's wait for a busy CPU: a loaded machine is not the student's fault.

Busy processes pinned to one CPU share it with a worker that pins itself there too, so the worker runs about
a quarter of the time. A call that needs 1.5 s of CPU then takes about 6 s of wall time, over a 4 s
limit, and must still pass; a call that sleeps, or loops for ever, must still time out, the loop by
``CPU_WAIT_STRETCH`` times the limit at the latest.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from autograder.core.grader import Grader
from autograder.sandbox.config import Limits
from autograder.core.session import CPU_WAIT_STRETCH
from conftest import REPO, with_cells

pytestmark = [pytest.mark.slow,  # three gradings on a deliberately starved CPU
              pytest.mark.serial,  # its hogs would starve whatever ran beside it: make test runs it alone
              pytest.mark.skipif(not os.path.exists("/proc/self/schedstat"),
                                 reason="this kernel does not report run delays: limits are plain wall-clock time")]

CALL_SECONDS = 4.0
BURN_SECONDS = 1.5
HOGS = 3
CPU = min(os.sched_getaffinity(0))  # the first CPU this machine lets us use (a container's cpuset may skip 0)
PIN = f"import os\nos.sched_setaffinity(0, {{{CPU}}})\n"
SUBMISSION = REPO / "tests/fixtures/course/assignments/fx/fx.ipynb"


@pytest.fixture(scope="module")
def grader():
    from autograder.core import course

    saved = course.REPO
    course.REPO = REPO / "tests" / "fixtures" / "course"
    try:
        grader = Grader("fx", Limits(call_seconds=CALL_SECONDS, test_seconds=60, submission_seconds=120))
    finally:
        course.REPO = saved
    yield grader
    grader.close()


@pytest.fixture
def busy_cpu():
    # each in a session of its own: with autogroup scheduling, a session shares the CPU as one task
    hogs = [subprocess.Popen([sys.executable, "-c", PIN + "while True:\n    pass\n"], start_new_session=True)
            for _ in range(HOGS)]
    time.sleep(0.5)
    yield
    for hog in hogs:
        hog.kill()
        hog.wait()


def _mean_of(tmp_path, body: str):
    source = ("def mean_of(values):\n    import os, time\n" f"    os.sched_setaffinity(0, {{{CPU}}})\n"
              + "".join(f"    {line}\n" for line in body.splitlines()) + "    return float(np.mean(values))\n")
    return with_cells(SUBMISSION, tmp_path / "s.ipynb", {"mean_of": source})


def _graded(grader, notebook):
    result = grader.grade(notebook)
    (test,) = [t for s in result.stubs if s.name == "mean_of" for t in s.tests]
    return test


def test_a_call_slowed_by_a_busy_cpu_still_passes(grader, tmp_path, busy_cpu):
    test = _graded(grader, _mean_of(tmp_path, f"start = time.thread_time()\n"
                                              f"while time.thread_time() - start < {BURN_SECONDS}:\n    pass"))
    assert test.passed, f"a call needing {BURN_SECONDS} s of CPU failed on a busy machine: {test.message}"
    assert test.seconds > CALL_SECONDS, f"the call took {test.seconds:.1f} s: the CPU was not busy, this proves nothing"


def test_a_sleeping_call_still_times_out_at_its_limit(grader, tmp_path, busy_cpu):
    test = _graded(grader, _mean_of(tmp_path, f"time.sleep({10 * CALL_SECONDS})"))
    assert not test.passed and "timed out" in test.message, test.message
    assert test.seconds < 1.5 * CALL_SECONDS, f"the test took {test.seconds:.1f} s: the sleep was forgiven"


def test_a_loop_on_a_busy_cpu_times_out_within_the_stretch(grader, tmp_path, busy_cpu):
    test = _graded(grader, _mean_of(tmp_path, "while True:\n    pass"))
    assert not test.passed and "timed out" in test.message, test.message
    assert CALL_SECONDS < test.seconds < CPU_WAIT_STRETCH * CALL_SECONDS + 2, f"the test took {test.seconds:.1f} s"
