"""Students' feedback once the written answers are graded: the automatic part and the hand-given part.

``python -m autograder feedback ID --results DIR`` writes, for every student the gradebook sync
recorded, ``feedback/<student>/<ID>/feedback.md`` in the nbgrader course: the batch's
per-stub feedback (what passed, what failed, the hints), then each written answer's score and
the grader's comment (or "not graded yet"), any stub score or comment a person changed in
formgrader, and the total, which is the gradebook's (the number ``export`` writes). With
``--html`` it also runs ``nbgrader generate_feedback``, whose HTML, beside it, shows the
submitted notebook with the same scores and comments cell by cell.

It says which written answers no one has graded yet (nbgrader's HTML shows them as 0), naming
each student and answer, and which submissions got no feedback because the grader failed on them.

Delivery: ``--zip DIR`` packs each student's feedback folder for an LMS: ``DIR/<ID>/<student>.zip``
(one per student, ``feedback.md`` and the HTML at its top level) and ``DIR/<ID>-feedback.zip``
(one folder per student inside). nbgrader's exchange (``release_feedback``) is not used: it needs a
``course_id`` and the exchange's ``submission_secret.txt`` of ``nbgrader collect``, and this course
releases into ``assignments/`` with an empty ``course_id``.
"""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from autograder.core import course
from autograder.outputs.batch_output import read_results, read_students
from autograder.outputs.gradebook import course_directory, open_gradebook, with_nbgrader_path
from autograder.core.store import atomic_write
from autograder.outputs.text import MESSAGE_CHARS, NAME_CHARS, NOTE_CHARS, cap, listed, markdown_text, plain, points
from autograder.core.batch import safe_name
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


@dataclass
class FeedbackReport:
    written: list[Path] = field(default_factory=list)
    """The ``feedback.md`` files written."""
    pending: list[tuple[str, str]] = field(default_factory=list)
    """``(student, written answer)`` for each answer no one has graded yet: it shows as 0 in the feedback."""
    not_graded: list[str] = field(default_factory=list)
    """Submissions with no feedback because the grader failed on them (run the batch again)."""
    zips: list[Path] = field(default_factory=list)

    def warnings(self) -> list[str]:
        out = []
        if self.pending:
            answers = listed([f"{plain(s)}: {plain(g)}" for s, g in self.pending], 30)
            out.append(f"warning: {len(self.pending)} written answer(s) are not graded yet and show as 0 in the "
                       f"feedback (nbgrader's HTML too): {answers}. Grade them in formgrader, then run feedback "
                       "again.")
        if self.not_graded:
            out.append(f"warning: no feedback for {len(self.not_graded)} submission(s) the grader failed on: "
                       f"{', '.join(plain(n) for n in self.not_graded[:30])}; run the batch again, sync, then feedback.")
        return out


def write_feedback(assignment: str, results_dir: Path, course_root: Path | None = None,
                   html: bool = False, zip_dir: Path | None = None) -> FeedbackReport:
    """Write ``feedback.md`` (and, with ``html``, nbgrader's feedback HTML) for every synced student, and with
    ``zip_dir`` the zips for an LMS (see the module)."""
    from nbgrader.api import MissingEntry

    course.check_assignment(assignment)
    results, students = read_results(results_dir), read_students(results_dir)
    if not students:
        raise SystemExit(f"{results_dir} has not been recorded in a gradebook yet: run "
                         f"python -m autograder nbgrader-sync {assignment} FOLDER --results {results_dir} first")
    coursedir = course_directory(course_root)
    if html:  # first: nbgrader's --force empties each feedback/<student>/<id>/ folder it writes
        generate_feedback_html(assignment, coursedir)
    report = FeedbackReport()
    folders = {}
    with open_gradebook(coursedir) as gb:
        for name, result in results.items():
            if result.status == GRADER_ERROR:
                report.not_graded.append(name)
                continue
            for student in students.get(name, []):
                try:
                    submitted = gb.find_submission_notebook(assignment, assignment, student)
                except MissingEntry:
                    continue
                folder = Path(coursedir.format_path(coursedir.feedback_directory, student, assignment))
                atomic_write(folder / FEEDBACK_NAME, feedback_with_hand_grades(result, submitted))
                report.written.append(folder / FEEDBACK_NAME)
                folders[student] = folder
                report.pending += [(student, g.name) for g in submitted.grades if g.cell_type != "code"
                                   and g.manual_score is None and g.auto_score is None]
    if zip_dir is not None:
        report.zips = zip_feedback(assignment, folders, Path(zip_dir))
    return report


def _feedback_files(folder: Path) -> list[Path]:
    """What a student receives of a feedback folder: the Markdown and HTML, never nbgrader's bookkeeping."""
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.is_symlink() and p.suffix in (".md", ".html"))


def zip_feedback(assignment: str, folders: dict[str, Path], out_dir: Path) -> list[Path]:
    """``out_dir/<assignment>/<student>.zip`` per student and ``out_dir/<assignment>-feedback.zip`` of them all
    (one folder per student, named by the student id made safe as batch makes names safe)."""
    per_student = out_dir / assignment
    per_student.mkdir(parents=True, exist_ok=True)
    written = []
    everyone = out_dir / f"{assignment}-feedback.zip"
    tmp_all = everyone.with_name(f".{everyone.name}.tmp")
    with zipfile.ZipFile(tmp_all, "w", zipfile.ZIP_DEFLATED) as whole:
        for student, folder in sorted(folders.items()):
            name = safe_name(student)
            target = per_student / f"{name}.zip"
            tmp = target.with_name(f".{target.name}.tmp")
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as one:
                for path in _feedback_files(folder):
                    one.write(path, path.name)
                    whole.write(path, f"{name}/{path.name}")
            tmp.replace(target)
            written.append(target)
    tmp_all.replace(everyone)
    return [*written, everyone]


def generate_feedback_html(assignment: str, coursedir) -> None:
    """``nbgrader generate_feedback`` for every student placed for formgrader: ``feedback/<student>/<id>/<id>.html``."""
    with_nbgrader_path()
    command = [str(Path(sys.executable).parent / "nbgrader"), "generate_feedback", assignment, "--force",
               f"--CourseDirectory.root={coursedir.root}", f"--CourseDirectory.db_url={coursedir.db_url}"]
    done = subprocess.run(command, cwd=coursedir.root, env=dict(os.environ), capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"nbgrader generate_feedback failed:\n{done.stderr[-2000:]}")
