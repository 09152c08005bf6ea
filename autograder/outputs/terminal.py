"""What a person at a terminal sees of a grading: a per-stub summary and a progress bar."""
from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

from tqdm import tqdm

from autograder.core.results import GradeResult
from autograder.outputs.text import MESSAGE_CHARS, NAME_CHARS, TERMINAL_MESSAGE_CHARS, cap, one_line, points

T = TypeVar("T")
LOG_INTERVAL = 10.0
"""Seconds between two updates of the bar when nobody watches (a log file, CI): few lines, still alive."""


def progress_bar(items: Iterable[T], total: int, desc: str) -> Iterator[T]:
    """``items`` with tqdm's bar on stderr; updated at most every :data:`LOG_INTERVAL` s in a log."""
    watched = sys.stderr.isatty()
    return iter(tqdm(items, total=total, desc=desc, leave=watched, mininterval=0.1 if watched else LOG_INTERVAL,
                     file=sys.stderr, dynamic_ncols=watched, ascii=not watched))


def summary_lines(result: GradeResult) -> list[str]:
    """A short per-stub table for the terminal."""
    name = one_line(cap(result.submission, NAME_CHARS))
    if not result.has_score:
        return [f"{result.assignment} · {name}: NOT GRADED: the grader failed, no score was given",
                f"  {one_line(cap(result.error or '', MESSAGE_CHARS))}"]
    width = max([len(s.name) for s in result.stubs] + [4])
    lines = [f"{result.assignment} · {name}: {points(result.score)}/{points(result.max_score)}"
             + (f"  (ungradable: {one_line(cap(result.error, TERMINAL_MESSAGE_CHARS))})" if result.error else "")]
    if result.wrong_notebook:
        lines.append(f"  {one_line(result.wrong_notebook)}")
    for stub in result.stubs:
        failed = [t for t in stub.tests if not t.passed]
        why = f"  {one_line(failed[0].message)[:TERMINAL_MESSAGE_CHARS]}" if failed else ""
        lines.append(f"  {stub.name:<{width}}  {points(stub.score):>4}/{points(stub.max_score):<4}{why}")
    return lines
