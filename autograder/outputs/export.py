"""Final grades of a course, from its nbgrader gradebook: one CSV, the shape LMS gradebooks import.

``python -m autograder export --out grades.csv`` writes one row per student and, per assignment,
four columns: ``<id>`` (the total), ``<id> automatic`` (the stubs' scores: the hidden tests',
or a person's where one changed it in formgrader), ``<id> written`` (the hand-graded answers)
and ``<id> late`` (``yes``/``no`` when the gradebook knows both the due date and the submission
time, empty otherwise), then the course total. ``--long`` writes one row per student and
assignment instead, with the maximum and the number of written answers still to grade.

Every number is the gradebook's own (``Grade.score``: a person's score where given, else the
automatic one, plus extra credit), so each total equals what ``nbgrader export`` writes as
``score`` for that student and assignment (0 where nothing was submitted). A written answer not
yet graded counts 0 until it is, and the command says how many there are.
"""
from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

from autograder.outputs.gradebook import course_directory, open_gradebook
from autograder.outputs.text import plain


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
    """``yes``, ``no``, or empty where the due date or the submission time is unknown (or nothing was submitted)."""
    submitted: bool
    waiting: int
    """Written answers of this submission that no one has graded yet."""

    @property
    def total(self) -> float:
        return self.automatic + self.written


def final_grades(gb) -> list[FinalGrade]:
    """Every student × assignment of the gradebook, by assignment name, then student id."""
    from nbgrader.api import MissingEntry

    out = []
    for assignment in sorted(gb.assignments, key=lambda a: a.name):
        for student in sorted(gb.students, key=lambda s: s.id):
            names = (student.first_name or "", student.last_name or "", student.email or "")
            try:
                submission = gb.find_submission(assignment.name, student.id)
            except MissingEntry:
                out.append(FinalGrade(student.id, *names, assignment.name, 0.0, 0.0, assignment.max_score, "",
                                      submitted=False, waiting=0))
                continue
            grades = [g for nb in submission.notebooks for g in nb.grades]
            late = ""
            if submission.timestamp is not None and submission.duedate is not None:
                late = "yes" if submission.total_seconds_late > 0 else "no"
            out.append(FinalGrade(
                student.id, *names, assignment.name,
                automatic=sum(g.score for g in grades if g.cell_type == "code"),
                written=sum(g.score for g in grades if g.cell_type != "code"),
                max_score=assignment.max_score, late=late, submitted=True,
                waiting=sum(g.cell_type != "code" and g.manual_score is None and g.auto_score is None for g in grades)))
    return out


def _number(value: float) -> str:
    return f"{round(value, 6):g}"


def _text(value: str) -> str:
    """A CSV cell a spreadsheet shows as text, never runs as a formula (names come from uploads)."""
    value = plain(value).replace("\n", " ")
    return "'" + value if value[:1] in ("=", "+", "-", "@") else value


def wide_rows(grades: list[FinalGrade]) -> list[list[str]]:
    assignments = list(dict.fromkeys(g.assignment for g in grades))
    header = ["student_id", "last_name", "first_name", "email"]
    for a in assignments:
        header += [a, f"{a} automatic", f"{a} written", f"{a} late"]
    rows = [header + ["course total"]]
    by_student: dict[str, dict[str, FinalGrade]] = {}
    for g in grades:
        by_student.setdefault(g.student_id, {})[g.assignment] = g
    for student, per in by_student.items():
        first = next(iter(per.values()))
        row = [_text(student), _text(first.last_name), _text(first.first_name), _text(first.email)]
        for a in assignments:
            g = per[a]
            row += [_number(g.total), _number(g.automatic), _number(g.written), g.late]
        rows.append(row + [_number(sum(g.total for g in per.values()))])
    return rows


def long_rows(grades: list[FinalGrade]) -> list[list[str]]:
    rows = [["student_id", "assignment", "automatic", "written", "total", "max_score", "late", "submitted",
             "written_not_graded"]]
    for g in grades:
        rows.append([_text(g.student_id), g.assignment, _number(g.automatic), _number(g.written), _number(g.total),
                     _number(g.max_score), g.late, "yes" if g.submitted else "no", str(g.waiting)])
    return rows


def export(out: Path, course_root: Path | None = None, long: bool = False) -> list[FinalGrade]:
    """Write the course's final grades to ``out`` (see the module); returns them."""
    with open_gradebook(course_directory(course_root)) as gb:
        grades = final_grades(gb)
    rows = long_rows(grades) if long else wide_rows(grades)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows(rows)
    os.replace(tmp, out)
    return grades
