"""Traps an instructor met in a trial term (their notes: T2-T6, T11), each as the outputs now behave.

Fast tests on the fixture course's assignment ``fx`` (stubs worth 3, 2, 1 and 1 points, a written answer
``q_why`` worth 2), with results written as ``batch`` writes them and grades given through
``nbgrader.api.Gradebook`` as formgrader's score box writes them.
"""
from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path

import nbformat

from autograder.core.batch import safe_name
from autograder.outputs import export, feedback, gradebook
from autograder.core.results import UNGRADABLE, GradeResult
from autograder.outputs.files import write_gradebook, write_outputs
from test_term import POINTS, empty_gradebook, graded, grades_of, give, new_course, submission, term  # noqa: F401


# ------------------------------------------------------------------ T2: a student id that is not a plain name

def test_a_student_id_with_a_space_is_recorded_and_exported_under_that_id(fixture_course, tmp_path, new_course):
    root = new_course
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:  # the roster, as nbgrader imports it
        gb.add_student("Mallory Smith", first_name="Mallory", last_name="Smith", lms_user_id="1012")
        gb.add_student("alice", first_name="Alice", last_name="Adams", lms_user_id="1001")
    (root / "roster.csv").write_text("id,first_name,last_name,lms_user_id\nMallory Smith,Mallory,Smith,1012\n"
                                     "alice,Alice,Adams,1001\n")
    folder, out = tmp_path / "submitted", tmp_path / "results"  # nbgrader's layout: submitted/<student>/fx/
    submission(folder / "Mallory Smith" / "fx" / "fx.ipynb", "Because.")
    submission(folder / "alice" / "fx" / "fx.ipynb", "Because.")
    safe = safe_name("Mallory Smith")
    assert safe != "Mallory Smith", "the batch's folder name is the id made safe"
    write_outputs(graded(safe, {"scaled_sum", "Counter"}), out / safe)
    write_outputs(graded("alice", set(POINTS)), out / "alice")

    report = gradebook.sync("fx", folder, out, root)
    assert sorted(s for _, s in report.recorded) == ["Mallory Smith", "alice"]
    assert report.warnings() == []
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        assert sorted(s.id for s in gb.students) == ["Mallory Smith", "alice"], "no new student under the safe name"
        gb.add_student(safe)  # what the sync before this fix recorded: named, so it can be removed
        with warnings.catch_warnings():  # nbgrader's add_submission builds rows before adding them: SAWarnings
            warnings.simplefilter("ignore")
            gb.add_submission("fx", safe)
    assert any(safe in w and "Mallory Smith" in w and "student remove" in w
               for w in gradebook.sync("fx", folder, out, root).warnings())
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.remove_submission("fx", safe)
        gb.remove_student(safe)
    assert grades_of(root, "Mallory Smith")["Counter"] == (2, None, False)
    assert (root / "autograded" / "Mallory Smith" / "fx" / "fx.ipynb").is_file()
    assert json.loads((out / "_students.json").read_text())[safe] == ["Mallory Smith"]

    give(root, "Mallory Smith", "q_why", 1.0)
    export.export(tmp_path / "canvas.csv", root, fmt="canvas")
    rows = {r[0]: r for r in csv.reader((tmp_path / "canvas.csv").open())}
    assert rows["Smith, Mallory"][1] == "1012" and rows["Smith, Mallory"][-1] == "6"
    assert len(rows) == 2 + 2, "a header, Points Possible and one row per roster student: no unmatchable row"
    done = feedback.write_feedback("fx", out, root)
    assert root / "feedback" / "Mallory Smith" / "fx" / "feedback.md" in done.written


def test_a_student_id_that_cannot_be_a_gradebook_id_is_named_in_a_warning(fixture_course, tmp_path, new_course):
    folder, out = tmp_path / "submitted", tmp_path / "results"
    raw = "eve\tx"  # a tab: no folder of autograded/ should carry it
    submission(folder / raw / "fx" / "fx.ipynb")
    write_outputs(graded(safe_name(raw), set()), out / safe_name(raw))
    report = gradebook.sync("fx", folder, out, new_course)
    assert [s for _, s in report.recorded] == [safe_name(raw)]
    assert len(report.warnings()) == 1 and "'eve\\tx'" in report.warnings()[0] and safe_name(raw) in report.warnings()[0]


# ------------------------------------------------------------------ T3: a hand grade of an answer handed in again

def test_a_hand_grade_of_an_answer_that_changed_is_marked_for_grading_again_and_named(term, tmp_path):
    folder, out, root = term
    gradebook.sync("fx", folder, out, root)
    give(root, "bob", "q_why", 1.5, "Half of it.")
    give(root, "alice", "q_why", 2.0)
    give(root, "bob", "Counter", 1.0)  # a stub score changed by hand; bob's code does not change below
    submission(folder / "bob.ipynb", None)  # bob hands in again without his answer
    nb = nbformat.read(str(folder / "alice.ipynb"), as_version=4)  # alice again: other code, the same answer
    nb.cells.append(nbformat.v4.new_code_cell("x = 1"))
    nbformat.write(nb, str(folder / "alice.ipynb"))

    report = gradebook.sync("fx", folder, out, root)
    assert grades_of(root, "bob")["q_why"] == (None, 1.5, True), "back in formgrader's needs-grading list"
    assert grades_of(root, "bob")["Counter"] == (0, 1.0, False), "its cell did not change"
    assert grades_of(root, "alice")["q_why"] == (None, 2.0, False), "her answer did not change"
    assert report.reread == [("bob", "q_why")]
    assert any("bob" in w and "q_why" in w for w in report.warnings())
    again = gradebook.sync("fx", folder, out, root)  # not graded again yet: still said, not lost
    assert again.reread == [("bob", "q_why")] and grades_of(root, "bob")["q_why"] == (None, 1.5, True)

    done = export.export(tmp_path / "grades.csv", root)
    bob = next(g for g in done.grades if g.student_id == "bob")
    assert "q_why" in bob.note and any("bob" in p and "q_why" in p for p in done.problems)
    give(root, "bob", "q_why", 0.0)  # a person graded it again (formgrader clears the flag)
    assert gradebook.sync("fx", folder, out, root).reread == []


# ------------------------------------------------------------------ T11: no submission time, a due date and a rule

def test_export_names_the_submissions_whose_time_is_unknown_when_there_is_a_deadline(term, tmp_path):
    folder, out, root = term
    with (root / "nbgrader_config.py").open("a") as f:
        f.write("\nc.LatePenalty.percent = 10.0\n")
    gradebook.sync("fx", folder, out, root)  # flat notebooks: no timestamp.txt, no time
    plain_before = export.export(tmp_path / "before.csv", root)
    assert not any("time" in p for p in plain_before.problems), "no due date: nothing to say"
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.update_or_create_assignment("fx", duedate="2026-03-01 12:00:00 UTC")
        for student in ("alice", "bob"):
            gb.update_or_create_submission("fx", student, timestamp="2026-03-02 13:00:00 UTC")
    done = export.export(tmp_path / "grades.csv", root)
    unknown = [p for p in done.problems if "submission time" in p]
    assert len(unknown) == 1 and "fx carol" in unknown[0] and "alice" not in unknown[0]
    carol = next(g for g in done.grades if g.student_id == "carol")
    assert carol.late == "" and carol.penalty == 0 and "submission time unknown" in carol.note
    alice = next(g for g in done.grades if g.student_id == "alice")
    assert alice.late == "yes" and alice.penalty > 0 and "unknown" not in alice.note


# ------------------------------------------------------------------ T4: stub scores changed by hand, in every total

def test_regrade_and_class_report_totals_count_a_stub_score_changed_by_hand_as_export_does(term, tmp_path):
    from autograder.outputs import regrade
    from autograder.outputs.batch_output import read_results
    from autograder.outputs.class_report import write_class_report

    folder, out, root = term
    gradebook.sync("fx", folder, out, root)
    give(root, "bob", "Counter", 1.5)  # the tests gave 0 of 2; a person gave 1.5
    give(root, "bob", "q_why", 1.0)
    before = read_results(out)
    write_outputs(graded("bob", {"scaled_sum", "mean_of"}), out / "bob")  # a regrade: mean_of 0 → 1
    gradebook.sync("fx", folder, out, root)
    exported = {g.student_id: g.total for g in export.export(tmp_path / "grades.csv", root).grades}
    assert exported["bob"] == 3 + 1.5 + 1 + 1.0

    done = regrade.Regrade(out, regrade.compare(before, read_results(out)), True,
                           regrade.written_scores("fx", out, root), [],
                           gradebook.hand_stub_scores("fx", out, root))
    lines = regrade.change_lines(done.changes, done.written, done.hand_stubs)
    bob = next(line for line in lines if line.startswith("bob"))
    assert "3 → 4" in bob and "5.5 → 6.5" in bob, bob  # before: 3 + 1.5 by hand + 1 written
    assert "Counter 1.5" in bob, "the line says which stub score a person set"

    report = write_class_report("fx", out, tmp_path / "report", course_root=root)
    totals = dict(zip(report.table.names, report.table.totals))
    assert totals == {name: exported[name] for name in totals}, "the report's totals are export's"
    assert "Counter" in (tmp_path / "report" / "report.md").read_text().split("## Score distribution")[0]


# ------------------------------------------------------------------ T5: results-diff against a partial snapshot

def test_results_diff_compares_only_the_submissions_in_both_and_says_how_many_were_left_out(term, capsys):
    from autograder.__main__ import main
    from autograder.outputs import regrade

    folder, out, root = term
    snapshot = regrade.archive(out, ["bob"])  # as the batch archives one student who handed in again
    write_outputs(graded("bob", {"scaled_sum", "mean_of"}), out / "bob")
    assert main(["results-diff", str(snapshot), str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in printed[1:-2]] == ["bob"], "alice and carol are not in the snapshot"
    assert printed[-2] == "1 of 1 submission(s) changed"
    assert printed[-1] == ("compared the 1 submission(s) in both folders; 2 only in the new one (not compared: "
                           "alice, carol), 0 only in the old one")


# ------------------------------------------------------------------ T6: results of an earlier suite, synced

def test_sync_warns_when_results_were_graded_by_a_suite_other_than_the_current_one(term):
    from autograder.core import course

    folder, out, root = term
    assert not any("suite" in w for w in gradebook.sync("fx", folder, out, root).warnings())
    for name in ("alice", "bob"):
        result = graded(name, {"scaled_sum"})
        result.suite_version = "0123456789abcdef"
        write_outputs(result, out / name)
    current = graded("carol", set())
    current.suite_version = course.suite_version("fx")
    write_outputs(current, out / "carol")
    report = gradebook.sync("fx", folder, out, root)
    stale = [w for w in report.warnings() if "suite" in w]
    assert len(stale) == 1 and "2 result(s)" in stale[0] and "0123456789abcdef" in stale[0]
    assert "alice" in stale[0] and "carol" not in stale[0] and "regrade fx" in stale[0]


# ------------------------------------------------------------------ another assignment's notebook, or none at all

def test_a_written_answer_missing_from_another_assignments_notebook_waits_for_nobody(term):
    folder, out, root = term
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("def policy(obs):\n    return 0")])
    nbformat.write(nb, str(folder / "dave.ipynb"))  # hw1's notebook, say, handed in for fx
    wrong = graded("dave", set())
    wrong.wrong_notebook = "this notebook defines none of fx's stubs; it seems to be hw1_imitation's"
    write_outputs(wrong, out / "dave")
    submission(folder / "bob.ipynb", None)  # fx's own notebook with the answer cell deleted: a person looks

    gradebook.sync("fx", folder, out, root)
    assert grades_of(root, "dave")["q_why"] == (0, None, False), "nothing of fx's to read: 0, not in the queue"
    assert grades_of(root, "bob")["q_why"] == (None, None, True), "the answer may be elsewhere in fx's notebook"
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        comments = {c.name: c.auto_comment for c in gb.find_submission_notebook("fx", "fx", "dave").comments}
    assert "hw1_imitation" in comments["q_why"]
    give(root, "dave", "q_why", 1.0)  # a person may still grade it; the next sync keeps their score
    gradebook.sync("fx", folder, out, root)
    assert grades_of(root, "dave")["q_why"] == (0, 1.0, False)


def test_gradebook_csv_gives_a_submission_found_ungradable_before_any_test_the_assignments_maximum(tmp_path):
    nothing = GradeResult("fx", "eve", [], [], error="no notebook in the submission", status=UNGRADABLE)
    write_gradebook([graded("alice", {"scaled_sum"}), nothing], tmp_path / "gradebook.csv")
    rows = {r["submission"]: r for r in csv.DictReader((tmp_path / "gradebook.csv").open())}
    assert rows["eve"]["max_score"] == rows["alice"]["max_score"] == "7"
    assert (rows["eve"]["score"], rows["eve"]["percent"], rows["eve"]["status"]) == ("0", "0.0", UNGRADABLE)
    write_gradebook([nothing], tmp_path / "alone.csv")  # no graded result to take the maximum from: left empty
    assert next(csv.DictReader((tmp_path / "alone.csv").open()))["max_score"] == ""


def test_a_student_named_by_two_submissions_gets_the_newest_and_a_warning(fixture_course, tmp_path, new_course):
    """Red team D: two Gradescope submissions listing the same SID were both recorded for that student, the one
    whose folder sorts last silently overwriting the other (here the older, untouched one over the full one)."""
    folder, out, root = tmp_path / "export", tmp_path / "results", new_course
    submission(folder / "submission_1" / "fx.ipynb", "Because.")
    submission(folder / "submission_2" / "fx.ipynb")
    (folder / "submission_metadata.yml").write_text("""\
submission_1:
  :submitters:
  - :name: Ada Lovelace
    :sid: '1001'
  :created_at: 2026-03-02 09:00:00.000000000 +00:00
submission_2:
  :submitters:
  - :name: Ada Lovelace
    :sid: '1001'
  :created_at: 2026-03-01 09:00:00.000000000 -07:00
""")
    write_outputs(graded("submission_1", set(POINTS)), out / "submission_1")
    write_outputs(graded("submission_2", set()), out / "submission_2")
    report = gradebook.sync("fx", folder, out, root)
    assert report.recorded == [("submission_1", "1001")]
    assert grades_of(root, "1001")["scaled_sum"] == (3, None, False), "the newer submission, graded 7/7"
    (warning,) = [w for w in report.warnings() if "named by 2 submissions" in w]
    assert "submission_1" in warning and "submission_2" in warning
    students = json.loads((out / "_students.json").read_text())
    assert students["submission_1"] == ["1001"] and students["submission_2"] == [], "feedback goes from the one recorded"
