"""Damaged and odd submissions: a clear message and the best honest score, never a traceback."""
from __future__ import annotations

import json

import nbformat
import pytest

from conftest import FIXTURE_COURSE, with_cells

SOLUTION = FIXTURE_COURSE / "solutions/fx/fx.ipynb"
RELEASE = FIXTURE_COURSE / "assignments/fx/fx.ipynb"


def solved_copy(tmp_path, name="solved.ipynb"):
    """The student notebook with every stub done (solution text, no markers)."""
    sol = nbformat.read(str(SOLUTION), as_version=4)
    code = {c.metadata["nbgrader"]["grade_id"]: "\n".join(l for l in c.source.splitlines() if "SOLUTION" not in l)
            for c in sol.cells if c.cell_type == "code" and c.metadata.get("nbgrader", {}).get("solution")}
    return with_cells(RELEASE, tmp_path / name, code)


@pytest.mark.parametrize("content, message", [
    (b"", "empty"),
    (b"this is not json", "not valid JSON"),
    (b'{"cells": [], "nbformat": 4, "nbformat_minor": 5, "metadata": {}}', "no cells"),
    (b'{"cells": [], "nbformat": 2, "metadata": {}}', "format version"),
    (b'[1, 2, 3]', "not a Jupyter notebook"),
    (b'{"cells": 5, "nbformat": 4, "nbformat_minor": 5, "metadata": {}}', "damaged"),
])
def test_unreadable_files_are_ungradable_with_a_reason(fx_grader, tmp_path, content, message):
    path = tmp_path / "bad.ipynb"
    path.write_bytes(content)
    result = fx_grader.grade(path)
    assert result.error and message in result.error
    assert result.score == 0 and result.max_score == 7  # every test is listed, at zero


def test_a_huge_notebook_is_refused_before_parsing(fx_grader, tmp_path):
    path = tmp_path / "huge.ipynb"
    with path.open("w") as f:
        f.write('{"cells": [{"cell_type": "markdown", "metadata": {}, "source": "')
        for _ in range(200):
            f.write("x" * 1024 * 1024)
        f.write('"}], "nbformat": 4, "nbformat_minor": 5, "metadata": {}}')
    result = fx_grader.grade(path)
    assert "MB" in result.error and "limit" in result.error


def test_stripped_metadata_and_reordered_cells_still_grade_fully(fx_grader, tmp_path):
    nb = nbformat.read(str(solved_copy(tmp_path)), as_version=4)
    for cell in nb.cells:
        cell.metadata = {}
    nb.cells.reverse()
    path = tmp_path / "stripped.ipynb"
    nbformat.write(nb, str(path))
    result = fx_grader.grade(path)
    assert result.score == 7
    assert any("found by the name" in note for note in result.notes)


def test_renamed_grade_ids_fall_back_to_the_defined_name(fx_grader, tmp_path):
    nb = nbformat.read(str(solved_copy(tmp_path)), as_version=4)
    for cell in nb.cells:
        if "nbgrader" in cell.metadata:
            cell.metadata["nbgrader"]["grade_id"] = "cell-" + str(id(cell))
    path = tmp_path / "renamed.ipynb"
    nbformat.write(nb, str(path))
    assert fx_grader.grade(path).score == 7


def test_deleted_cells_cost_only_their_stub(fx_grader, tmp_path):
    path = with_cells(solved_copy(tmp_path), tmp_path / "deleted.ipynb", {"Counter": None})
    result = fx_grader.grade(path)
    by_stub = {s.name: s for s in result.stubs}
    assert result.score == 5 and by_stub["Counter"].score == 0
    assert "no cell defines `Counter`" in by_stub["Counter"].tests[0].message


def test_non_utf8_is_read_with_a_note(fx_grader, tmp_path):
    path = solved_copy(tmp_path)
    raw = json.loads(path.read_text())
    raw["cells"][0]["source"] = "# café"
    path.write_bytes(json.dumps(raw, ensure_ascii=False).encode("latin-1"))
    result = fx_grader.grade(path)
    assert result.score == 7 and any("UTF-8" in note for note in result.notes)


def test_old_format_3_notebooks_are_converted(fx_grader, tmp_path):
    nb3 = {"nbformat": 3, "nbformat_minor": 0, "metadata": {}, "worksheets": [{"cells": [
        {"cell_type": "code", "input": "def mean_of(values):\n    return float(sum(values) / len(values))",
         "language": "python", "outputs": [], "metadata": {}}]}]}
    path = tmp_path / "v3.ipynb"
    path.write_text(json.dumps(nb3))
    result = fx_grader.grade(path)
    assert {s.name: s.score for s in result.stubs}["mean_of"] == 1
    assert any("format 3" in note for note in result.notes)


def test_an_answer_in_a_new_cell_below_the_untouched_stub_is_the_answer(fx_grader, tmp_path):
    """Students often leave the stub cell as released and write the function again in a cell below; the
    notebook, run top to bottom, uses the later one, so the grader does too, and says where it took it from.
    A definition *above* the untouched stub is not the answer: running the notebook, the stub replaces it."""
    solved = nbformat.read(str(solved_copy(tmp_path)), as_version=4)
    answer = next(c.source for c in solved.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == "mean_of")
    release = nbformat.read(str(RELEASE), as_version=4)
    stub_at = next(i for i, c in enumerate(release.cells)
                   if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == "mean_of")

    def graded(position: int) -> dict:
        nb = nbformat.read(str(RELEASE), as_version=4)
        nb.cells.insert(position, nbformat.v4.new_code_cell(answer))
        path = tmp_path / f"answer_at_{position}.ipynb"
        nbformat.write(nb, str(path))
        result = fx_grader.grade(path)
        return {"stub": {s.name: s for s in result.stubs}["mean_of"], "notes": result.notes}

    below = graded(stub_at + 1)
    assert below["stub"].score == below["stub"].max_score > 0
    assert any("below its own stub cell" in note for note in below["notes"]), below["notes"]
    above = graded(stub_at)
    assert above["stub"].score == 0 and not any("below its own stub cell" in n for n in above["notes"])


def test_a_cell_below_a_finished_stub_never_replaces_it(fx_grader, tmp_path):
    """Red team C: a debugging wrapper, an unfinished rewrite with a syntax error or a magic, or a rewrite that
    needs later cells, written below a finished stub, cost the stub its points. The finished stub is the answer;
    below an untouched stub, a cell that does not parse is not one either."""
    solved = nbformat.read(str(solved_copy(tmp_path)), as_version=4)
    stub_at = next(i for i, c in enumerate(solved.cells)
                   if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == "mean_of")
    release = nbformat.read(str(RELEASE), as_version=4)
    answer = solved.cells[stub_at].source

    def score(nb, below: str, name: str) -> float:
        nb = nbformat.from_dict(nb)
        nb.cells.insert(stub_at + 1, nbformat.v4.new_code_cell(below))
        path = tmp_path / f"{name}.ipynb"
        nbformat.write(nb, str(path))
        return {s.name: s.score for s in fx_grader.grade(path).stubs}["mean_of"]

    full = score(solved, "x = 1", "plain")
    assert full > 0
    wrapper = "_first = mean_of\ndef mean_of(values):\n    print(values)\n    return _first(values)"
    rewrite = "def mean_of(values):\n    return total / count   # total and count come from a later cell"
    broken = "def mean_of(values)\n    return sum(values) / len(values)"
    magic = "%%time\ndef mean_of(values):\n    return 0.0"
    for name, below in (("wrapper", wrapper), ("rewrite", rewrite), ("broken", broken), ("magic", magic)):
        assert score(solved, below, name) == full, name
    assert score(release, broken, "broken_below_untouched") == 0
    assert score(release, magic, "magic_below_untouched") == 0
    assert score(release, answer, "answer_below_untouched") == full


def test_a_cell_over_the_cell_cap_is_not_parsed_whole_by_the_outputs():
    """Red team C: nbgrader-sync parsed every code cell of a notebook, a 12 MB one included (19 s, 4.3 GB). Cells
    over MAX_CELL_BYTES are read for names only up to the cap and marked unrunnable, as grading reads them."""
    from autograder.core.intake import MAX_CELL_BYTES
    from autograder.core.notebook import code_cells, find_stubs

    huge = "def mean_of(values):\n    return 0.0\n" + "x = [" + "1, " * (MAX_CELL_BYTES // 2) + "]\n"
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(huge)])
    (cell,) = code_cells(nb)
    assert cell.defines == ["mean_of"] and "MB of code" in cell.problem
    assert find_stubs(nb, ["mean_of"])[0]["mean_of"].problem == cell.problem
