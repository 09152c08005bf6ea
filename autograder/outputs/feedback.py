"""Students' feedback once the written answers are graded: the automatic part and the hand-given part.

``python -m autograder feedback ID --results DIR`` writes, for every student the gradebook sync
recorded, ``feedback/<student>/<ID>/feedback.md`` in the nbgrader course: the batch's
per-stub feedback (what passed, what failed, the hints), then each written answer's score and
the grader's comment (or "not graded yet"), any stub score or comment a person changed in
formgrader, and the total, which is the gradebook's (the number ``export`` writes). With
``--html`` it also runs ``nbgrader generate_feedback``, whose HTML, beside it, shows the
submitted notebook with the same scores and comments cell by cell.
"""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

from autograder.core import course
from autograder.outputs.batch_output import read_results, read_students
from autograder.outputs.gradebook import course_directory, open_gradebook, with_nbgrader_path
from autograder.core.store import atomic_write
from autograder.outputs.text import MESSAGE_CHARS, NAME_CHARS, NOTE_CHARS, cap, markdown_text, points
from autograder.core.results import GRADER_ERROR, GradeResult



FEEDBACK_NAME = "feedback.md"
"""Each submission's feedback file, in its batch folder (and in the course's feedback/ after a sync)."""


def feedback_markdown(result: GradeResult) -> str:
    """The per-student feedback file: per stub, what passed, what failed and a hint."""
    out = [f"# Feedback: {result.assignment} · {markdown_text(cap(result.submission, NAME_CHARS))}", "",
           f"**Automatic score: {points(result.score)} / {points(result.max_score)}**", ""]
    if result.error:
        out += [f"> This submission could not be graded automatically: {markdown_text(cap(result.error, MESSAGE_CHARS))}",
                ""]
    for note in result.notes:
        out.append(f"- note: {markdown_text(cap(note, NOTE_CHARS))}")
    if result.notes:
        out.append("")
    for stub in result.stubs:
        out += [f"## `{stub.name}`: {points(stub.score)} / {points(stub.max_score)}", ""]
        for test in stub.tests:
            if test.passed:
                out.append(f"- ✓ {test.name}")
            else:
                out.append(f"- ✗ {test.name}: {markdown_text(cap(test.message, MESSAGE_CHARS))}")
                if test.hint:
                    out.append(f"  - *hint:* {test.hint}")
        out.append("")
    if result.manual:
        out += ["## Written answers (graded by hand)", ""]
        out += [f"- `{gid}`: {points(p)} point(s), pending" for gid, p in result.manual]
        out.append("")
    return "\n".join(out)

def _points(value: float | None) -> str:
    return f"{round(value, 6):g}" if value is not None else "-"


def _comment(text: str | None) -> list[str]:
    return [f"  - *comment:* {markdown_text(text)}"] if text and text.strip() else []


def feedback_with_hand_grades(result: GradeResult, submitted) -> str:
    """``feedback.md`` for one student: the batch's automatic feedback, then what people gave in the gradebook.

    ``submitted`` is the student's ``nbgrader.api.SubmittedNotebook``. The hand-graded section lists
    every written answer (markdown grade cell) with its score, or "not graded yet", and the grader's
    comment; a stub whose score a person set (``manual_score``) or commented on is listed too.
    """
    automatic = feedback_markdown(dataclasses.replace(result, manual=[]))
    comments = {c.name: c.manual_comment for c in submitted.comments}
    written = [g for g in submitted.grades if g.cell_type != "code"]
    adjusted = [g for g in submitted.grades if g.cell_type == "code"
                and (g.manual_score is not None or g.extra_credit or (comments.get(g.name) or "").strip())]
    out = [automatic.rstrip(), ""]
    if written:
        out += ["## Written answers (graded by hand)", ""]
        for grade in written:
            if grade.manual_score is None and grade.auto_score is None:
                out.append(f"- `{grade.name}`: not graded yet ({_points(grade.max_score)} point(s))")
            else:
                extra = f" + {_points(grade.extra_credit)} extra credit" if grade.extra_credit else ""
                unanswered = " (left unanswered)" if grade.manual_score is None else ""
                out.append(f"- `{grade.name}`: {_points(grade.score - (grade.extra_credit or 0))} / "
                           f"{_points(grade.max_score)}{extra}{unanswered}")
            out += _comment(comments.get(grade.name))
        out.append("")
    if adjusted:
        out += ["## Stubs your grader looked at", ""]
        for grade in adjusted:
            extra = f" + {_points(grade.extra_credit)} extra credit" if grade.extra_credit else ""
            if grade.manual_score is not None:
                out.append(f"- `{grade.name}`: {_points(grade.manual_score)} / {_points(grade.max_score)}{extra} "
                           f"(the tests gave {_points(grade.auto_score)})")
            else:
                out.append(f"- `{grade.name}`: {_points(grade.auto_score)} / {_points(grade.max_score)}{extra}")
            out += _comment(comments.get(grade.name))
        out.append("")
    code = sum(g.score for g in submitted.grades if g.cell_type == "code")
    hand = sum(g.score for g in written)
    waiting = sum(g.manual_score is None and g.auto_score is None for g in written)
    out += [f"**Total: {_points(code)} (stubs) + {_points(hand)} (written) = {_points(submitted.score)} / "
            f"{_points(submitted.max_score)}**" + (f" ({waiting} written answer(s) not graded yet)" if waiting else ""),
            ""]
    return "\n".join(out)


def write_feedback(assignment: str, results_dir: Path, course_root: Path | None = None,
                   html: bool = False) -> list[Path]:
    """Write ``feedback.md`` (and, with ``html``, nbgrader's feedback HTML) for every synced student."""
    from nbgrader.api import MissingEntry

    course.check_assignment(assignment)
    results, students = read_results(results_dir), read_students(results_dir)
    if not students:
        raise SystemExit(f"{results_dir} has not been recorded in a gradebook yet: run "
                         f"python -m autograder nbgrader-sync {assignment} FOLDER --results {results_dir} first")
    coursedir = course_directory(course_root)
    if html:  # first: nbgrader's --force empties each feedback/<student>/<id>/ folder it writes
        generate_feedback_html(assignment, coursedir)
    written = []
    with open_gradebook(coursedir) as gb:
        for name, result in results.items():
            if result.status == GRADER_ERROR:
                continue
            for student in students.get(name, []):
                try:
                    submitted = gb.find_submission_notebook(assignment, assignment, student)
                except MissingEntry:
                    continue
                folder = Path(coursedir.format_path(coursedir.feedback_directory, student, assignment))
                atomic_write(folder / FEEDBACK_NAME, feedback_with_hand_grades(result, submitted))
                written.append(folder / FEEDBACK_NAME)
    return written


def generate_feedback_html(assignment: str, coursedir) -> None:
    """``nbgrader generate_feedback`` for every student placed for formgrader: ``feedback/<student>/<id>/<id>.html``."""
    with_nbgrader_path()
    command = [str(Path(sys.executable).parent / "nbgrader"), "generate_feedback", assignment, "--force",
               f"--CourseDirectory.root={coursedir.root}", f"--CourseDirectory.db_url={coursedir.db_url}"]
    done = subprocess.run(command, cwd=coursedir.root, env=dict(os.environ), capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"nbgrader generate_feedback failed:\n{done.stderr[-2000:]}")
