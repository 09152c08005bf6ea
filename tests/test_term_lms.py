"""The instructor's term as an LMS course runs it (issue 36): formgrader's destructive buttons refused, a roster,
late penalties and extensions, Canvas's and Moodle's imports, feedback zips, regrade's refusals, one checkout.

Fast tests use the fixture course's assignment ``fx`` (stubs worth 3, 2, 1 and 1 points, a written answer
``q_why`` worth 2) with results written directly. The slow one runs a class in nbgrader's layout through
the whole term with the real commands: a student who skipped the assignment, a late student with an
extension, a late one without, a roster; batch, sync, hand grading through ``nbgrader.api.Gradebook`` (as
formgrader writes it), a suite fix and a regrade, the Canvas export and the feedback zips.
"""
from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import nbformat
import pytest
from traitlets.config import Config

from autograder.core.batch import GRADEBOOK_NAME
from autograder.core.results import GRADED, GRADER_ERROR, GradeResult, StubResult
from autograder.core.results import TestOutcome as Outcome
from autograder.outputs import export, feedback, gradebook, late, regrade
from autograder.outputs.batch_output import PREVIOUS_DIR, read_results
from autograder.outputs.checkout import checkout_problem, worker_packages
from autograder.outputs.files import write_gradebook, write_outputs
from autograder.outputs.formgrader_guard import AUTOGRADE_REFUSED, GENERATE_REFUSED
from conftest import FIXTURE_COURSE, REPO

POINTS = {"scaled_sum": 3.0, "Counter": 2.0, "mean_of": 1.0, "double_scaled": 1.0}
RELEASE = FIXTURE_COURSE / "assignments" / "fx" / "fx.ipynb"
BIN = Path(sys.executable).parent
ENV = {**os.environ, "PATH": str(BIN) + os.pathsep + os.environ.get("PATH", "")}


def graded(name: str, passed: set[str], version: str = "") -> GradeResult:
    stubs = [StubResult(s, [Outcome(f"{s} is right", s, p, s in passed, "" if s in passed else "off")])
             for s, p in POINTS.items()]
    return GradeResult("fx", name, stubs, [("q_why", 2.0)], status=GRADED, suite_version=version)


def submission(path: Path, answer: str = "YOUR ANSWER HERE") -> Path:
    nb = nbformat.read(str(RELEASE), as_version=4)
    for cell in nb.cells:
        if cell.metadata.get("nbgrader", {}).get("grade_id") == "q_why":
            cell.source = answer
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, str(path))
    return path


@pytest.fixture(scope="module")
def empty_gradebook(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("template")
    shutil.copy(REPO / "nbgrader_config.py", root / "nbgrader_config.py")
    gradebook.open_gradebook(gradebook.course_directory(root)).close()
    return root / ".nbgrader" / "gradebook.db"


@pytest.fixture
def new_course(tmp_path, empty_gradebook) -> Path:
    root = tmp_path / "course"
    (root / ".nbgrader").mkdir(parents=True)
    shutil.copy(REPO / "nbgrader_config.py", root / "nbgrader_config.py")
    shutil.copy(empty_gradebook, root / ".nbgrader" / "gradebook.db")
    return root


def nbgrader(*args: str, cwd: Path) -> str:
    done = subprocess.run([str(BIN / "nbgrader"), *args], cwd=cwd, env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return done.stdout + done.stderr


# ------------------------------------------------------------------ formgrader's buttons

def _course_copy(root: Path, config: str) -> Path:
    """The fixture course as nbgrader sees it, with one student submitted and placed for formgrader."""
    shutil.copytree(FIXTURE_COURSE, root, ignore=shutil.ignore_patterns("samples", "__pycache__", "ex"))
    (root / "nbgrader_config.py").write_text(config)
    for place in ("submitted", "autograded"):
        submission(root / place / "alice" / "fx" / "fx.ipynb", "Because.")
    return root


def _formgrader_api(root: Path, monkeypatch):
    """The ``NbGraderAPI`` formgrader's handlers build (``BaseHandler.api``), for the course in ``root``."""
    from nbgrader.apps.api import NbGraderAPI
    from nbgrader.server_extensions.formgrader.formgrader import FormgradeExtension

    monkeypatch.chdir(root)
    monkeypatch.setenv("PATH", ENV["PATH"])
    extension = FormgradeExtension()
    extension.initialize([])
    extension.coursedir.parent.load_config_file()
    return NbGraderAPI(extension.coursedir, extension.authenticator, parent=extension)


def test_formgrader_generate_and_autograde_are_refused_and_change_nothing(tmp_path, monkeypatch):
    root = _course_copy(tmp_path / "course", (REPO / "nbgrader_config.py").read_text())
    files = [root / "assignments/fx/fx.ipynb", root / "autograded/alice/fx/fx.ipynb", root / "submitted/alice/fx/fx.ipynb"]
    before = {p: p.read_bytes() for p in files}
    api = _formgrader_api(root, monkeypatch)
    generate = api.generate_assignment("fx")  # formgrader's Generate button (AssignHandler)
    assert not generate["success"] and GENERATE_REFUSED in generate["log"] and "make assignments" in generate["error"]
    autograde = api.autograde("fx", "alice")  # the Autograde button on a submission (AutogradeHandler)
    assert not autograde["success"] and AUTOGRADE_REFUSED in autograde["log"]
    assert {p: p.read_bytes() for p in files} == before, "the release and the autograded notebook survive"
    assert not (root / "feedback").exists()
    # The command-line generate that `make assignments` runs is not refused.
    nbgrader("generate_assignment", "fx", "--force", f"--CourseDirectory.db_url=sqlite:///{tmp_path}/scratch.db",
             cwd=root)
    assert nbformat.read(str(files[0]), as_version=4).cells


def test_without_the_guard_generate_deletes_the_release(tmp_path, monkeypatch):
    """The trap the guard closes, shown on the same course with the two guard lines removed."""
    config = "\n".join(line for line in (REPO / "nbgrader_config.py").read_text().splitlines()
                       if "exporter_class" not in line)
    root = _course_copy(tmp_path / "course", config)
    (root / "nbgrader_config.py").write_text(config.replace('"sqlite:///.nbgrader/gradebook.db"',
                                                            f'"sqlite:///{tmp_path}/missing/gradebook.db"'))
    api = _formgrader_api(root, monkeypatch)
    assert not api.generate_assignment("fx")["success"]
    assert not (root / "assignments/fx/fx.ipynb").exists(), "Generate with force removed the student notebook"


# ------------------------------------------------------------------ late rule, extensions, roster, LMS files

def test_the_late_rule_counts_each_period_begun_after_the_grace_up_to_the_cap():
    rule = late.LatePenalty(percent=10, cap_percent=50, grace_minutes=15)
    hour = 3600
    assert [late.penalty(rule, "s", 8.0, s) for s in (0, 10 * 60, 16 * 60, 24 * hour, 25 * hour, 30 * 24 * hour)] == \
        [0, 0, 0.8, 0.8, 1.6, 4.0]
    hourly = late.LatePenalty(per="hour", points=1)
    assert [late.penalty(hourly, "s", 3.0, s) for s in (1, hour, 90 * 60, 10 * hour)] == [1, 1, 2, 3]  # <= score
    config = Config()
    config.AssignLatePenalties.plugin_class = "autograder.outputs.late.LatePenalty"
    config.LatePenalty.percent = 20.0
    plugin = late.course_plugin(config)
    assert isinstance(plugin, late.LatePenalty) and plugin.percent == 20
    config = Config()
    config.LateSubmissionPlugin.penalty_method = "zero"  # nbgrader's own plugin, as its documentation configures it
    assert late.penalty(late.course_plugin(config), "s", 5.0, 1.0) == 5.0
    assert late.how_late(26 * hour + 59) == "1 day 2 h 1 min"
    with pytest.raises(Exception, match=">= 0"):
        late.LatePenalty(percent=-1)


ROSTER = """id,first_name,last_name,email,lms_user_id,sis_user_id,sis_login_id,section
alice,Alice,Adams,alice@example.edu,101,S-1,aadams,Tutorial A
bob,Bob,=Brown,bob@example.edu,102,S-2,bbrown,Tutorial B
carol,Carol,Clark,carol@example.edu,,S-3,cclark,Tutorial A
"""


@pytest.fixture
def synced(fixture_course, tmp_path, new_course):
    """A roster imported with nbgrader's own command, then four flat submissions synced: alice, bob, carol graded
    and dave a grader error; a due date, submission times, a penalty rule and an extension for bob."""
    root = new_course
    with (root / "nbgrader_config.py").open("a") as f:
        f.write("\nc.LatePenalty.percent = 10.0\nc.LatePenalty.cap_percent = 50.0\n")
    (root / "roster.csv").write_text(ROSTER)
    nbgrader("db", "student", "import", "roster.csv", cwd=root)
    folder, out = tmp_path / "submissions", tmp_path / "results"
    for name in ("alice", "bob", "carol", "dave"):
        submission(folder / f"{name}.ipynb", "Because.")
    write_outputs(graded("alice", set(POINTS)), out / "alice")
    write_outputs(graded("bob", {"scaled_sum", "Counter"}), out / "bob")
    write_outputs(graded("carol", {"scaled_sum"}), out / "carol")
    write_outputs(GradeResult("fx", "dave", [], [], error="sandbox did not start", status=GRADER_ERROR), out / "dave")
    gradebook.sync("fx", folder, out, root)
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.update_or_create_assignment("fx", duedate="2026-03-01 12:00:00 UTC")
        for student, when in [("alice", "2026-03-01 11:00:00 UTC"), ("bob", "2026-03-02 10:00:00 UTC"),
                              ("carol", "2026-03-02 13:00:00 UTC")]:
            gb.update_or_create_submission("fx", student, timestamp=when)
        for student, score in [("alice", 2.0), ("bob", 1.0), ("carol", 1.0)]:  # as formgrader's score box writes
            grade = gb.find_grade("q_why", "fx", "fx", student)
            grade.manual_score, grade.needs_manual_grade = score, False
        gb.db.commit()
    (root / "extensions.csv").write_text("student_id,assignment,deadline\nbob,fx,2026-03-02 12:00:00 UTC\n")
    return folder, out, root


def test_roster_names_survive_the_sync_and_formgrader_shows_them(synced):
    _, _, root = synced
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        alice = gb.find_student("alice")
        assert (alice.first_name, alice.last_name, alice.email, alice.lms_user_id) == (
            "Alice", "Adams", "alice@example.edu", "101")
        assert sorted(s.id for s in gb.students) == ["alice", "bob", "carol", "dave"]
        assert [s.student.last_name for s in gb.assignment_submissions("fx")]  # what formgrader lists by name
        with pytest.raises(Exception):
            gb.find_submission("fx", "dave")  # a grader error: the student is known, no submission recorded
    assert gradebook.read_not_recorded(root) == {"fx": {"dave": "sandbox did not start"}}


def test_canvas_export_applies_extensions_and_the_late_rule_and_agrees_with_nbgrader(synced, tmp_path):
    from nbgrader.plugins.export import CsvExportPlugin

    _, _, root = synced
    done = export.export(tmp_path / "canvas.csv", root, fmt="canvas")
    rows = list(csv.reader((tmp_path / "canvas.csv").open()))
    assert rows[0] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", "fx"]
    assert rows[1] == ["    Points Possible", "", "", "", "", "9"]
    by_name = {r[0]: r for r in rows[2:]}
    # alice on time: 7 + 2; bob 22 h late but within his extension: 5 + 1; carol 25 h late: 2 days begun, -20%
    # of 3 + 1; dave: the grader failed, nothing recorded: an empty cell, never a 0
    assert by_name["Adams, Alice"] == ["Adams, Alice", "101", "S-1", "aadams", "Tutorial A", "9"]
    assert by_name["'=Brown, Bob"][1:] == ["102", "S-2", "bbrown", "Tutorial B", "6"]
    assert by_name["Clark, Carol"][-1] == "3.2" and by_name["Clark, Carol"][1] == ""
    assert by_name["dave"][-1] == ""
    grades = {g.student_id: g for g in done.grades}
    assert grades["bob"].extended and grades["bob"].penalty == 0 and grades["bob"].late == "no"
    assert "extension to 2026-03-02 12:00 UTC" in grades["bob"].note
    assert grades["carol"].penalty == pytest.approx(0.8) and "1 day 1 h late" in grades["carol"].note
    assert grades["dave"].not_recorded and not grades["dave"].graded
    assert any("dave" in p for p in done.problems), "Canvas cannot match dave: no ID in the roster"
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        CsvExportPlugin(to=str(tmp_path / "nbgrader.csv")).export(gb)
    theirs = {r["student_id"]: float(r["score"]) for r in csv.DictReader((tmp_path / "nbgrader.csv").open())}
    assert theirs == {"alice": 9, "bob": 6, "carol": pytest.approx(3.2), "dave": 0}, \
        "nbgrader's own export sees the same penalties and extension (recorded in its gradebook)"

    export.export(tmp_path / "plain.csv", root, long=True)
    long = {r["student_id"]: r for r in csv.DictReader((tmp_path / "plain.csv").open())}
    assert long["carol"]["late_penalty"] == "0.8" and long["carol"]["total"] == "3.2"
    assert "-0.8 point(s) (10% of the score per day late" in long["carol"]["note"]
    assert long["dave"]["total"] == "" and "the grader failed" in long["dave"]["note"]
    export.export(tmp_path / "moodle.csv", root, fmt="moodle")
    moodle = list(csv.reader((tmp_path / "moodle.csv").open()))
    assert moodle[0] == ["First name", "Last name", "ID number", "Email address", "fx"]
    assert moodle[1] == ["Alice", "Adams", "alice", "alice@example.edu", "9"]


def test_an_lms_column_name_and_the_export_command(synced, tmp_path):
    from autograder.__main__ import main

    _, _, root = synced
    (tmp_path / "columns.csv").write_text("assignment,column\nfx,Homework 0 (87568490)\n")
    status = main(["export", "--format", "canvas", "--out", str(tmp_path / "c.csv"), "--course", str(root),
                   "--lms-columns", str(tmp_path / "columns.csv")])
    assert status == 3, "the export says the grader failed on dave, with a non-zero status"
    assert next(csv.reader((tmp_path / "c.csv").open()))[-1] == "Homework 0 (87568490)"


def test_feedback_zips_one_per_student_and_one_of_all(synced, tmp_path):
    _, out, root = synced
    done = feedback.write_feedback("fx", out, root, zip_dir=tmp_path / "zips")
    assert done.not_graded == ["dave"] and done.pending == []
    assert sorted(p.name for p in done.zips) == ["alice.zip", "bob.zip", "carol.zip", "fx-feedback.zip"]
    with zipfile.ZipFile(tmp_path / "zips" / "fx" / "bob.zip") as z:
        assert z.namelist() == ["feedback.md"] and "- `q_why`: 1 / 2" in z.read("feedback.md").decode()
    with zipfile.ZipFile(tmp_path / "zips" / "fx-feedback.zip") as z:
        assert sorted(z.namelist()) == ["alice/feedback.md", "bob/feedback.md", "carol/feedback.md"]
    assert "dave" in done.warnings()[-1]


# ------------------------------------------------------------------ regrade's refusals, one checkout

def test_regrade_only_after_a_suite_change_is_refused_before_anything_is_written(fixture_course, tmp_path):
    folder, out = tmp_path / "submissions", tmp_path / "results"
    for name in ("alice", "bob"):
        submission(folder / f"{name}.ipynb")
        write_outputs(graded(name, {"scaled_sum"}, version="0123456789abcdef"), out / name)
    write_gradebook(read_results(out).values(), out / GRADEBOOK_NAME)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(SystemExit, match="refused, nothing written.*bob.*Regrade them all"):
        regrade.regrade("fx", folder, out, only=["alice"])
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert not (out / PREVIOUS_DIR).exists()


def test_a_worker_that_would_import_another_checkout_is_refused_naming_both(tmp_path, monkeypatch):
    import autograder

    here = Path(autograder.__file__).resolve().parent
    assert worker_packages()["autograder"] == here and checkout_problem() is None
    other = tmp_path / "other"
    for package in ("autograder", "rlcourse"):
        (other / package).mkdir(parents=True)
        (other / package / "__init__.py").write_text("")
    monkeypatch.setenv("PYTHONPATH", str(other))  # as an editable install of another checkout would point
    problem = checkout_problem()
    assert problem and str(here) in problem and str(other / "autograder") in problem
    course_copy = tmp_path / "kit"
    (course_copy / "rlcourse").mkdir(parents=True)
    (course_copy / "rlcourse" / "__init__.py").write_text("")
    found = {"autograder": here, "rlcourse": REPO / "rlcourse"}
    assert str(course_copy) in checkout_problem(course_copy, found)
