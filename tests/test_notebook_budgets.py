"""Each notebook's stated running time is the one measured in bench/results/notebook_budgets.json.

``bench/bench_notebook_budgets.py`` times the solution notebooks and writes, in each, a Markdown cell
tagged ``measured-budget`` right after the parameters cell; ``make assignments`` carries it to the
student notebook. A re-measurement that is not written back, or a hand edit of the sentence, fails
here. hw2b, hw7 and hw7b state the budgets their own benchmarks measure (OWNED_ELSEWHERE).
"""
from __future__ import annotations

import json

import nbformat
import pytest

from autograder.core import course
from bench.bench_notebook_budgets import OWNED_ELSEWHERE, RESULTS, TAG, budget_sentence

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
