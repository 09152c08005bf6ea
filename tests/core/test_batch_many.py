"""A batch over several assignments (issue 37): one pool, so each grading process imports the grader once and
grades every assignment; each assignment's results and gradebook in a folder of its own."""
from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.core import course
from autograder.core.batch import Batch, assignment_folder, assignments_in, run_batches
from conftest import FIXTURE_COURSE, REPO

pytestmark = pytest.mark.slow  # end-to-end: a pool of grading processes

SOLUTIONS = FIXTURE_COURSE / "solutions"


def record_pid(result, folder: Path) -> None:
    """A writer (run in the grading process) that leaves which process graded the submission."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "pid").write_text(f"{os.getpid()} {result.assignment}")


def _nbgrader(root: Path, handed_in: dict[str, list[str]]) -> Path:
    for student, assignments in handed_in.items():
        for a in assignments:
            (root / "submitted" / student / a).mkdir(parents=True)
            shutil.copy(SOLUTIONS / a / f"{a}.ipynb", root / "submitted" / student / a / f"{a}.ipynb")
    for path in [root, *root.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    return root


@pytest.fixture
def fixture_env(monkeypatch):
    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))  # for the grading processes


def test_one_process_grades_every_assignment(fixture_env, open_tmp):
    folder = open_tmp / "in"
    for a, students in (("fx", ["alice", "bob"]), ("ex", ["carol", "dan", "erin"])):
        (folder / a).mkdir(parents=True)
        for s in students:
            shutil.copy(SOLUTIONS / a / f"{a}.ipynb", folder / a / f"{s}.ipynb")
    for path in [folder, *folder.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o666)
    assert assignment_folder(folder, "fx") == folder / "fx"
    batches = [Batch(a, assignment_folder(folder, a), open_tmp / "out" / a) for a in ("fx", "ex")]
    results = run_batches(batches, write=record_pid, jobs=1)
    assert {a: sorted(r.submission for r in rs) for a, rs in results.items()} == \
        {"fx": ["alice", "bob"], "ex": ["carol", "dan", "erin"]}
    assert all(r.score == r.max_score for rs in results.values() for r in rs)
    graded_by = {(open_tmp / "out" / a / n / "pid").read_text() for a, n in
                 [("fx", "alice"), ("fx", "bob"), ("ex", "carol"), ("ex", "dan"), ("ex", "erin")]}
    assert len({line.split()[0] for line in graded_by}) == 1, f"more than one process: {graded_by}"
    assert (open_tmp / "out" / "fx" / "_batch-1-of-1.json").exists() and (open_tmp / "out" / "ex" / "_batch-1-of-1.json").exists()


def test_cli_batch_all_over_nbgraders_layout(open_tmp):
    root = _nbgrader(open_tmp / "course", {"alice": ["fx", "ex"], "bob": ["ex"]})
    env = dict(os.environ, RLCOURSE_REPO=str(FIXTURE_COURSE))
    saved = course.REPO
    course.REPO = FIXTURE_COURSE
    try:
        assert assignments_in(root) == ["ex", "fx"]
        assert assignment_folder(root, "fx") == root
    finally:
        course.REPO = saved
    out = open_tmp / "out"
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "--all", str(root), "--out", str(out),
                           "--jobs", "2"], capture_output=True, text=True, env=env, cwd=REPO, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = {a: list(csv.DictReader((out / a / "gradebook.csv").open())) for a in ("fx", "ex")}
    assert [r["submission"] for r in rows["fx"]] == ["alice"] and [r["submission"] for r in rows["ex"]] == ["alice", "bob"]
    assert all(r["status"] == "graded" and r["score"] == r["max_score"] for rs in rows.values() for r in rs)
    assert "fx: 1 submissions" in done.stdout and "ex: 2 submissions" in done.stdout
    assert "hold no fx/" in done.stdout and "bob" in done.stdout, done.stdout


def test_a_folder_called_submitted_holding_one_folder_per_assignment_is_read_as_that(fixture_env, tmp_path):
    """``submitted/fx/*.ipynb`` is one folder per assignment, not nbgrader's ``submitted/<student>/<assignment>/``
    with a student called fx (found by a script that named its folder so and graded nothing)."""
    folder = tmp_path / "submitted"
    (folder / "fx").mkdir(parents=True)
    shutil.copy(SOLUTIONS / "fx" / "fx.ipynb", folder / "fx" / "alice.ipynb")
    assert assignment_folder(folder, "fx") == folder / "fx"
    nbgrader = _nbgrader(tmp_path / "course", {"alice": ["fx"]})
    assert assignment_folder(nbgrader, "fx") == nbgrader, "nbgrader's own layout is still read as such"
