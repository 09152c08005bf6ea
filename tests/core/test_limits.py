"""Per-test time limits from the reference's own time (issue 37): written by ``autograder.authoring.limits``,
read from ``limits.json``'s ``"tests"``, and binding every call of their test, a suite's own ``timeout`` too."""
from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pytest

from autograder.authoring import limits as authoring_limits
from autograder.core import course
from autograder.core.grader import Grader
from autograder.core.results import Reason
from conftest import FIXTURE_COURSE, with_cells

pytestmark = pytest.mark.slow  # each builds a grader (a zygote and the reference)

OWN_LIMIT = 1.5
EXPLICIT_TIMEOUT = 30
LOOP_TEST = "test_a_loop.py::test_mean_of_with_a_timeout_of_its_own"


@pytest.fixture
def course_copy(open_tmp: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A writable copy of the fixture course, which the course tools then read."""
    copy = open_tmp / "course"
    shutil.copytree(FIXTURE_COURSE, copy)
    for path in [copy, *copy.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    monkeypatch.setattr(course, "REPO", copy)
    return copy


def test_the_rule_is_a_multiple_of_the_reference_plus_a_constant_within_test_seconds():
    assert authoring_limits.limit_for(0.0, 180) == authoring_limits.CONSTANT
    assert authoring_limits.limit_for(0.5, 180) == pytest.approx(authoring_limits.MULTIPLE * 0.5 + authoring_limits.CONSTANT)
    assert authoring_limits.limit_for(1000.0, 180) == 180
    assert authoring_limits.own_seconds({"span": 3.0, "credit": 1.0, "grader_wait": 0.5}) == pytest.approx(1.5)
    assert authoring_limits.own_seconds({"span": 1.0, "credit": 2.0}) == 0.0


def test_per_test_keys_are_not_limits_fields(course_copy):
    path = course_copy / "autograder/suites/fx/limits.json"
    raw = json.loads(path.read_text())
    path.write_text(json.dumps({**raw, "tests": {"test_fx.py::test_mean_of": 2.5}, "tests_reference": {"rule": "x"}}))
    assert course.limits("fx").call_seconds == raw["call_seconds"]
    assert course.per_test_limits("fx") == {"test_fx.py::test_mean_of": 2.5}
    (course_copy / "autograder/suites/ex/limits.json").unlink()  # a suite without limits.json: no per-test limit
    assert course.per_test_limits("ex") == {}


def test_a_tests_own_limit_stops_a_loop_even_through_the_suites_own_timeout(course_copy, tmp_path):
    suite = course_copy / "autograder/suites/fx"
    (suite / "test_a_loop.py").write_text(
        "from autograder.suite import stub\n\n\n"
        "@stub('mean_of', points=1)\n"
        "def test_mean_of_with_a_timeout_of_its_own(student):\n"
        f"    assert student.mean_of([1.0, 3.0], timeout={EXPLICIT_TIMEOUT}) == 2.0\n")
    limits = suite / "limits.json"
    limits.write_text(json.dumps({**json.loads(limits.read_text()), "tests": {LOOP_TEST: OWN_LIMIT}}))
    looping = with_cells(course_copy / "solutions/fx/fx.ipynb", tmp_path / "loop.ipynb",
                         {"mean_of": "def mean_of(values):\n    while True:\n        pass\n"})
    grader = Grader("fx")
    try:
        assert grader.test_limits == {LOOP_TEST: OWN_LIMIT}
        started = time.monotonic()
        result = grader.grade(looping)
        spent = time.monotonic() - started
        stats = grader.last_test_stats
    finally:
        grader.close()
    (test,) = [t for s in result.stubs if s.name == "mean_of" for t in s.tests if "timeout of its own" in t.name]
    assert not test.passed and test.reason == Reason.TIMEOUT, test.message
    assert f"time limit of {OWN_LIMIT:.1f} s" in test.message, test.message
    # the CPU-wait credit may stretch the limit (a loaded machine), never to the suite's own 30 s
    assert test.seconds < EXPLICIT_TIMEOUT / 2, f"the loop ran {test.seconds:.1f} s: the test's own limit did not bind"
    assert stats[LOOP_TEST]["limit"] == OWN_LIMIT
    others = {k: v for k, v in stats.items() if k != LOOP_TEST and "span" in v}
    assert others and all(v["limit"] == course.limits("fx").test_seconds for v in others.values())
    assert all(v["messages"] >= 2 and v["worker_cpu"] >= 0 for v in others.values())
    assert spent < 120


def test_written_limits_cover_every_test_and_the_grader_reads_them(course_copy):
    raw = authoring_limits.write_limits("ex")
    tests = course.per_test_limits("ex")
    assert tests == raw["tests"] and tests, "no limits were written"
    test_seconds = course.limits("ex").test_seconds
    assert all(authoring_limits.CONSTANT <= v <= test_seconds for v in tests.values())
    reference = raw["tests_reference"]["seconds"]
    assert set(reference) == set(tests)
    for node, seconds in tests.items():
        assert seconds == authoring_limits.limit_for(reference[node]["own"], test_seconds) or \
            abs(seconds - authoring_limits.limit_for(reference[node]["own"], test_seconds)) < 0.11
    grader = Grader("ex")
    try:
        assert grader.test_limits == tests
        result = grader.grade(course_copy / "autograder/samples/ex/complete.ipynb")
    finally:
        grader.close()
    assert result.score == result.max_score, [t.message for s in result.stubs for t in s.tests if not t.passed]


def test_a_re_measure_keeps_an_earlier_limit_lower_by_noise_only():
    """A limit re-measured a little higher keeps the earlier one; a test that became heavier gets its new limit."""
    earlier = {"tests": {"a": 5.2, "b": 6.0, "c": 9.0},
               "tests_reference": {"seconds": {"a": {"own": 0.012}, "b": {"own": 0.1}, "c": {"own": 0.4}}}}
    tests = {"a": 5.4, "b": 9.0, "c": 8.0, "d": 5.1}
    reference = {k: {"own": 0.0} for k in tests}
    kept = authoring_limits.keep_earlier(earlier, tests, reference)
    assert kept == ["a"]
    assert tests == {"a": 5.2, "b": 9.0, "c": 8.0, "d": 5.1}, "only a noise-sized rise is undone; a fall always lands"
    assert reference["a"] == {"own": 0.012} and reference["b"] == {"own": 0.0}
    assert authoring_limits.keep_earlier({}, dict(tests), dict(reference)) == []
