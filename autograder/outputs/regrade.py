"""Regrade after a suite is fixed mid-term, and show per student what changed.

``python -m autograder regrade ID FOLDER --out DIR [--only NAME ...]`` regrades the submissions
of a batch already graded into ``DIR`` (all of them, or the named few):

1. it copies their current results (``result.json``, ``results.json``, ``feedback.md``) and the
   batch's ``gradebook.csv`` into ``DIR/_previous/<UTC time>/``, where they stay readable;
2. it removes each one's ``result.json`` (the mark ``batch`` reads as "graded") and runs the
   batch again, which grades exactly those and rewrites ``gradebook.csv`` for all;
3. when ``DIR`` was recorded in the course's gradebook before, it records it again: the
   automatic scores change, the scores and comments people gave in formgrader stay;
4. it prints, per submission, the automatic score before and after, the stubs that changed,
   the hand-given written score (unchanged) and the total before and after, which counts a stub
   score a person changed in formgrader (kept, and named on the line) as ``export`` does.

Before it writes anything it refuses a partial regrade (``--only``) when the suite changed since the
other submissions were graded (their recorded suite version is not the current one): grading a few
with the new suite would leave ``gradebook.csv`` and the nbgrader gradebook with results of two
suites. It ends with a non-zero status when the grader failed on any submission (their rows have no
score; run it again), naming them.

``python -m autograder results-diff OLD NEW`` prints the same comparison for any two result
folders (``DIR/_previous/<time>`` and ``DIR``, say), over the submissions in both, and says how many
were in one only (a ``_previous/<time>`` the batch wrote when one student handed in again holds that one).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from autograder.core import course
from autograder.core.batch import GRADEBOOK_NAME, discover
from autograder.outputs.files import grade_folder
from autograder.outputs.gradebook import HandStubs, hand_stub_delta, hand_stub_scores
from autograder.outputs.batch_output import read_results, read_students
from autograder.outputs.text import listed
from autograder.core.store import RESULT_NAME, archive_results
from autograder.core.results import GRADED, GRADER_ERROR, GradeResult


@dataclass
class Change:
    submission: str
    before: float | None
    """The automatic score before (None: no score, a grader error or not graded)."""
    after: float | None
    stubs: list[tuple[str, float | None, float | None]] = field(default_factory=list)
    """``(stub, before, after)`` for each stub whose score changed."""
    status: tuple[str, str] | None = None
    """``(before, after)`` when the result's status changed (graded, ungradable, grader_error)."""
    before_stubs: dict[str, float] = field(default_factory=dict)
    """Every stub's automatic score before (empty without a score); ``after_stubs`` after."""
    after_stubs: dict[str, float] = field(default_factory=dict)

    @property
    def changed(self) -> bool:
        return self.before != self.after or bool(self.stubs) or self.status is not None


def _score(result: GradeResult | None) -> float | None:
    return result.score if result is not None and result.has_score else None


def compare(before: dict[str, GradeResult], after: dict[str, GradeResult],
            names: list[str] | None = None) -> list[Change]:
    """Per submission (those named, else every one in either), what changed between two sets of results."""
    changes = []
    for name in names if names is not None else sorted(set(before) | set(after)):
        old, new = before.get(name), after.get(name)
        old_stubs = {s.name: s.score for s in old.stubs} if old is not None and old.has_score else {}
        new_stubs = {s.name: s.score for s in new.stubs} if new is not None and new.has_score else {}
        stubs = [(s, old_stubs.get(s), new_stubs.get(s)) for s in dict.fromkeys([*old_stubs, *new_stubs])
                 if old_stubs.get(s) != new_stubs.get(s)]
        statuses = (old.status if old else "none", new.status if new else "none")
        changes.append(Change(name, _score(old), _score(new), stubs,
                              statuses if statuses[0] != statuses[1] else None, old_stubs, new_stubs))
    return changes


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{round(value, 6):g}"


def change_lines(changes: list[Change], written: dict[str, float | None] | None = None,
                 hand_stubs: dict[str, HandStubs] | None = None) -> list[str]:
    """A table, one line per submission: automatic before → after, the stubs that changed and, when
    ``written`` (the hand-given written score per submission) is known, it and the totals. The totals count
    ``hand_stubs`` (stub scores a person changed in formgrader, kept) as the gradebook and ``export`` do, and
    the line names them."""
    hand_stubs = hand_stubs or {}
    lines = []
    width = max([len(c.submission) for c in changes] + [10])
    head = f"{'submission':<{width}}  {'automatic':<15}"
    if written is not None:
        head += f"  {'written (by hand, kept)':<23}  {'total':<15}"
    lines.append(head + "  what changed")
    for c in changes:
        auto = f"{_fmt(c.before)} → {_fmt(c.after)}" if c.before != c.after else f"{_fmt(c.after)} (same)"
        line = f"{c.submission:<{width}}  {auto:<15}"
        if written is not None:
            hand = written.get(c.submission)
            stubs_by_hand = hand_stubs.get(c.submission, {})
            total = ("-" if hand is None or c.after is None or c.before is None else
                     f"{_fmt(c.before + hand + hand_stub_delta(c.before_stubs, stubs_by_hand))} → "
                     f"{_fmt(c.after + hand + hand_stub_delta(c.after_stubs, stubs_by_hand))}")
            line += f"  {_fmt(hand):<23}  {total:<15}"
        what = [f"{s} {_fmt(a)} → {_fmt(b)}" for s, a, b in c.stubs]
        if c.status:
            what.insert(0, f"{c.status[0]} → {c.status[1]}")
        kept = [f"{s} {_fmt(m) if m is not None else 'tests'}" + (f" + {_fmt(x)} extra" if x else "")
                for s, (m, x) in hand_stubs.get(c.submission, {}).items()] if written is not None else []
        text = "; ".join(what) or "nothing"
        if kept:
            text += f" (stub score changed by hand, kept, in the total: {', '.join(kept)})"
        lines.append((line + "  " + text).rstrip())
    changed = sum(c.changed for c in changes)
    lines.append(f"{changed} of {len(changes)} submission(s) changed")
    return lines


def diff_lines(before: dict[str, GradeResult], after: dict[str, GradeResult]) -> list[str]:
    """``results-diff``: the comparison of the submissions in both sets of results, and how many were in one only
    (a ``_previous/<time>`` written when one student handed in again holds that student alone)."""
    both = sorted(set(before) & set(after))
    lines = change_lines(compare(before, after, both))

    def only(names: set[str]) -> str:
        return f"{len(names)} only in the {{}} one" + (f" (not compared: {listed(sorted(names), 10)})" if names else "")

    lines.append(f"compared the {len(both)} submission(s) in both folders; "
                 + only(set(after) - set(before)).format("new") + ", " + only(set(before) - set(after)).format("old"))
    return lines


def archive(out_dir: Path, names: list[str]) -> Path:
    """Copy the named submissions' results and the batch's gradebook into ``out_dir/_previous/<UTC time>/``."""
    return archive_results(out_dir, names, [GRADEBOOK_NAME])


def written_scores(assignment: str, out_dir: Path, course_root: Path | None) -> dict[str, float | None]:
    """Per submission, the written score in the gradebook (hand-given; None where no submission is recorded).
    A submission of several students (a Gradescope group) shows its first student's."""
    from nbgrader.api import MissingEntry

    from autograder.outputs.gradebook import course_directory, open_gradebook

    out = {}
    with open_gradebook(course_directory(course_root)) as gb:
        for name, students in read_students(out_dir).items():
            try:
                submitted = gb.find_submission_notebook(assignment, assignment, students[0])
            except (MissingEntry, IndexError):
                out[name] = None
                continue
            out[name] = sum(g.score for g in submitted.grades if g.cell_type != "code")
    return out


@dataclass
class Regrade:
    archive: Path
    changes: list[Change]
    synced: bool
    written: dict[str, float | None] | None
    grader_errors: list[str] = field(default_factory=list)
    """Submissions the grader failed on in this regrade (no score: run it again)."""
    hand_stubs: dict[str, HandStubs] = field(default_factory=dict)
    """Stub scores a person changed in formgrader, per submission (kept; in the totals)."""
    sync_warnings: list[str] = field(default_factory=list)
    """What the gradebook sync warned about (hand grades of a changed cell, student ids it could not use)."""


def other_suite_versions(assignment: str, before: dict[str, GradeResult], names: list[str]) -> dict[str, str]:
    """Graded results not being regraded whose suite version is not the current one: ``{submission: version}``
    (``"unknown"`` for a result older than versions)."""
    current = course.suite_version(assignment)
    return {n: r.suite_version or "unknown" for n, r in before.items()
            if n not in names and r.status == GRADED and r.suite_version != current}


def regrade(assignment: str, folder: Path, out_dir: Path, only: list[str] | None = None, jobs: int = 2,
            course_root: Path | None = None, progress: bool = True) -> Regrade:
    """Regrade ``out_dir``'s submissions of ``folder`` (or those in ``only``); see the module."""
    from autograder.outputs.gradebook import sync

    course.check_assignment(assignment)
    out_dir = Path(out_dir)
    entries = [e.name for e in discover(folder, assignment, course.stub_names(assignment))]
    names = entries if not only else list(dict.fromkeys(only))
    unknown = [n for n in names if n not in entries]
    if unknown:
        raise SystemExit(f"not a submission of {folder}: {', '.join(unknown)} (submissions: {', '.join(entries)})")
    before = read_results(out_dir) if out_dir.is_dir() else {}
    if only:
        stale = other_suite_versions(assignment, before, names)
        if stale:
            raise SystemExit(
                f"refused, nothing written: {assignment}'s suite changed since {len(stale)} other submission(s) were "
                f"graded ({listed(sorted(stale), 10)}; suite {sorted(set(stale.values()))[0]}, now "
                f"{course.suite_version(assignment)}). "
                f"Regrading only {', '.join(names)} would mix two suites in {out_dir / GRADEBOOK_NAME} and the "
                f"gradebook. Regrade them all: python -m autograder regrade {assignment} {folder} --out {out_dir}")
    kept = archive(out_dir, [n for n in names if n in before])
    for name in names:
        (out_dir / name / RESULT_NAME).unlink(missing_ok=True)
    grade_folder(assignment, folder, out_dir, jobs=jobs, progress=progress)
    after = read_results(out_dir)
    changes = compare(before, after, names)
    synced = bool(read_students(out_dir))
    written, hand_stubs, warned = None, {}, []
    if synced:
        warned = sync(assignment, folder, out_dir, course_root).warnings()
        written = written_scores(assignment, out_dir, course_root)
        hand_stubs = hand_stub_scores(assignment, out_dir, course_root)
    errors = [n for n in names if n in after and after[n].status == GRADER_ERROR]
    return Regrade(kept, changes, synced, written, errors, hand_stubs, warned)
