"""Issue 27, part 6: hidden tests that cannot be passed trivially, rebuilt from the release, or replayed.

Each assignment is graded once with every stub replaced by a trivial answer (the input handed back, a
uniform policy, the initial distribution times the horizon, a constant probability, a constant loss with
zero metrics, zeros, a made-up history) or a shortcut through the release (hw2's ``maxent_irl`` regenerates
the test's MDP by searching ``random_mdp`` seeds and returns its true weights): every stub must score 0,
so every hidden test pairs its invariance with a value that such an answer gets wrong.
"""
from __future__ import annotations

import runpy
import zlib

import nbformat
import numpy as np
import pytest

from autograder.core import course
from autograder.core.grader import Grader
from autograder.authoring.samples import _with_stubs
from conftest import graded_stubs

pytestmark = pytest.mark.slow  # one grading per assignment: make test-fast leaves it out


def trivial_answers(assignment: str) -> dict[str, str]:
    """``autograder/suites/<id>/trivial_answers.py``'s ``ANSWERS`` (empty when the file is missing)."""
    path = course.suite_dir(assignment) / "trivial_answers.py"
    return runpy.run_path(str(path))["ANSWERS"] if path.is_file() else {}


def gradable_assignments() -> list[str]:
    return [a for a in course.assignment_ids() if course.suite_dir(a).is_dir()]


@pytest.mark.parametrize("assignment", gradable_assignments())
def test_every_stub_has_a_trivial_answer(assignment):
    """Every assignment, a new one included, ships a trivial answer for each of its stubs."""
    assert set(trivial_answers(assignment)) == set(course.stub_names(assignment)), \
        f"autograder/suites/{assignment}/trivial_answers.py must answer every stub (python -m autograder new makes one)"


@pytest.fixture(scope="module", params=gradable_assignments())
def assignment(request) -> str:
    """Each gradable assignment; module-scoped, so that pytest runs all of one assignment's tests together and
    :func:`graded_stubs` keeps its grader for both of them."""
    return request.param


def _earned(assignment: str, stubs: dict[str, str], path) -> dict[str, list[str]]:
    """Grade the solution notebook with ``stubs`` in place of its stub cells: the tests passed, by stub that scored."""
    return {name: [t.name for t in s.tests if t.passed]
            for name, s in graded_stubs(assignment, stubs, path).items() if s.score > 0}


def test_trivial_answers_and_seed_search_earn_nothing(assignment, open_tmp):
    earned = _earned(assignment, trivial_answers(assignment), open_tmp / f"trivial_{assignment}.ipynb")
    assert not earned, f"trivial answers earned points on {assignment}: {earned}"


def test_stubs_that_always_raise_earn_nothing(assignment, open_tmp):
    """A stub that raises the error its contract asks for on bad input, whatever it is given, is a constant answer
    too: every test that checks a refusal also makes a call that must not raise. (The untouched stub's
    NotImplementedError is the samples' ``untouched``.)"""
    error = "ValueError"
    stubs = {name: (f"class {name}:\n    def __init__(self, *args, **kwargs):\n        raise {error}('no')\n"
                    if name[:1].isupper() else f"def {name}(*args, **kwargs):\n    raise {error}('no')\n")
             for name in course.stub_names(assignment)}
    earned = _earned(assignment, stubs, open_tmp / f"raises_{assignment}.ipynb")
    assert not earned, f"stubs that always raise {error} earned points on {assignment}: {earned}"


def _discounted(rewards, gamma):
    out, running = np.zeros_like(rewards), np.zeros(rewards.shape[0])
    for t in reversed(range(rewards.shape[1])):
        running = rewards[:, t] + gamma * running
        out[:, t] = running
    return out


def test_feedback_over_two_submissions_holds_no_hidden_expected_value(open_tmp):
    """Hidden inputs are the same at every submission (the rng is seeded by the test's name): a student who hands in
    zeros, then ones, and reads both feedbacks must find no expected entry of the hidden instances there."""
    wrong = {"zeros": "def discounted_returns(rewards, gamma):\n    return np.zeros(np.shape(rewards))\n",
             "ones": "def discounted_returns(rewards, gamma):\n    return np.ones(np.shape(rewards))\n"}
    messages = []
    grader = Grader("hw0_setup")
    try:
        for name, source in wrong.items():
            path = open_tmp / f"{name}.ipynb"
            nbformat.write(_with_stubs("hw0_setup", {"discounted_returns": source}), str(path))
            result = grader.grade(path)
            messages += [t.message for s in result.stubs if s.name == "discounted_returns" for t in s.tests]
    finally:
        grader.close()
    text = "\n".join(messages)
    assert "wrong" in text or "too" in text, "the feedback should still say what is wrong"
    hidden = []  # the suite's own instances, rebuilt here as the grader's rng fixture draws them
    rng = np.random.default_rng(zlib.crc32(b"test_random_batch_matches_reference"))
    hidden.append(_discounted(rng.normal(size=(5, 13)), 0.9))
    rng = np.random.default_rng(zlib.crc32(b"test_edge_discounts"))
    rewards = rng.normal(size=(2, 7))
    hidden += [_discounted(rewards, 0.0), _discounted(rewards, 1.0)]
    renderings = {r for want in hidden for v in want.ravel() if abs(v) > 1e-3
                  for r in [repr(float(v))] + [f"{v:.{d}g}" for d in range(3, 9)] if len(r.strip("-0.")) >= 3}
    leaked = sorted(r for r in renderings if r in text)
    assert not leaked, f"the feedback holds hidden expected values: {leaked[:5]}"
    assert "np." not in text, "plain numbers only (not np.float64(...))"
