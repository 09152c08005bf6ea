"""Each notebook's stated running time is the one measured in bench/results/notebook_budgets.json.

``bench/bench_notebook_budgets.py`` times the solution notebooks and writes, in each, a Markdown cell
tagged ``measured-budget`` right after the parameters cell, and in every code cell that ran for
``LONG_CELL`` seconds or more two first comment lines with that cell's own time; ``make assignments``
carries both to the student notebook. A re-measurement that is not written back, or a hand edit of
either, fails here. hw2b, hw7 and hw7b state the budgets their own benchmarks measure (OWNED_ELSEWHERE).
"""
from __future__ import annotations

import json

import nbformat
import pytest

from autograder.core import course
from bench.bench_notebook_budgets import (CELL_LINE, LONG_CELL, OWNED_ELSEWHERE, RESULTS, TAG, budget_sentence,
                                          cell_line, with_cell_line)

IDS = [i for i in course.assignment_ids() if i not in OWNED_ELSEWHERE]


def _cells(path) -> tuple[int, list]:
    nb = nbformat.read(path, as_version=4)
    params = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
    return params, [(i, c) for i, c in enumerate(nb.cells) if TAG in c.metadata.get("tags", [])]


@pytest.mark.parametrize("assignment", IDS)
def test_the_notebook_states_its_measured_running_time(assignment):
    results = json.loads(RESULTS.read_text())["notebooks"]
    if assignment not in results:  # a new assignment (python -m autograder new): it may not claim a measured time
        for path in (course.solution_notebook(assignment), course.release_notebook(assignment)):
            _, stated = _cells(path)
            assert all(cell.source == budget_sentence({}) for _, cell in stated), \
                f"{path} states a running time, but {RESULTS.name} has no entry: run bench/bench_notebook_budgets.py"
        return
    expected = budget_sentence(results[assignment])
    for path in (course.solution_notebook(assignment), course.release_notebook(assignment)):
        params, stated = _cells(path)
        assert len(stated) == 1, f"{path}: expected one cell tagged {TAG}, found {len(stated)}"
        index, cell = stated[0]
        assert index == params + 1, f"{path}: the {TAG} cell should follow the parameters cell"
        assert cell.source == expected, (f"{path} states a running time that is not the results file's: "
                                         "run bench/bench_notebook_budgets.py --write-notebooks, then make assignments")


def test_the_sentence_says_what_was_measured_and_what_was_not():
    run = {"seconds": 87.4, "meta": {"load": [3.24, 2.0, 1.0], "commit": "abc1234", "date": "2026-12-04"}}
    text = budget_sentence({"fast": run})
    assert "full budget: not measured yet" in text
    assert "with `FAST = True`: 87 s (load 3.2, commit `abc1234`, 2026-12-04)" in text


def _stated_lines(path) -> list[str]:
    return [c.source.split("\n", 2)[:2] for c in nbformat.read(path, as_version=4).cells
            if c.cell_type == "code" and c.source.startswith(CELL_LINE)]


@pytest.mark.parametrize("assignment", IDS)
def test_every_long_cell_states_its_own_measured_time(assignment):
    entry = json.loads(RESULTS.read_text())["notebooks"].get(assignment, {})
    solution = nbformat.read(course.solution_notebook(assignment), as_version=4)
    for cell in solution.cells:
        if cell.cell_type != "code":
            continue
        expected = cell_line(entry, cell.get("id", ""))
        stated = "\n".join(cell.source.split("\n", 2)[:2]) if cell.source.startswith(CELL_LINE) else None
        assert stated == expected, (f"{assignment}, code cell {cell.get('id')}: states {stated!r}, the results file "
                                    f"says {expected!r}: run bench/bench_notebook_budgets.py --write-notebooks")
    release = course.release_notebook(assignment)
    assert _stated_lines(release) == _stated_lines(course.solution_notebook(assignment)), \
        f"{release} does not carry the solution's running-time lines: make assignments"


def test_a_long_cell_gets_two_lines_and_loses_them_when_it_is_no_longer_long():
    def run(cells, load=1.04):
        return {"seconds": 1, "cell_seconds": cells, "meta": {"load": [load, 0, 0]}}

    entry = {"full": run({"a": 412.0, "b": LONG_CELL - 0.5, "c": 42.4}), "fast": run({"a": 12.6})}
    assert cell_line(entry, "a") == (f"{CELL_LINE}: about 7 min at the full budget, about 13 s with FAST = True\n"
                                     "# (measured at load 1.0 on the course's 2-core machine, "
                                     "bench/results/notebook_budgets.json)")
    assert "about 42 s at the full budget, under a second with FAST" in cell_line(entry, "c")
    assert cell_line(entry, "b") is None and cell_line(entry, "missing") is None
    assert cell_line({"full": entry["full"]}, "a") is None, "both budgets must be measured per cell"
    source = "x = train()\nplot(x)"
    once = with_cell_line(source, cell_line(entry, "a"))
    assert once.endswith("\n" + source) and with_cell_line(once, cell_line(entry, "a")) == once
    assert with_cell_line(once, None) == source
    assert with_cell_line(with_cell_line(once, cell_line(entry, "c")), None) == source
