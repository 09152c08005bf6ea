"""Final grades of a course, from its nbgrader gradebook: one CSV, in this kit's shape or an LMS's import format.

``python -m autograder export --out grades.csv [--format plain|canvas|moodle] [--long]`` writes:

- ``plain`` (the default): one row per student and, per assignment, ``<id>`` (the total, after any
  late penalty), ``<id> automatic`` (the stubs' scores: the hidden tests', or a person's where one
  changed it in formgrader), ``<id> written`` (the hand-graded answers), ``<id> late`` (``yes``/``no``
  when the gradebook knows both the deadline and the submission time, empty otherwise; a submission
  with a deadline but no time is named in a warning and its note),
  ``<id> penalty`` (the points the late rule took) and ``<id> note`` (what was applied, in words:
  an extension, how late, the penalty, a grade not recorded because the grader failed), then the
  course total. ``--long`` writes one row per student and assignment instead.
- ``canvas``: Canvas's gradebook import: ``Student, ID, SIS User ID, SIS Login ID, Section``, then
  one column per assignment (named as ``--lms-columns`` maps it, e.g. ``Homework 0 (87568490)``
  as Canvas's own export names it, else the assignment id), a ``Points Possible`` row, and one
  row per student; nothing else, since Canvas would take any other column for a new assignment.
  ``ID``, ``SIS User ID``, ``SIS Login ID`` and ``Section`` come from the roster (``roster.csv``:
  ``lms_user_id``, ``sis_user_id``, ``sis_login_id``, ``section``; the same file
  ``nbgrader db student import`` reads, which ignores the columns it does not know).
- ``moodle``: ``First name, Last name, ID number, Email address``, then one column per assignment:
  Moodle's CSV grade import, mapped by ``Email address`` (or ``ID number``) in its dialog.

Every number is the gradebook's own (``Grade.score``: a person's score where given, else the
automatic one, plus extra credit). The late rule is the course's nbgrader late-submission plugin
(:mod:`autograder.outputs.late`), applied to the current score past each student's deadline (the due
date, or their extension from ``extensions.csv``, recorded in the gradebook first) and recorded as
nbgrader's ``late_submission_penalty``, so each total equals what ``nbgrader export`` writes as
``score`` (0 where nothing was submitted). A written answer not yet graded counts 0 until it is, and
the command says how many there are; a score given by hand to a cell whose text changed since (the
notebook handed in again, marked by ``nbgrader-sync``) counts until a person grades it again, and the
command names it. A student whose submission the grader failed on (so it was
never recorded) gets an empty cell, never a 0, and the command names them.
"""
from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field
from pathlib import Path

from autograder.outputs import late
from autograder.outputs.gradebook import course_directory, open_gradebook, read_not_recorded
from autograder.outputs.text import listed, plain

FORMATS = ("plain", "canvas", "moodle")
ROSTER_NAME = "roster.csv"
"""The course's roster, in its root: nbgrader's student columns and the LMS's (see the module)."""
CANVAS_IDS = ("Student", "ID", "SIS User ID", "SIS Login ID", "Section")
CANVAS_POINTS = "    Points Possible"
"""The first cell of the row under Canvas's header, as Canvas's own export writes it."""
MOODLE_IDS = ("First name", "Last name", "ID number", "Email address")


@dataclass
class FinalGrade:
    student_id: str
    first_name: str
    last_name: str
    email: str
    assignment: str
    automatic: float
    written: float
    max_score: float
    late: str
    """``yes``, ``no``, or empty where the deadline or the submission time is unknown (or nothing was submitted)."""
    submitted: bool
    waiting: int
    """Written answers of this submission that no one has graded yet."""
    penalty: float = 0.0
    """Points the late rule took off."""
    seconds_late: float = 0.0
    deadline: str = ""
    """This student's deadline (the due date, or their extension), UTC; empty when the assignment has none."""
    extended: bool = False
    not_recorded: str = ""
    """Why the latest grading of this submission is not in the gradebook (the grader failed), if so."""
    lms_user_id: str = ""
    time_unknown: bool = False
    """A deadline is set but the submission's time is not known, so lateness could not be checked."""
    reread: list[str] = field(default_factory=list)
    """Cells graded by hand whose text changed since (marked by ``nbgrader-sync``): the earlier score counts."""
    notes: list[str] = field(default_factory=list)

    @property
    def raw(self) -> float:
        return self.automatic + self.written

    @property
    def total(self) -> float:
        return self.raw - self.penalty

    @property
    def graded(self) -> bool:
        """False where there is no grade to give: the grader failed and nothing was recorded before."""
        return not (self.not_recorded and not self.submitted)

    @property
    def note(self) -> str:
        return "; ".join(self.notes)


def _utc(when) -> str:
    return when.strftime("%Y-%m-%d %H:%M UTC") if when is not None else ""


def final_grades(gb, plugin=None, not_recorded: dict[str, dict[str, str]] | None = None) -> list[FinalGrade]:
    """Every student × assignment of the gradebook, by assignment name, then student id; with the late rule
    ``plugin`` (default: none) applied and recorded as each submission's ``late_submission_penalty``."""
    from nbgrader.api import MissingEntry

    not_recorded = not_recorded or {}
    out = []
    for assignment in sorted(gb.assignments, key=lambda a: a.name):
        failed = not_recorded.get(assignment.name, {})
        for student in sorted(gb.students, key=lambda s: s.id):
            names = (student.first_name or "", student.last_name or "", student.email or "")
            why = failed.get(student.id, "")
            try:
                submission = gb.find_submission(assignment.name, student.id)
            except MissingEntry:
                grade = FinalGrade(student.id, *names, assignment.name, 0.0, 0.0, assignment.max_score, "",
                                   submitted=False, waiting=0, deadline=_utc(assignment.duedate), not_recorded=why,
                                   lms_user_id=student.lms_user_id or "")
                grade.notes.append(f"not graded: the grader failed on this submission ({plain(why)[:200]}); "
                                   "grade it again, then sync" if why else "not submitted")
                out.append(grade)
                continue
            grades = [g for nb in submission.notebooks for g in nb.grades]
            grade = FinalGrade(
                student.id, *names, assignment.name,
                automatic=sum(g.score for g in grades if g.cell_type == "code"),
                written=sum(g.score for g in grades if g.cell_type != "code"),
                max_score=assignment.max_score, late="", submitted=True,
                waiting=sum(g.cell_type != "code" and g.manual_score is None and g.auto_score is None for g in grades),
                deadline=_utc(submission.duedate), extended=submission.extension is not None, not_recorded=why,
                lms_user_id=student.lms_user_id or "")
            grade.reread = sorted(g.name for g in grades if g.manual_score is not None and g.needs_manual_grade)
            _lateness(grade, submission, plugin)
            if why:
                grade.notes.append(f"the latest grading failed ({plain(why)[:200]}): the grade shown is the one "
                                   "recorded before; grade it again, then sync")
            if grade.waiting:
                grade.notes.append(f"{grade.waiting} written answer(s) not graded yet, counted 0")
            if grade.reread:
                grade.notes.append(f"handed in again since {', '.join(grade.reread)} was graded by hand: the earlier "
                                   "score counts until it is graded again")
            out.append(grade)
    gb.db.commit()
    return out


def _lateness(grade: FinalGrade, submission, plugin) -> None:
    """Whether the submission was late, the penalty the rule gives on its current score (recorded in the
    gradebook as nbgrader's own penalty, on its notebook), and a note saying so."""
    if grade.extended:
        grade.notes.append(f"extension to {grade.deadline}")
    if submission.duedate is not None and submission.timestamp is None:
        grade.time_unknown = True
        grade.notes.append("submission time unknown (no timestamp.txt or :created_at:): lateness not checked, "
                           "no late penalty applied")
    if submission.timestamp is None or submission.duedate is None:
        return
    grade.seconds_late = submission.total_seconds_late
    grade.late = "yes" if grade.seconds_late > 0 else "no"
    if plugin is not None and grade.seconds_late > 0:
        grade.penalty = late.penalty(plugin, grade.student_id, grade.raw, grade.seconds_late)
    for i, notebook in enumerate(submission.notebooks):  # one notebook per assignment in this course
        notebook.late_submission_penalty = grade.penalty if i == 0 and grade.penalty else None
    if grade.seconds_late > 0:
        grade.notes.append(f"submitted {late.how_late(grade.seconds_late)} late: "
                           + (f"-{_number(grade.penalty)} point(s) ({late.describe(plugin)})" if grade.penalty
                              else f"no penalty ({late.describe(plugin) if plugin is not None else 'no rule'})"))


def _number(value: float) -> str:
    return f"{round(value, 6):g}"


def _text(value: str) -> str:
    """A CSV cell a spreadsheet shows as text, never runs as a formula (names come from uploads)."""
    value = plain(value).replace("\n", " ")
    return "'" + value if value[:1] in ("=", "+", "-", "@", "\t", "\r", "|", "%") else value


def _total(g: FinalGrade) -> str:
    return _number(g.total) if g.graded else ""


def _by_student(grades: list[FinalGrade]) -> tuple[list[str], dict[str, dict[str, FinalGrade]]]:
    assignments = list(dict.fromkeys(g.assignment for g in grades))
    by_student: dict[str, dict[str, FinalGrade]] = {}
    for g in grades:
        by_student.setdefault(g.student_id, {})[g.assignment] = g
    return assignments, by_student


def wide_rows(grades: list[FinalGrade]) -> list[list[str]]:
    assignments, by_student = _by_student(grades)
    header = ["student_id", "last_name", "first_name", "email"]
    for a in assignments:
        header += [a, f"{a} automatic", f"{a} written", f"{a} late", f"{a} penalty", f"{a} note"]
    rows = [header + ["course total"]]
    for student, per in by_student.items():
        first = next(iter(per.values()))
        row = [_text(student), _text(first.last_name), _text(first.first_name), _text(first.email)]
        for a in assignments:
            g = per[a]
            auto, written = (_number(g.automatic), _number(g.written)) if g.graded else ("", "")
            row += [_total(g), auto, written, g.late, _number(g.penalty), _text(g.note)]
        rows.append(row + [_number(sum(g.total for g in per.values() if g.graded))])
    return rows


def long_rows(grades: list[FinalGrade]) -> list[list[str]]:
    rows = [["student_id", "assignment", "automatic", "written", "late_penalty", "total", "max_score", "deadline",
             "late", "submitted", "written_not_graded", "note"]]
    for g in grades:
        auto, written = (_number(g.automatic), _number(g.written)) if g.graded else ("", "")
        rows.append([_text(g.student_id), g.assignment, auto, written, _number(g.penalty), _total(g),
                     _number(g.max_score), g.deadline, g.late, "yes" if g.submitted else "no", str(g.waiting),
                     _text(g.note)])
    return rows


def read_roster(path: Path | None) -> dict[str, dict[str, str]]:
    """Per student id, the roster's columns (lower-cased names, spaces as ``_``); empty without a roster."""
    if path is None or not Path(path).is_file():
        return {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = [{(k or "").strip().lower().replace(" ", "_"): (v or "").strip() for k, v in r.items()}
                for r in csv.DictReader(f)]
    if rows and "id" not in rows[0]:
        raise SystemExit(f"{path}: a roster needs an `id` column (nbgrader's student id), as nbgrader db student "
                         "import reads it")
    return {r["id"]: r for r in rows if r.get("id")}


def read_lms_columns(path: Path | None) -> dict[str, str]:
    """``assignment -> column name`` for an LMS file (CSV ``assignment,column``); empty without one."""
    if path is None:
        return {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    if rows and [c.strip().lower() for c in rows[0][:2]] == ["assignment", "column"]:
        rows = rows[1:]
    return {r[0].strip(): r[1].strip() for r in rows if len(r) >= 2 and r[0].strip()}


def canvas_rows(grades: list[FinalGrade], roster: dict[str, dict[str, str]],
                columns: dict[str, str]) -> list[list[str]]:
    """Canvas's gradebook import (see the module): identity columns, one column per assignment, Points Possible."""
    assignments, by_student = _by_student(grades)
    maximum = {g.assignment: g.max_score for g in grades}
    rows = [[*CANVAS_IDS, *(_text(columns.get(a, a)) for a in assignments)],
            [CANVAS_POINTS, "", "", "", "", *(_number(maximum[a]) for a in assignments)]]
    for student, per in by_student.items():
        first, info = next(iter(per.values())), roster.get(student, {})
        name = ", ".join(n for n in (first.last_name, first.first_name) if n) or student
        rows.append([_text(name), _text(info.get("lms_user_id") or first.lms_user_id),
                     _text(info.get("sis_user_id", "")), _text(info.get("sis_login_id", "")),
                     _text(info.get("section", "")), *(_total(per[a]) for a in assignments)])
    return rows


def moodle_rows(grades: list[FinalGrade], roster: dict[str, dict[str, str]],
                columns: dict[str, str]) -> list[list[str]]:
    """Moodle's CSV grade import: names, ID number, e-mail, then one column per assignment."""
    assignments, by_student = _by_student(grades)
    rows = [[*MOODLE_IDS, *(_text(columns.get(a, a)) for a in assignments)]]
    for student, per in by_student.items():
        first, info = next(iter(per.values())), roster.get(student, {})
        rows.append([_text(first.first_name), _text(first.last_name), _text(info.get("id_number") or student),
                     _text(first.email or info.get("email", "")), *(_total(per[a]) for a in assignments)])
    return rows


@dataclass
class Exported:
    grades: list[FinalGrade]
    rule: str
    """The late rule, in words."""
    problems: list[str]
    """Extensions that could not be applied, students an LMS cannot match: one line each."""


def export(out: Path, course_root: Path | None = None, long: bool = False, fmt: str = "plain",
           roster: Path | None = None, extensions: Path | None = None, lms_columns: Path | None = None) -> Exported:
    """Write the course's final grades to ``out`` (see the module). ``roster`` and ``extensions`` default to the
    course's ``roster.csv`` and ``extensions.csv`` (either may be absent)."""
    if fmt not in FORMATS:
        raise SystemExit(f"unknown format {fmt!r}; one of {', '.join(FORMATS)}")
    coursedir = course_directory(course_root)
    root = Path(coursedir.root)
    plugin = late.course_plugin(coursedir.config)
    with open_gradebook(coursedir) as gb:
        problems = late.apply_extensions(gb, late.read_extensions(extensions or root / late.EXTENSIONS_NAME))
        grades = final_grades(gb, plugin, read_not_recorded(root))
    unknown = [f"{g.assignment} {plain(g.student_id)}" for g in grades if g.time_unknown]
    if unknown:
        problems.append(f"{len(unknown)} submission(s) have a deadline but no submission time (no timestamp.txt, no "
                        f":created_at:), so they were not checked for lateness and no late penalty ("
                        f"{late.describe(plugin)}) was applied: {listed(unknown, 30)}")
    reread = [f"{g.assignment} {plain(g.student_id)}: {', '.join(g.reread)}" for g in grades if g.reread]
    if reread:
        problems.append(f"{len(reread)} submission(s) have a score given by hand to a cell whose text changed since "
                        f"(handed in again): {'; '.join(reread[:20])}; the earlier score counts until a person grades "
                        "it again in formgrader (it is listed there as needing a grade)")
    people = read_roster(roster or root / ROSTER_NAME)
    columns = read_lms_columns(lms_columns)
    if fmt == "canvas":
        rows = canvas_rows(grades, people, columns)
        unmatched = sorted({g.student_id for g in grades if not (people.get(g.student_id, {}).get("lms_user_id")
                                                                  or people.get(g.student_id, {}).get("sis_user_id")
                                                                  or g.lms_user_id)})
        if unmatched:
            problems.append(f"{len(unmatched)} student(s) have no Canvas ID or SIS User ID in the roster, so Canvas "
                            f"matches them by name only: {', '.join(plain(s) for s in unmatched[:20])}")
    elif fmt == "moodle":
        rows = moodle_rows(grades, people, columns)
    else:
        rows = long_rows(grades) if long else wide_rows(grades)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows(rows)
    os.replace(tmp, out)
    return Exported(grades, late.describe(plugin), problems)
