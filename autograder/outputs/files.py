"""The files a grading leaves for people: per submission ``results.json`` (Gradescope's format) and
``feedback.md``, and a batch's ``gradebook.csv``.

The core grades and keeps the record (:mod:`autograder.core.store`); it hands each result to
:func:`render_files`, which this room owns. :func:`grade_folder` is the batch as the instructor's
commands run it: the core's :func:`~autograder.core.batch.run_batch` with these writers and a bar.
"""
from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Iterable, Sequence

from autograder.core.batch import Batch, Shard, assignment_folder, run_batch, run_batches
from autograder.core.results import GradeResult
from autograder.core.store import atomic_write, save_result
from autograder.outputs.feedback import FEEDBACK_NAME, feedback_markdown
from autograder.outputs.gradescope import GRADESCOPE_NAME, gradescope_results
from autograder.outputs.terminal import progress_bar
from autograder.outputs.text import NOTE_CHARS, cap, csv_cell, points


def render_files(result: GradeResult, folder: Path) -> None:
    """``results.json`` (Gradescope) and ``feedback.md`` into ``folder``; a grader error removes any left
    from before, since it carries no score to show."""
    folder = Path(folder)
    if not result.has_score:
        for name in (GRADESCOPE_NAME, FEEDBACK_NAME):
            (folder / name).unlink(missing_ok=True)
        return
    atomic_write(folder / GRADESCOPE_NAME, json.dumps(gradescope_results(result), indent=2, ensure_ascii=False))
    atomic_write(folder / FEEDBACK_NAME, feedback_markdown(result))


def write_outputs(result: GradeResult, folder: Path) -> None:
    """:func:`render_files`, then the record (``result.json``), last: its presence marks the submission done."""
    render_files(result, folder)
    save_result(result, folder)


def write_gradebook(results: Iterable[GradeResult], path: Path, stubs: list[str] = ()) -> None:
    """The CSV gradebook: one row per submission, ungradable ones included with their reason, and grader
    errors with empty score cells (never a zero: the student was not graded). A graded notebook that defines none
    of the assignment's stubs has its zeros and, as its reason, what it seems to be (another assignment's, say)."""
    results = list(results)
    stubs = list(dict.fromkeys([*stubs, *(s.name for r in results for s in r.stubs)]))
    # A submission found ungradable before any test ran has no stubs: it is out of the assignment's points all the
    # same (those of the graded results; left empty when the batch graded none).
    full = max((r.max_score for r in results if r.stubs), default=None)
    rows = [["submission", "score", "max_score", "percent", *stubs, "status", "reason"]]
    for r in sorted(results, key=lambda r: r.submission):
        reason = csv_cell(cap(r.error or r.wrong_notebook or "", NOTE_CHARS))
        if not r.has_score:
            rows.append([csv_cell(r.submission), "", "", "", *[""] * len(stubs), r.status, reason])
            continue
        per = {s.name: s.score for s in r.stubs}
        max_score = r.max_score if r.stubs else full
        percent = 100 * r.score / max_score if max_score else 0.0
        rows.append([csv_cell(r.submission), points(r.score), "" if max_score is None else points(max_score),
                     f"{percent:.1f}", *[points(per.get(s, 0)) for s in stubs], r.status, reason])
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    path.parent.mkdir(parents=True, exist_ok=True)
    with tmp.open("w", newline="", encoding="utf-8", errors="replace") as f:
        csv.writer(f).writerows(rows)
    os.replace(tmp, path)


def grade_folder(assignment: str | Sequence[str], folder: Path, out_dir: Path, jobs: int = 2, progress: bool = True,
                 shard: Shard = Shard()) -> list[GradeResult] | dict[str, list[GradeResult]]:
    """Grade every submission of ``folder`` (of ``shard``) not yet graded in ``out_dir``, write each one's files
    and then the gradebook of them all (``gradebook.csv``, or ``gradebook-K-of-N.csv`` for a shard).

    ``assignment`` may be a list of several: they are graded in one pool of processes, which pays the
    grader's start-up (its imports) once rather than once per assignment; each one's submissions are in
    ``folder`` (nbgrader's layout) or ``folder/<id>/``, and its results and gradebook go to ``out_dir/<id>/``.
    The results are then by assignment."""
    from autograder.core import course

    bar = progress_bar if progress else None
    if isinstance(assignment, str):
        results = run_batch(assignment, folder, out_dir, write=render_files, jobs=jobs, progress=bar, shard=shard)
        write_gradebook(results, Path(out_dir) / shard.gradebook_name, course.stub_names(assignment))
        return results
    batches = [Batch(a, assignment_folder(folder, a), Path(out_dir) / a, shard) for a in assignment]
    by_assignment = run_batches(batches, write=render_files, jobs=jobs, progress=bar)
    for batch in batches:
        write_gradebook(by_assignment[batch.assignment], batch.out_dir / shard.gradebook_name,
                        course.stub_names(batch.assignment))
    return by_assignment
