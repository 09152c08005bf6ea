"""PrairieLearn's external-grader route: results.json in its documented format, and a grader fault never a 0."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.outputs import prairielearn
from autograder.core.results import GRADER_ERROR, GradeResult, GraderError, StubResult
from autograder.core.results import TestOutcome as Outcome
from conftest import REPO

SAMPLES = REPO / "autograder/samples/hw0_setup"


def check_format(results: dict) -> None:
    """PrairieLearn's "Grading results": score in [0, 1] when gradable; tests with points <= max_points; < 1 MB."""
    assert len(json.dumps(results).encode()) <= prairielearn.RESULTS_BYTES
    assert isinstance(results.get("gradable", True), bool)
    if results.get("gradable", True):
        assert 0.0 <= results["score"] <= 1.0
        for test in results.get("tests", []):
            assert {"name", "points", "max_points"} <= set(test)
            assert 0 <= test["points"] <= test["max_points"]
            assert all(isinstance(test.get(k, ""), str) for k in ("name", "description", "message", "output"))
    else:
        assert "score" not in results, "an ungraded submission carries no score at all"
        assert results["format_errors"] and results["message"]


def _result(status: str = "graded", error: str | None = None) -> GradeResult:
    tests = [Outcome("shape", "f", 2.0, True), Outcome("values", "f", 3.0, False, "off by one\x1b[31m", "the sum")]
    return GradeResult("hw0_setup", "s", [StubResult("f", tests)], [("written", 4.0)], ["note"], error, status=status)


def test_a_graded_result_is_a_fraction_with_one_test_per_hidden_test():
    results = prairielearn.prairielearn_results(_result())
    check_format(results)
    assert results["gradable"] is True and results["score"] == pytest.approx(2 / 5)
    assert [(t["points"], t["max_points"]) for t in results["tests"]] == [(2.0, 2.0), (0.0, 3.0)]
    assert "\x1b" not in results["tests"][1]["message"] and "off by one" in results["tests"][1]["message"]
    assert results["tests"][1]["output"] == "hint: the sum"
    assert "graded by hand" in results["message"]


def test_a_grader_fault_is_not_gradable_and_never_a_zero():
    results = prairielearn.prairielearn_results(_result(GRADER_ERROR, "the sandbox could not start"))
    check_format(results)
    assert results["gradable"] is False and "not your fault" in results["message"]
    ungradable = prairielearn.prairielearn_results(_result("ungradable", "not a notebook"))
    check_format(ungradable)
    assert ungradable["gradable"] is False and "not a notebook" in ungradable["format_errors"][0]


def test_huge_messages_are_cut_to_the_size_limit():
    result = _result()
    result.stubs[0].tests = [Outcome(f"t{i}", "f", 1.0, False, "x" * 5000, "y" * 5000) for i in range(600)]
    text = prairielearn._fit(prairielearn.prairielearn_results(result))
    assert len(text.encode()) <= prairielearn.RESULTS_BYTES
    check_format(json.loads(text))


def _grade(root: Path) -> tuple[int, dict]:
    done = subprocess.run([sys.executable, "-m", "autograder", "prairielearn", "hw0_setup", "--root", str(root)],
                          capture_output=True, text=True, timeout=600)
    return done.returncode, json.loads((root / "results" / "results.json").read_text())


@pytest.mark.slow
def test_grades_a_student_folder_laid_out_as_prairielearn_lays_it_out(tmp_path):
    files = prairielearn.question_files("hw0_setup", tmp_path / "course")
    info = json.loads((tmp_path / "course/questions/hw0_setup/info.json").read_text())
    assert info["externalGradingOptions"]["entrypoint"] == "/grade/serverFilesCourse/rlcourse/run_hw0_setup.sh"
    assert os.access(files[0], os.X_OK) and "prairielearn hw0_setup --root /grade" in files[0].read_text()

    root = tmp_path / "grade"
    (root / "student").mkdir(parents=True)
    shutil.copy(SAMPLES / "partial.ipynb", root / "student" / "hw0_setup.ipynb")
    code, results = _grade(root)
    assert code == 0
    check_format(results)
    assert results["score"] == pytest.approx(5 / 8)
    assert sum(t["points"] for t in results["tests"]) == 5 and sum(t["max_points"] for t in results["tests"]) == 8

    # A link to the solution is never followed: not gradable, with the reason.
    (root / "student" / "hw0_setup.ipynb").unlink()
    (root / "student" / "hw0_setup.ipynb").symlink_to(REPO / "solutions/hw0_setup/hw0_setup.ipynb")
    code, results = _grade(root)
    check_format(results)
    assert results["gradable"] is False and "link" in results["format_errors"][0]


def test_when_the_grader_cannot_start_the_results_say_so(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise GraderError("the reference solution could not be built")

    monkeypatch.setattr("autograder.core.batch.Grader", broken)
    (tmp_path / "student").mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", tmp_path / "student" / "hw0_setup.ipynb")
    assert prairielearn.run("hw0_setup", tmp_path) == 1
    results = json.loads((tmp_path / "results" / "results.json").read_text())
    check_format(results)
    assert results["gradable"] is False and "not your fault" in results["message"]
