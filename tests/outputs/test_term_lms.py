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
from autograder.outputs.text import markdown_text
from test_term import empty_gradebook, new_course  # noqa: F401 - fixtures shared with the term test
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
        listed = sorted((s.student.last_name, s.student.first_name) for s in gb.assignment_submissions("fx"))
        assert listed == [("=Brown", "Bob"), ("Adams", "Alice"), ("Clark", "Carol")], "formgrader's names, not None"
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
    assert worker_packages()["autograder"] == here and checkout_problem() is None, \
        "the zygote puts the grader's own checkout first, so its workers import this one"
    problem = checkout_problem(found={"autograder": other / "autograder", "rlcourse": other / "rlcourse"})
    assert problem and str(here) in problem and str(other / "autograder") in problem
    course_copy = tmp_path / "kit"
    (course_copy / "rlcourse").mkdir(parents=True)
    (course_copy / "rlcourse" / "__init__.py").write_text("")
    found = {"autograder": here, "rlcourse": REPO / "rlcourse"}
    assert str(course_copy) in checkout_problem(course_copy, found)


# ------------------------------------------------------------------ the whole term, end to end

BUGGY_MEAN_TEST = "check_scalar(got, float(np.median(values)))  # a suite bug: the median, not the mean"
TERM_ROSTER = """id,first_name,last_name,email,lms_user_id,sis_user_id,sis_login_id,section
alice,Alice,Adams,alice@example.edu,101,S-1,aadams,A
bob,Bob,Brown,bob@example.edu,102,S-2,bbrown,A
carol,Carol,Clark,carol@example.edu,103,S-3,cclark,B
erin,Erin,Evans,erin@example.edu,104,S-4,eevans,B
"""


@pytest.mark.slow
def test_a_term_in_nbgrader_layout_to_canvas_with_a_roster_a_missing_student_and_late_ones(open_tmp, monkeypatch):
    """alice hands in everything on time; bob hands in late inside his extension; carol late without one (10% a
    day begun); erin hands in only the other assignment (ex), so she is missing from fx. The suite marks mean_of
    against the median; it is fixed after hand grading and the class regraded."""
    from autograder.core import course

    source = open_tmp / "fixture"
    shutil.copytree(FIXTURE_COURSE, source, ignore=shutil.ignore_patterns("samples", "__pycache__"))
    shutil.copy(REPO / "nbgrader_config.py", source / "nbgrader_config.py")
    suite = source / "autograder" / "suites" / "fx" / "test_fx.py"
    fixed = suite.read_text()
    suite.write_text(fixed.replace("check_scalar(got, reference.mean_of(values))", BUGGY_MEAN_TEST))
    assert suite.read_text() != fixed
    monkeypatch.setattr(course, "REPO", source)
    env = {**ENV, "RLCOURSE_REPO": str(source)}
    root = open_tmp / "course"
    root.mkdir()
    (root / "nbgrader_config.py").write_text((REPO / "nbgrader_config.py").read_text()
                                             + "\nc.LatePenalty.percent = 10.0\nc.LatePenalty.cap_percent = 50.0\n")
    (root / "roster.csv").write_text(TERM_ROSTER)
    (root / "extensions.csv").write_text("student_id,assignment,deadline\nbob,fx,2026-03-03 00:00:00 UTC\n")
    solution = {c.metadata["nbgrader"]["grade_id"]: re.sub(r"\s*### (BEGIN|END) SOLUTION\n?", "\n", c.source)
                for c in nbformat.read(str(source / "solutions/fx/fx.ipynb"), as_version=4).cells
                if "nbgrader" in c.metadata}
    submitted = root / "submitted"
    for student, stubs, answer, stamp in [
            ("alice", list(POINTS), "The max cancels in the ratio.", "2026-03-01 20:00:00.000000 UTC"),
            ("bob", ["scaled_sum"], "Because.", "2026-03-02 22:00:00.000000 UTC"),
            ("carol", ["scaled_sum", "Counter"], "It cancels.", "2026-03-03 01:00:00.000000 UTC")]:
        nb = nbformat.read(str(source / "assignments/fx/fx.ipynb"), as_version=4)
        for cell in nb.cells:
            gid = cell.metadata.get("nbgrader", {}).get("grade_id")
            if gid in stubs:
                cell.source = solution[gid]
            elif gid == "q_why":
                cell.source = answer
        (submitted / student / "fx").mkdir(parents=True)
        nbformat.write(nb, str(submitted / student / "fx" / "fx.ipynb"))
        (submitted / student / "fx" / "timestamp.txt").write_text(stamp)
    (submitted / "erin" / "ex").mkdir(parents=True)
    shutil.copy(source / "assignments/ex/ex.ipynb", submitted / "erin" / "ex" / "ex.ipynb")
    for path in [open_tmp, *open_tmp.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o644)
    out = open_tmp / "results"

    def cli(*args: str, status: int = 0) -> subprocess.CompletedProcess:
        done = subprocess.run([sys.executable, "-m", "autograder", *args], env=env, cwd=REPO, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode == status, done.stdout[-2000:] + done.stderr[-3000:]
        return done

    (root / ".nbgrader").mkdir()  # where this configuration keeps the gradebook: nbgrader does not create it
    nbgrader("db", "student", "import", "roster.csv", cwd=root)
    shown = cli("batch", "fx", str(root), "--out", str(out)).stdout
    assert {n: r.score for n, r in read_results(out).items()} == {"alice": 6, "bob": 3, "carol": 5}
    assert "1 student folder(s) hold no fx/" in shown and "erin" in shown
    assert "(3 graded, 0 ungradable, 0 not graded because the grader failed)" in shown, shown
    cli("nbgrader-sync", "fx", str(root), "--results", str(out), "--course", str(root))
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.update_or_create_assignment("fx", duedate="2026-03-02 00:00:00 UTC")
        assert sorted(s.student.id for s in gb.assignment_submissions("fx")) == ["alice", "bob", "carol"]
        assert gb.find_student("carol").last_name == "Clark", "the roster's names are kept by the sync"
        waiting = [(g.notebook.assignment.student.id, g.name) for g in gb.db.query(type(gb.find_grade(
            "q_why", "fx", "fx", "alice"))).all() if g.needs_manual_grade]
        assert sorted(waiting) == [("alice", "q_why"), ("bob", "q_why"), ("carol", "q_why")], "erin's not in the queue"
        for student, score in [("alice", 2.0), ("bob", 1.0), ("carol", 1.0)]:  # formgrader's score boxes
            grade = gb.find_grade("q_why", "fx", "fx", student)
            grade.manual_score, grade.needs_manual_grade = score, False
        gb.find_comment("q_why", "fx", "fx", "bob").manual_comment = "Say why it cancels."
        gb.db.commit()

    suite.write_text(fixed)  # the suite is fixed mid-term
    csv_before = (out / GRADEBOOK_NAME).read_bytes()
    refused = cli("regrade", "fx", str(root), "--out", str(out), "--only", "alice", "--course", str(root), status=1)
    assert "refused, nothing written" in refused.stderr and (out / GRADEBOOK_NAME).read_bytes() == csv_before
    assert not (out / PREVIOUS_DIR).exists()
    shown = cli("regrade", "fx", str(root), "--out", str(out), "--course", str(root)).stdout
    alice_line = next(line for line in shown.splitlines() if line.startswith("alice"))
    assert "6 → 7" in alice_line and "mean_of 0 → 1" in alice_line and "8 → 9" in alice_line, shown
    assert {n: r.score for n, r in read_results(out).items()} == {"alice": 7, "bob": 3, "carol": 5}

    shown = cli("export", "--format", "canvas", "--out", str(open_tmp / "canvas.csv"), "--course", str(root)).stdout
    rows = list(csv.reader((open_tmp / "canvas.csv").open()))
    assert rows[0] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", "fx"]
    assert rows[1][0].strip() == "Points Possible" and rows[1][5] == "9"
    assert {r[0]: (r[1], r[5]) for r in rows[2:]} == {
        "Adams, Alice": ("101", "9"),  # on time: 7 + 2
        "Brown, Bob": ("102", "4"),  # 22 h late, inside his extension: 3 + 1, no penalty
        "Clark, Carol": ("103", "4.8"),  # 25 h late, two days begun: (5 + 1) - 20%
        "Evans, Erin": ("104", "0")}  # handed in no fx
    assert "fx bob: extension to 2026-03-03 00:00 UTC" in shown and "fx carol: submitted 1 day 1 h late" in shown
    done = subprocess.run([str(BIN / "nbgrader"), "export", "--to", str(open_tmp / "nb.csv")], cwd=root, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    theirs = {r["student_id"]: float(r["score"]) for r in csv.DictReader((open_tmp / "nb.csv").open())}
    assert theirs == {"alice": 9, "bob": 4, "carol": pytest.approx(4.8), "erin": 0}

    shown = cli("feedback", "fx", "--results", str(out), "--course", str(root), "--zip", str(open_tmp / "zips"))
    assert "warning" not in shown.stderr, shown.stderr
    with zipfile.ZipFile(open_tmp / "zips" / "fx-feedback.zip") as z:
        assert sorted(z.namelist()) == ["alice/feedback.md", "bob/feedback.md", "carol/feedback.md"]
        bob = z.read("bob/feedback.md").decode()
    assert "**Automatic score: 3 / 7**" in bob and "- `q_why`: 1 / 2" in bob and "= 4 / 9**" in bob

    report = cli("class-report", "fx", str(root), "--results", str(out), "--course", str(root)).stdout
    assert "the grader failed on none" in report
    md = (out / "_class_report" / "report.md").read_text()
    assert markdown_text("written: q_why") in md and "maximum 9 points" in md  # the written answer is an item
    assert "Names are pseudonyms" in md and "alice" not in md and (out / "_pseudonyms.csv").is_file()
