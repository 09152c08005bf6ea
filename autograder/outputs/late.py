"""Late submissions: the course's penalty rule (an nbgrader late-submission plugin) and per-student extensions.

The rule lives in the course's ``nbgrader_config.py``, where nbgrader looks for it: nbgrader's
``AssignLatePenalties.plugin_class`` names the plugin, here :class:`LatePenalty` (configured by
``c.LatePenalty.*``), though nbgrader's own ``LateSubmissionPlugin`` (``penalty_method = 'zero'``) or
any other ``BasePlugin`` works the same. :func:`course_plugin` builds the plugin the configuration
names, as nbgrader's ``autograde`` would, and :func:`penalty` applies it to one submission, bounded
to ``[0, score]`` as nbgrader's ``AssignLatePenalties`` bounds it.

Extensions come from a CSV file (default ``extensions.csv`` in the course), one row per student and
assignment: ``student_id,assignment,deadline`` (the new deadline, e.g. ``2026-03-03 12:00:00 UTC``).
:func:`apply_extensions` records each one in the gradebook as nbgrader's own extension (the time
past the assignment's due date), so formgrader, ``nbgrader export`` and this kit's export all see
the same deadline.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from nbgrader.plugins import BasePlugin
from traitlets import Enum, Float, validate

EXTENSIONS_NAME = "extensions.csv"
"""The extensions file of a course, in its root, read by ``nbgrader-sync`` and ``export``."""
PERIOD_SECONDS = {"day": 86_400.0, "hour": 3_600.0}


class LatePenalty(BasePlugin):
    """A penalty per day (or hour) late, each period begun counting whole, after a grace period, up to a cap.

    ``percent`` takes that share of the submission's score per period; ``points`` takes that many
    points per period (set one of them). The penalty never exceeds ``cap_percent`` of the score.
    """

    per = Enum(("day", "hour"), default_value="day", help="the period a penalty is counted in").tag(config=True)
    percent = Float(0.0, help="percent of the score lost per period late (begun)").tag(config=True)
    points = Float(0.0, help="points lost per period late (begun)").tag(config=True)
    cap_percent = Float(100.0, help="the penalty never exceeds this percent of the score").tag(config=True)
    grace_minutes = Float(0.0, help="a submission at most this late carries no penalty").tag(config=True)

    @validate("percent", "points", "cap_percent", "grace_minutes")
    def _non_negative(self, proposal):
        if proposal.value < 0:
            raise ValueError(f"LatePenalty.{proposal.trait.name} must be >= 0, not {proposal.value}")
        return proposal.value

    def periods(self, seconds_late: float) -> int:
        """Periods of lateness charged: none within the grace, else every period begun (from the deadline)."""
        if seconds_late <= 60 * self.grace_minutes or seconds_late <= 0:
            return 0
        return math.ceil(seconds_late / PERIOD_SECONDS[self.per])

    def late_submission_penalty(self, student_id: str, score: float, total_seconds_late: float) -> float | None:
        if self.percent and self.points:
            raise ValueError("set LatePenalty.percent or LatePenalty.points, not both")
        n = self.periods(total_seconds_late)
        taken = n * (self.percent / 100 * score if self.percent else self.points)
        return round(min(taken, self.cap_percent / 100 * score), 6)

    def describe(self) -> str:
        """The rule in words, for the export's notes and the documentation."""
        if not (self.percent or self.points):
            return "no penalty"
        each = f"{self.percent:g}% of the score" if self.percent else f"{self.points:g} point(s)"
        grace = f" after {self.grace_minutes:g} min of grace" if self.grace_minutes else ""
        return f"{each} per {self.per} late (each begun){grace}, at most {self.cap_percent:g}% of the score"


def course_plugin(config) -> BasePlugin:
    """The late-submission plugin the course's nbgrader configuration names, built as nbgrader builds it."""
    from nbgrader.preprocessors import AssignLatePenalties

    assign = AssignLatePenalties(config=config)
    assign.init_plugin()
    return assign.plugin_inst


def penalty(plugin: BasePlugin, student_id: str, score: float, seconds_late: float) -> float:
    """The points ``plugin`` takes off ``score`` for a submission ``seconds_late`` late, within ``[0, score]``."""
    if seconds_late <= 0 or score <= 0:
        return 0.0
    taken = plugin.late_submission_penalty(student_id, score, seconds_late)
    return 0.0 if taken is None else float(min(max(taken, 0.0), score))


def describe(plugin: BasePlugin) -> str:
    if hasattr(plugin, "describe"):
        return plugin.describe()
    method = getattr(plugin, "penalty_method", None)
    return {"zero": "a late submission scores 0", "none": "no penalty"}.get(method, type(plugin).__name__)


@dataclass(frozen=True)
class Extension:
    student_id: str
    assignment: str
    deadline: datetime
    """The new deadline, in UTC (naive, as nbgrader stores times)."""


def _column(header: list[str], *names: str) -> str | None:
    wanted = {n.replace("_", " ") for n in names}
    return next((h for h in header if h.strip().lower().replace("_", " ") in wanted), None)


def read_extensions(path: Path) -> list[Extension]:
    """The extensions in ``path`` (CSV: ``student_id,assignment,deadline``); an absent file gives none."""
    from nbgrader.utils import parse_utc

    path = Path(path)
    if not path.is_file():
        return []
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    header = list(rows[0]) if rows else []
    student = _column(header, "student_id", "student", "id")
    assignment = _column(header, "assignment", "assignment_id")
    deadline = _column(header, "deadline", "new_deadline", "new deadline", "due", "duedate")
    if rows and not (student and assignment and deadline):
        raise SystemExit(f"{path}: the columns must be student_id, assignment and deadline (found: {', '.join(header)})")
    out = []
    for line, row in enumerate(rows, start=2):
        if not (row.get(student) or "").strip():
            continue
        try:
            when = parse_utc(row[deadline].strip())
        except (ValueError, OverflowError, TypeError) as err:
            raise SystemExit(f"{path}, line {line}: {row[deadline]!r} is not a date and time ({err})") from None
        out.append(Extension(row[student].strip(), row[assignment].strip(), when))
    return out


def apply_extensions(gb, extensions: list[Extension]) -> list[str]:
    """Record each extension in the gradebook (nbgrader's ``grant_extension``: the time past the due date).
    Returns what could not be applied, one line each (no submission, no due date, a deadline before it)."""
    from nbgrader.api import MissingEntry

    problems = []
    for ext in extensions:
        try:
            assignment = gb.find_assignment(ext.assignment)
            gb.find_submission(ext.assignment, ext.student_id)
        except MissingEntry:
            problems.append(f"extension for {ext.student_id} on {ext.assignment}: no such submission in the gradebook "
                            "(not handed in, or not synced yet); nothing to extend")
            continue
        if assignment.duedate is None:
            problems.append(f"extension for {ext.student_id} on {ext.assignment}: {ext.assignment} has no due date in "
                            "the gradebook (set one in formgrader, or nbgrader db assignment add ID --duedate=...)")
            continue
        minutes = (ext.deadline - assignment.duedate).total_seconds() / 60
        if minutes < 0:
            problems.append(f"extension for {ext.student_id} on {ext.assignment}: {ext.deadline} is before the due "
                            f"date {assignment.duedate}; not applied")
            continue
        gb.grant_extension(ext.assignment, ext.student_id, minutes=minutes)
    return problems


def how_late(seconds: float) -> str:
    """``2 days 3 h 5 min``: lateness as a person reads it (to the minute, rounded up)."""
    minutes = math.ceil(seconds / 60)
    days, rest = divmod(minutes, 24 * 60)
    hours, minutes = divmod(rest, 60)
    parts = ([f"{days} day" + ("s" if days != 1 else "")] if days else []) + ([f"{hours} h"] if hours else []) \
        + ([f"{minutes} min"] if minutes or not (days or hours) else [])
    return " ".join(parts)
