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
``measured-budget`` (right after the parameters cell) from that file; ``make assignments`` carries it
to the student notebooks, and ``tests/test_notebook_budgets.py`` fails when a notebook's sentence
differs from what the results file says. Nothing in that cell is typed by hand.
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
        if cell is None:
            params = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
            cell = nbformat.v4.new_markdown_cell(text, metadata={"tags": [TAG]})
            nb.cells.insert(params + 1, cell)
        elif cell.source == text:
            continue
        cell.source = text
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
