"""Every solution notebook runs end to end in fast mode, with no warning shown in its outputs; every student
notebook runs up to its first stub, with none either."""
from __future__ import annotations

import re

import nbformat
import pytest

from autograder.core import course
from autograder.authoring.nbrun import run_notebook

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

IDS = course.assignment_ids()


# How Python's warnings module shows a warning: "file:line: SomeWarning: message" (warnings.formatwarning).
WARNING = re.compile(r":\d+: (?:\w+\.)*\w*Warning: ")


def warning_blocks(path) -> list[str]:
    """The stderr outputs of an executed notebook that hold a Python warning (a pink block in JupyterLab)."""
    nb = nbformat.read(str(path), as_version=4)
    return [f"code cell {i}: {out['text'].strip()[:500]}" for i, cell in enumerate(nb.cells) if cell.cell_type == "code"
            for out in cell.get("outputs", [])
            if out.get("output_type") == "stream" and out.get("name") == "stderr" and WARNING.search(out.get("text", ""))]


def test_warning_blocks_finds_a_warning_and_nothing_else(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell(outputs=[nbformat.v4.new_output(
            "stream", name="stderr", text="/x/mujoco_env.py:12: DeprecationWarning: `settotalmass` is deprecated\n")]),
        nbformat.v4.new_code_cell(outputs=[nbformat.v4.new_output("stream", name="stderr", text="epoch 3/10\n"),
                                           nbformat.v4.new_output("stream", name="stdout", text="a.py:1: UserWarning: x\n")])])
    nbformat.write(nb, tmp_path / "nb.ipynb")
    assert warning_blocks(tmp_path / "nb.ipynb") == [
        "code cell 0: /x/mujoco_env.py:12: DeprecationWarning: `settotalmass` is deprecated"]


@pytest.mark.parametrize("assignment", IDS)
def test_solution_runs_in_fast_mode(assignment, tmp_path):
    report = run_notebook(course.solution_notebook(assignment), {"FAST": True}, timeout=300, cwd=tmp_path,
                          output=tmp_path / "executed.ipynb")
    assert report.ok, report.describe(assignment)
    assert warning_blocks(tmp_path / "executed.ipynb") == [], f"{assignment} shows a warning at FAST"


@pytest.mark.parametrize("assignment", IDS)
def test_student_notebook_setup_runs(assignment, tmp_path):
    report = run_notebook(course.release_notebook(assignment), {"FAST": True}, timeout=300, cwd=tmp_path,
                          until_first_stub=True, output=tmp_path / "executed.ipynb")
    assert report.ok, report.describe(assignment)
    assert warning_blocks(tmp_path / "executed.ipynb") == [], f"{assignment} shows a warning before its first stub"
