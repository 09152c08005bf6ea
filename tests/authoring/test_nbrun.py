"""The notebook runner: parameters are injected, failures name the cell and line, budgets hold."""
from __future__ import annotations

import pytest

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from autograder.authoring.nbrun import inject_parameters, run_notebook

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it


def notebook(tmp_path, *sources, name="nb.ipynb"):
    cells = [new_markdown_cell("# t")]
    for source in sources:
        tags = ["parameters"] if source.startswith("FAST") else []
        cells.append(new_code_cell(source, metadata={"tags": tags}))
    path = tmp_path / name
    nbformat.write(new_notebook(cells=cells), str(path))
    return path


def test_parameters_are_injected_after_the_parameters_cell(tmp_path):
    path = notebook(tmp_path, "FAST = False", "assert FAST is True, 'not injected'")
    assert run_notebook(path, {"FAST": True}, timeout=120).ok
    assert not run_notebook(path, {}, timeout=120).ok
    nb = nbformat.read(str(path), as_version=4)
    inject_parameters(nb, {"FAST": True, "N": 3})
    assert nb.cells[2].metadata["tags"] == ["injected-parameters"] and "N = 3" in nb.cells[2].source


def test_a_failure_names_the_cell_the_line_and_the_error(tmp_path):
    path = notebook(tmp_path, "x = 1", "y = 2\nz = x / 0\nw = 3")
    report = run_notebook(path, timeout=120)
    assert not report.ok and report.failed_cell == 2
    assert report.failed_source_line == "line 2: z = x / 0"
    assert report.error.startswith("ZeroDivisionError")
    assert "code cell 2" in report.describe(path)


def test_the_failing_cell_is_counted_as_the_student_counts_and_named(tmp_path):
    """The injected parameters cell is not counted; a graded cell is named by its grade_id."""
    path = notebook(tmp_path, "FAST = False", "x = 1", "raise ValueError('boom')")
    nb = nbformat.read(str(path), as_version=4)
    nb.cells[3].metadata["nbgrader"] = {"grade_id": "my_stub", "solution": True}
    nbformat.write(nb, str(path))
    report = run_notebook(path, {"FAST": True}, timeout=120)
    assert report.failed_cell == 3 and report.failed_label == "my_stub"
    assert "code cell 3 (`my_stub`)" in report.describe(path)


def test_the_time_budget_covers_the_whole_notebook(tmp_path):
    path = notebook(tmp_path, "import time\ntime.sleep(2)", "time.sleep(2)", "time.sleep(2)")
    report = run_notebook(path, timeout=5)
    assert not report.ok and "budget" in report.error and report.failed_cell in (2, 3)


def test_until_first_stub_stops_before_the_first_solution_cell(tmp_path):
    path = notebook(tmp_path, "a = 1", "raise RuntimeError('stub')")
    nb = nbformat.read(str(path), as_version=4)
    nb.cells[2].metadata["nbgrader"] = {"solution": True, "grade_id": "f"}
    nbformat.write(nb, str(path))
    report = run_notebook(path, timeout=120, until_first_stub=True)
    assert report.ok and report.cells_run == 1
