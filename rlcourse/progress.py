"""Progress of a long loop: a live bar when a person watches, a few plain lines when a log does.

``for t in progress(range(1000), desc="rollout"):`` shows a tqdm bar when the stream (stderr by
default) is a terminal, or a notebook widget inside Jupyter. Anywhere else (a log file, CI, a
captured subprocess) a bar's carriage-return updates would pile up as hundreds of lines, so the loop
instead writes one plain line every ``interval`` seconds and a last line when it ends; a loop that
ends before the first interval writes nothing.
"""
from __future__ import annotations

import importlib.util
import sys
import time
from typing import Iterable, Iterator, Optional, TextIO, TypeVar

from tqdm import tqdm

T = TypeVar("T")

LOG_INTERVAL = 5.0
"""Seconds between two plain lines in a log: often enough to see a run is alive, rare enough to read."""

_clock = time.monotonic  # the log mode's clock (tests replace it)


def progress(iterable: Iterable[T], desc: str = "", total: Optional[int] = None, *, disable: bool = False,
             interval: float = LOG_INTERVAL, stream: Optional[TextIO] = None) -> Iterator[T]:
    """The items of ``iterable``, reporting progress on ``stream`` (default ``sys.stderr``).

    ``total`` defaults to ``len(iterable)`` where there is one. ``disable=True`` reports nothing.
    """
    if disable:
        return iter(iterable)
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    watched = _watched_by(stream)
    if watched == "notebook":
        from tqdm.notebook import tqdm as notebook_tqdm

        return iter(notebook_tqdm(iterable, desc=desc, total=total, leave=False))
    out = sys.stderr if stream is None else stream
    if watched == "terminal":
        return iter(tqdm(iterable, desc=desc, total=total, leave=False, file=out))
    return _log_lines(iterable, desc, total, interval, out)


def _watched_by(stream: Optional[TextIO]) -> Optional[str]:
    """``"terminal"`` or ``"notebook"`` when a person watches ``stream`` (``None``: stderr), else ``None``."""
    out = sys.stderr if stream is None else stream
    try:
        if out.isatty():
            return "terminal"
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return None
    if stream is None and _in_jupyter_kernel():
        return "notebook"
    return None


def _in_jupyter_kernel() -> bool:
    """Whether this process is a Jupyter kernel that can draw tqdm's widget (ipywidgets installed)."""
    shell = getattr(sys.modules.get("IPython"), "get_ipython", lambda: None)()
    return type(shell).__name__ == "ZMQInteractiveShell" and importlib.util.find_spec("ipywidgets") is not None


def _log_lines(iterable: Iterable[T], desc: str, total: Optional[int], interval: float,
               out: TextIO) -> Iterator[T]:
    """Yield the items, writing a status line at most every ``interval`` seconds, and a final one if any was."""
    start = last = _clock()
    done, wrote = 0, False
    try:
        for item in iterable:
            done += 1  # counted when handed out, so a loop that breaks on its last item reads as finished
            yield item
            now = _clock()
            if now - last >= interval:
                print(_status(desc, done, total, now - start), file=out, flush=True)
                last, wrote = now, True
    finally:
        if wrote:
            print(_status(desc, done, total, _clock() - start, finished=True), file=out, flush=True)


def _status(desc: str, done: int, total: Optional[int], seconds: float, finished: bool = False) -> str:
    """One line such as ``rollout Hopper-v5: 412/1000 (41%) after 5 s, 82.4/s``."""
    count = f"{done}/{total} ({done / total:.0%})" if total else f"{done}"
    rate = f"{done / seconds:.3g}/s" if seconds > 0 else "-"
    stopped = finished and total is not None and done < total
    when = f"{'stopped after' if stopped else 'finished in'} {seconds:.0f} s" if finished else f"after {seconds:.0f} s"
    return f"{desc + ': ' if desc else ''}{count} {when}, {rate}"
