"""The grader's own work for a test is bounded in time and memory, and a reference stand-in answers only a
test's worth of calls (issue 35)."""
from __future__ import annotations

import resource
import time

import numpy as np
import pytest

from autograder.core.trusted_work import TrustedWorkTimeout, address_space, bounded
from autograder.sandbox.config import Limits
from conftest import FIXTURE_COURSE, with_cells


def test_a_long_computation_is_interrupted_at_the_bound():
    start = time.monotonic()
    with pytest.raises(TrustedWorkTimeout):
        with bounded(0.5, 0):
            while True:
                sum(range(1000))
    assert time.monotonic() - start < 2.0
    time.sleep(0.7)  # the timer is off once the block is left: nothing fires now


def test_memory_beyond_the_budget_fails_and_the_limit_is_restored():
    before = resource.getrlimit(resource.RLIMIT_AS)
    with pytest.raises(MemoryError):
        with bounded(0, 256 * 2**20):
            np.ones(2 * 2**30 // 8)  # 2 GB
    assert resource.getrlimit(resource.RLIMIT_AS) == before
    with bounded(0, 256 * 2**20):
        small = np.ones(2**20)  # well within the budget
    assert small.sum() == 2**20 and address_space() > 0


@pytest.mark.slow
def test_a_stand_in_answers_a_tests_worth_of_calls_only(tmp_path, monkeypatch):
    from autograder.core import course
    from autograder.core.grader import Grader

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    grader = Grader("fx", limits=Limits(call_seconds=120, test_seconds=120, exec_seconds=10, submission_seconds=300,
                                        reference_calls=500))
    try:
        calls = ("def double_scaled(x):\n    for _ in range(20_000):\n        scaled_sum(x)\n"
                 "    return 2 * scaled_sum(x)\n")
        nb = with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", tmp_path / "asks.ipynb", {"double_scaled": calls})
        start = time.monotonic()
        result = grader.grade(nb)
        seconds = time.monotonic() - start
    finally:
        grader.close()
    stub = next(s for s in result.stubs if s.name == "double_scaled")
    assert stub.score == 0 and "the grader answers no more" in stub.tests[0].message, stub.tests[0].message
    assert seconds < 30


@pytest.mark.slow
def test_hidden_inputs_follow_the_submission_so_a_learnt_answer_is_worth_nothing_next_time(tmp_path, monkeypatch):
    """The ``rng`` fixture is seeded by the test and by the submission's code: the same code meets the same
    inputs (a regrade is stable), changed code meets new ones (answers read out of one submission's feedback
    do not fit the next)."""
    from autograder.core import course
    from autograder.core.grader import Grader

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    leak = "def scaled_sum(x):\n    raise ValueError(repr(np.asarray(x).round(6).tolist()))\n"
    first = with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", tmp_path / "a.ipynb", {"scaled_sum": leak})
    second = with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", tmp_path / "b.ipynb",
                        {"scaled_sum": leak + "# now with the answers pasted in\n"})
    grader = Grader("fx")
    try:
        def seen(nb):
            stub = next(s for s in grader.grade(nb).stubs if s.name == "scaled_sum")
            return stub.tests[0].message
        once, again, changed = seen(first), seen(first), seen(second)
    finally:
        grader.close()
    assert "ValueError" in once and once == again
    assert changed != once
