"""How long each solution notebook takes, at its full budget and with ``FAST = True``, and the sentence
each notebook states about it, written from the results file.

    python bench/bench_notebook_budgets.py [ID ...] [--fast] [--full] [--record]
    python bench/bench_notebook_budgets.py --write-notebooks

Each run executes ``solutions/<id>/<id>.ipynb`` top to bottom in a fresh kernel (the course's
notebook runner, ``autograder.authoring.nbrun``) and times it; the load average before and after is
recorded beside the time, since a figure from the shared 2-core machine means nothing without it.
``--record`` merges the runs into ``bench/results/notebook_budgets.json`` (one entry per notebook and
budget, each with its own commit, date and load), so a notebook can be re-measured alone.

``--write-notebooks`` rewrites, in each solution notebook, the Markdown cell tagged
``measured-budget`` (right after the parameters cell) from that file, and the first line of every
code cell that ran for ``LONG_CELL`` seconds or more at the full budget (a comment the student reads
before running it: that cell's own time at both budgets); ``make assignments`` carries both to the
student notebooks, and ``tests/test_notebook_budgets.py`` fails when a notebook's sentence or a long
cell's line differs from what the results file says. Nothing in them is typed by hand.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

RESULTS = REPO / "bench" / "results" / "notebook_budgets.json"
TAG = "measured-budget"
OWNED_ELSEWHERE = {"hw2b_adversarial", "hw7_verifier_rl", "hw7b_ai_feedback"}
"""Notebooks whose budgets their own benchmarks measure and state (bench_hw2b/hw7/hw7b): no generated cell."""


LONG_CELL = 10.0
"""Seconds at the full budget from which a code cell states its own running time in its first line."""
CELL_LINE = "# Measured running time of this cell"
CELL_LINE_SOURCE = "# (measured at load"
"""How the two generated lines start: they are rewritten or removed, never kept stale."""


def _load(values) -> str:
    return f"{values[0]:.1f}"


def budget_sentence(entry: dict) -> str:
    """The Markdown a notebook shows about its own running time, from its entry in the results file."""
    def part(budget: str, label: str) -> str:
        run = entry.get(budget)
        if not run:
            return f"{label}: not measured yet"
        return (f"{label}: {run['seconds']:.0f} s (load {_load(run['meta']['load'])}, "
                f"commit `{run['meta']['commit']}`, {run['meta']['date']})")

    return ("**Measured running time** (written by `bench/bench_notebook_budgets.py` from "
            "`bench/results/notebook_budgets.json`; on the course's 2-core machine, the load is its 1-minute "
            "load average, and at load 2 or more expect the run to take longer than on an idle laptop). "
            f"The whole notebook, {part('full', 'full budget')}; {part('fast', 'with `FAST = True`')}.")


def _about(seconds: float | None) -> str:
    if seconds is None:
        return "under a second"
    if seconds < 60:
        return f"about {max(1, round(seconds))} s"
    minutes = round(seconds / 30) / 2
    return f"about {minutes:g} min"


def cell_line(entry: dict, cell_id: str) -> str | None:
    """The first lines a code cell shows about its own running time, or None for a cell under ``LONG_CELL``
    at the full budget (or a notebook whose two budgets are not both measured with per-cell times)."""
    full, fast = entry.get("full") or {}, entry.get("fast") or {}
    if "cell_seconds" not in full or "cell_seconds" not in fast:
        return None
    seconds = full["cell_seconds"].get(cell_id)
    if seconds is None or seconds < LONG_CELL:
        return None
    return (f"{CELL_LINE}: {_about(seconds)} at the full budget, {_about(fast['cell_seconds'].get(cell_id))} "
            f"with FAST = True\n{CELL_LINE_SOURCE} {_load(full['meta']['load'])} on the course's 2-core machine, "
            "bench/results/notebook_budgets.json)")


def with_cell_line(source: str, line: str | None) -> str:
    """``source`` with its generated first lines replaced by ``line`` (added, or removed when None)."""
    for prefix in (CELL_LINE, CELL_LINE_SOURCE):
        if source.startswith(prefix):
            source = source.partition("\n")[2]
    return source if line is None else f"{line}\n{source}"


def measure(assignment: str, fast: bool) -> dict:
    from autograder.authoring.nbrun import run_notebook

    notebook = REPO / "solutions" / assignment / f"{assignment}.ipynb"
    with tempfile.TemporaryDirectory() as folder:
        before = os.getloadavg()
        start = time.perf_counter()
        report = run_notebook(notebook, {"FAST": True} if fast else {}, timeout=3600, cwd=folder)
        seconds = time.perf_counter() - start
    record = meta([f"solutions/{assignment}", "rlcourse"])
    record["load"] = [round(max(a, b), 2) for a, b in zip(before, os.getloadavg())]  # the busier of start and end
    return {"seconds": round(seconds, 1), "ok": report.ok, "cells": report.cells_run,
            "cell_seconds": {cell: t for cell, t in report.cell_seconds.items() if t >= 1.0},
            "error": None if report.ok else report.describe(assignment), "meta": record}


def write_notebooks(results: dict) -> list[Path]:
    """Rewrite each solution notebook's ``measured-budget`` cell (inserted after the parameters cell if missing)."""
    import nbformat

    written = []
    for assignment, entry in sorted(results.get("notebooks", {}).items()):
        if assignment in OWNED_ELSEWHERE:
            continue
        path = REPO / "solutions" / assignment / f"{assignment}.ipynb"
        nb = nbformat.read(path, as_version=4)
        text = budget_sentence(entry)
        cell = next((c for c in nb.cells if TAG in c.metadata.get("tags", [])), None)
        changed = cell is None or cell.source != text
        if cell is None:
            params = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
            cell = nbformat.v4.new_markdown_cell(text, metadata={"tags": [TAG]})
            nb.cells.insert(params + 1, cell)
        cell.source = text
        for code in nb.cells:
            if code.cell_type == "code" and code.get("id"):
                source = with_cell_line(code.source, cell_line(entry, code.id))
                changed |= source != code.source
                code.source = source
        if changed:
            nbformat.write(nb, path)
            written.append(path)
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", help="assignments (default: every one not measured elsewhere)")
    parser.add_argument("--fast", action="store_true", help="run with FAST = True")
    parser.add_argument("--full", action="store_true", help="run at the full budget")
    parser.add_argument("--record", action="store_true", help=f"merge into {RESULTS.relative_to(REPO)}")
    parser.add_argument("--write-notebooks", action="store_true", help="rewrite the solution notebooks' sentences")
    args = parser.parse_args()
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {"notebooks": {}}
    if args.fast or args.full:
        from autograder.core import course

        ids = args.ids or [i for i in course.assignment_ids() if i not in OWNED_ELSEWHERE]
        budgets = (["fast"] if args.fast else []) + (["full"] if args.full else [])
        for assignment in ids:
            for budget in budgets:
                run = measure(assignment, fast=budget == "fast")
                print(f"{assignment} {budget}: {run['seconds']} s, load {run['meta']['load']}"
                      + ("" if run["ok"] else f"\n  {run['error']}"), flush=True)
                if args.record and run["ok"]:
                    results["notebooks"].setdefault(assignment, {})[budget] = run
                    results["meta"] = run["meta"]
                    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    if args.write_notebooks:
        for path in write_notebooks(results):
            print(f"wrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
