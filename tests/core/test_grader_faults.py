"""A fault of the grader is never a grade: grade, batch, demo and Gradescope refuse to score.

The grader is broken on purpose in a copy of the fixture course: a sandbox that cannot start (a
private /tmp of an impossible size), a solution notebook that fails, a released setup cell that
fails. Each command must say so, exit non-zero and write no score; a batch must retry.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from autograder.authoring.demo import differences
from autograder.core import results
from autograder.core.results import GRADED, GRADER_ERROR, GradeResult, StubResult
from conftest import FIXTURE_COURSE, REPO, with_cells

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

SOLUTION = FIXTURE_COURSE / "solutions/fx/fx.ipynb"
GRADER_FAULT_EXIT = 3


@pytest.fixture
def course_copy(open_tmp: Path) -> Path:
    """A writable copy of the fixture course, with the solution as a sample and its expected.json."""
    course = open_tmp / "course"
    shutil.copytree(FIXTURE_COURSE, course)
    samples = course / "autograder/samples/fx"
    samples.mkdir(parents=True)
    shutil.copy(SOLUTION, samples / "complete.ipynb")
    stubs = ["scaled_sum", "Counter", "mean_of", "double_scaled"]
    (samples / "expected.json").write_text(json.dumps({"complete": {s: "full" for s in stubs}}))
    for path in [course, *course.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    return course


def _break_sandbox(course: Path) -> None:
    limits = course / "autograder/suites/fx/limits.json"
    limits.write_text(json.dumps({**json.loads(limits.read_text()), "tmp_bytes": -1}))  # no tmpfs takes that size


def _cli(course: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, RLCOURSE_REPO=str(course))
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True, text=True, env=env,
                          timeout=300, cwd=REPO)


def test_grade_with_a_broken_sandbox_writes_no_score_and_fails(course_copy, open_tmp):
    _break_sandbox(course_copy)
    done = _cli(course_copy, "grade", "fx", str(SOLUTION), "--out", str(open_tmp / "out"))
    assert done.returncode == GRADER_FAULT_EXIT, (done.stdout, done.stderr[-2000:])
    assert "NOT GRADED" in done.stderr and "sandbox could not start" in done.stderr
    assert not (open_tmp / "out" / "results.json").exists() and not (open_tmp / "out" / "feedback.md").exists()


def test_grade_with_a_broken_reference_fails_before_grading(course_copy, open_tmp):
    nb = nbformat.read(str(course_copy / "solutions/fx/fx.ipynb"), as_version=4)
    cell = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "mean_of")
    cell.source += "\nraise RuntimeError('a bug in the solution notebook')\n"
    nbformat.write(nb, str(course_copy / "solutions/fx/fx.ipynb"))
    done = _cli(course_copy, "grade", "fx", str(SOLUTION), "--out", str(open_tmp / "out"))
    assert done.returncode == GRADER_FAULT_EXIT and "reference solution of fx could not be built" in done.stderr
    assert not (open_tmp / "out" / "results.json").exists()


def test_batch_records_grader_errors_without_scores_and_retries_them(course_copy, open_tmp):
    folder = open_tmp / "submissions"
    folder.mkdir()
    for name in ("alice", "bob"):
        shutil.copy(SOLUTION, folder / f"{name}.ipynb")
    out = open_tmp / "out"
    _break_sandbox(course_copy)
    done = _cli(course_copy, "batch", "fx", str(folder), "--out", str(out), "--jobs", "1")
    assert done.returncode == GRADER_FAULT_EXIT, done.stderr[-2000:]
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    assert [r["submission"] for r in rows] == ["alice", "bob"]
    for row in rows:
        assert row["status"] == GRADER_ERROR and row["score"] == "" and row["scaled_sum"] == "", row
        assert not (out / row["submission"] / "results.json").exists(), "a grader error must leave no Gradescope score"
    shutil.copy(FIXTURE_COURSE / "autograder/suites/fx/limits.json", course_copy / "autograder/suites/fx/limits.json")
    done = _cli(course_copy, "batch", "fx", str(folder), "--out", str(out), "--jobs", "1")
    assert done.returncode == 0, done.stderr[-2000:]
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    assert [(r["status"], r["score"]) for r in rows] == [(GRADED, "7"), (GRADED, "7")]


def test_demo_fails_on_a_broken_sandbox_and_passes_once_mended(course_copy, open_tmp):
    _break_sandbox(course_copy)
    done = _cli(course_copy, "demo", "--out", str(open_tmp / "demo"), "--jobs", "1")
    assert done.returncode != 0 and "DEMO FAILED" in done.stderr and "grader failed" in done.stderr
    shutil.copy(FIXTURE_COURSE / "autograder/suites/fx/limits.json", course_copy / "autograder/suites/fx/limits.json")
    done = _cli(course_copy, "demo", "--out", str(open_tmp / "demo2"), "--jobs", "1")
    assert done.returncode == 0, done.stderr[-2000:]


def test_gradescope_run_leaves_no_results_when_the_grader_fails(course_copy, open_tmp, monkeypatch):
    from autograder.core import course
    from autograder.outputs import gradescope

    _break_sandbox(course_copy)
    monkeypatch.setattr(course, "REPO", course_copy)
    root = open_tmp / "gs"
    (root / "submission").mkdir(parents=True)
    shutil.copy(SOLUTION, root / "submission" / "work.ipynb")
    (root / "results").mkdir()
    (root / "results" / "results.json").write_text('{"score": 0}')  # a stale file must not survive either
    assert gradescope.run("fx", root) != 0
    assert not (root / "results" / "results.json").exists()


def test_a_setup_cell_that_fails_alone_is_the_graders_fault(course_copy, open_tmp, monkeypatch):
    from autograder.core import course
    from autograder.core.grader import Grader

    release = course_copy / "assignments/fx/fx.ipynb"
    nb = nbformat.read(str(release), as_version=4)
    next(c for c in nb.cells if "setup" in c.metadata.get("tags", [])).source += "\nimport a_module_that_is_not_there\n"
    nbformat.write(nb, str(release))
    monkeypatch.setattr(course, "REPO", course_copy)
    grader = Grader("fx")
    try:
        result = grader.grade(SOLUTION)
    finally:
        grader.close()
    assert result.status == GRADER_ERROR and not result.stubs and "setup fails in the sandbox" in result.error


def test_a_setup_cell_broken_by_a_stub_cell_is_the_students_fault(open_tmp, monkeypatch):
    """A stub cell that deletes a name a later setup cell needs costs the student, not a grader error."""
    from autograder.core import course
    from autograder.core.grader import Grader

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    release = nbformat.read(str(FIXTURE_COURSE / "assignments/fx/fx.ipynb"), as_version=4)
    later_setup = nbformat.v4.new_code_cell("HALF = SCALE / 2", metadata={"tags": ["setup"]})
    copy = open_tmp / "release.ipynb"
    release.cells.insert(4, later_setup)
    nbformat.write(release, str(copy))
    grader = Grader("fx")
    grader.plan = __import__("autograder.core.notebook", fromlist=["release_plan"]).release_plan(release)
    try:
        sneaky = with_cells(SOLUTION, open_tmp / "sneaky.ipynb", {
            "scaled_sum": "del SCALE\ndef scaled_sum(x):\n    return x.sum(axis=-1)"})
        result = grader.grade(sneaky)
    finally:
        grader.close()
    assert result.status == GRADED and result.score == 0
    assert all("setup failed after your cells ran" in t.message for s in result.stubs for t in s.tests)


def _result(name: str, scores: dict[str, tuple[float, float]], status: str = GRADED) -> GradeResult:
    stubs = [StubResult(stub, [results.TestOutcome("t", stub, top, got == top)]) for stub, (got, top) in scores.items()]
    return GradeResult("fx", name, stubs, [], status=status)


def test_demo_differences_name_every_mismatch():
    expected = {"complete": {"a": "full", "b": "full"}, "partial": {"a": "full", "b": "zero"}}
    assert differences([_result("complete", {"a": (2, 2), "b": (1, 1)}),
                        _result("partial", {"a": (2, 2), "b": (0, 1)})], expected) == []
    problems = differences([_result("complete", {"a": (0, 2), "b": (1, 1)}),
                            _result("extra", {"a": (2, 2)}),
                            GradeResult("fx", "partial", [], [], error="boom", status=GRADER_ERROR)], expected)
    assert any("complete: `a` scored 0/2, expected full" in p for p in problems)
    assert any("partial: not graded, the grader failed: boom" in p for p in problems)
    assert any("extra: graded, but expected.json says nothing" in p for p in problems)
