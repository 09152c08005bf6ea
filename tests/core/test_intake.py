"""Taking a submission in: files opened without following links, notebooks read in a budgeted child."""
from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import pytest

from autograder.core.intake import (MAX_CELL_BYTES, NotebookError, open_regular, read_capped, read_cells,
                               read_code_cells, walk_notebooks)
from autograder.core.notebook import find_stubs, read_submission
from conftest import FIXTURE_COURSE

RELEASE = FIXTURE_COURSE / "assignments/fx/fx.ipynb"
STUBS = ["scaled_sum", "Counter", "mean_of", "double_scaled"]


def _notebook(tmp_path: Path, name: str, change=None, text: str | None = None) -> Path:
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
        return path
    nb = json.loads(RELEASE.read_text())
    if change:
        change(nb)
    path.write_text(json.dumps(nb))
    return path


def test_a_regular_notebook_is_read_and_matched(tmp_path):
    nb, notes = read_code_cells(_notebook(tmp_path, "ok.ipynb"))
    assert notes == []
    found, _ = find_stubs(nb, STUBS)
    assert sorted(found) == sorted(STUBS) and all(m.how == "grade_id" for m in found.values())
    whole, _ = read_submission(RELEASE)
    assert [c.cell_type for c in whole.cells] == [c["cell_type"] for c in json.loads(RELEASE.read_text())["cells"]]
    assert all("outputs" not in c or c.outputs == [] for c in whole.cells)


@pytest.mark.parametrize("kind", ["link_to_file", "link_to_device", "link_to_folder", "pipe", "socket", "folder"])
def test_anything_but_a_regular_file_is_refused_with_its_reason(tmp_path, kind):
    path = tmp_path / "sub.ipynb"
    if kind == "link_to_file":
        path.symlink_to(RELEASE)
    elif kind == "link_to_device":
        path.symlink_to("/dev/zero")
    elif kind == "link_to_folder":
        path.symlink_to(tmp_path)
    elif kind == "pipe":
        os.mkfifo(path)
    elif kind == "socket":
        server = socket.socket(socket.AF_UNIX)
        server.bind(str(path))
    else:
        path.mkdir()
    reason = "symbolic link" if kind.startswith("link") else ("folder" if kind == "folder" else "not a regular file")
    for read in (open_regular, read_capped, read_code_cells, read_cells, read_submission):
        with pytest.raises(NotebookError, match=reason):
            read(path)


def test_size_cap_is_checked_before_reading_and_never_read_past(tmp_path):
    path = _notebook(tmp_path, "big.ipynb", text="x" * 5000)
    with pytest.raises(NotebookError, match="over the"):
        read_capped(path, cap=4096)
    with pytest.raises(NotebookError, match="over the"):
        read_code_cells(path, cap=4096)
    assert read_capped(path, cap=5000) == b"x" * 5000


def test_walk_skips_links_and_says_so(tmp_path):
    (tmp_path / "sub" / "inner").mkdir(parents=True)
    (tmp_path / "sub" / "real.ipynb").write_text("{}")
    (tmp_path / "sub" / "inner" / "deep.ipynb").write_text("{}")
    (tmp_path / "sub" / "linked.ipynb").symlink_to(RELEASE)
    (tmp_path / "sub" / "dir_link").symlink_to(FIXTURE_COURSE / "assignments")
    os.mkfifo(tmp_path / "sub" / "pipe.ipynb")
    (tmp_path / "sub" / ".ipynb_checkpoints").mkdir()
    (tmp_path / "sub" / ".ipynb_checkpoints" / "real-checkpoint.ipynb").write_text("{}")
    found, skipped = walk_notebooks(tmp_path / "sub")
    assert [p.relative_to(tmp_path / "sub").as_posix() for p in found] == ["inner/deep.ipynb", "real.ipynb"]
    assert sorted(skipped) == ["dir_link is a symbolic link: not followed", "linked.ipynb is a symbolic link: not followed",
                               "pipe.ipynb is not a regular file: not read"]


def test_damaged_cells_cost_only_themselves(tmp_path):
    def damage(nb):
        nb["cells"][3]["source"] = {"not": "text"}   # scaled_sum
        nb["cells"][6]["source"] = 7                 # mean_of
        nb["cells"].insert(0, "not a cell")
        nb["cells"].insert(0, None)
    nb, notes = read_code_cells(_notebook(tmp_path, "damaged.ipynb", damage))
    found, _ = find_stubs(nb, STUBS)
    assert "source is not text" in found["scaled_sum"].problem and "source is not text" in found["mean_of"].problem
    assert found["Counter"].problem == "" and "class Counter" in found["Counter"].source
    assert any("4 cell(s) of the notebook are damaged" in n for n in notes), notes


def test_code_too_long_or_too_deep_to_analyse_is_the_submissions_problem(tmp_path):
    long_expression = "def scaled_sum(x):\n    return " + "+".join(["x"] * 200_000) + "\n"
    deep = "def mean_of(v):\n    return " + "(" * 5000 + "1" + ")" * 5000 + "\n"

    def change(nb):
        nb["cells"][3]["source"] = long_expression
        nb["cells"][6]["source"] = deep
        nb["cells"][5]["source"] = "class Counter:\n    pass\n# " + "y" * MAX_CELL_BYTES
    nb, _ = read_code_cells(_notebook(tmp_path, "long.ipynb", change))
    found, _ = find_stubs(nb, STUBS)
    assert found["scaled_sum"].problem == "" and found["scaled_sum"].source == long_expression
    assert found["mean_of"].source == deep
    assert "over the 1.0 MB limit" in found["Counter"].problem and found["Counter"].source == ""


@pytest.mark.parametrize("text, reason", [
    ("", "empty"),
    ("{not json", "not valid JSON"),
    ('{"cells": ' + "[" * 100_000 + "]" * 100_000 + "}", "nested too deeply"),
    ('{"nbformat": 4, "cells": []}', "no cells"),
    ('{"nbformat": 4, "cells": {"a": 1}}', "not a list"),
    ('{"nbformat": 9, "cells": [1]}', "unsupported notebook format"),
    ('[1, 2]', "not a Jupyter notebook"),
])
def test_not_a_notebook_says_why(tmp_path, text, reason):
    with pytest.raises(NotebookError, match=reason):
        read_code_cells(_notebook(tmp_path, "bad.ipynb", text=text))


def test_json_that_swells_in_memory_is_refused_within_the_childs_budget(tmp_path):
    """A 6 MB file of empty lists needs over 120 MB once parsed: over a 100 MB budget, in the child, not here."""
    path = _notebook(tmp_path, "swell.ipynb", text='{"nbformat": 4, "cells": [], "metadata": {"x": ['
                     + "[]," * 2_000_000 + "[]]}}")
    with pytest.raises(NotebookError, match="needs more than|budget"):
        read_code_cells(path, memory=100 * 2**20)
    with pytest.raises(NotebookError, match="needs more than|budget"):
        read_cells(path, memory=100 * 2**20)


def test_format_3_notebooks_are_converted(tmp_path):
    v3 = {"nbformat": 3, "nbformat_minor": 0, "metadata": {}, "worksheets": [{"cells": [
        {"cell_type": "heading", "level": 1, "source": "Title", "metadata": {}},
        {"cell_type": "code", "input": ["def scaled_sum(x):\n", "    return x\n"], "metadata": {}, "outputs": []}]}]}
    nb, notes = read_code_cells(_notebook(tmp_path, "v3.ipynb", text=json.dumps(v3)))
    found, match_notes = find_stubs(nb, STUBS)
    assert found["scaled_sum"].source == "def scaled_sum(x):\n    return x\n" and found["scaled_sum"].how == "name"
    assert any("format 3" in n for n in notes)


def test_a_reader_that_cannot_run_is_the_graders_fault_not_the_submissions(monkeypatch):
    from autograder.core import intake
    from autograder.core.results import GraderError

    monkeypatch.setattr(intake.sys, "executable", "/bin/false")  # exits 1 before reading anything
    with pytest.raises(GraderError, match="could not run"):
        read_code_cells(RELEASE)
