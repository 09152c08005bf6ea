"""Notebooks as the grader needs them: the course's own (release plan, written answers, parameters) and
the matching of a submission's cells to stubs.

A submission may be anything a student's upload can be: not JSON, an old
nbformat, empty, huge, not UTF-8, with cells reordered or deleted and metadata
stripped; :mod:`autograder.core.intake` reads it safely and turns each of those into
a clear message. :func:`find_stubs` matches cells by nbgrader ``grade_id`` first
and by the name of the function or class a cell defines as a fallback, so lost
metadata costs nothing when the code is there.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import nbformat

from autograder.core.intake import (MAX_CELL_BYTES, MAX_NOTEBOOK_BYTES, CodeCell, NotebookError, SubmittedNotebook,
                                    defined_names, read_cells)

__all__ = ["MAX_NOTEBOOK_BYTES", "NotebookError", "StubMatch", "defined_names", "find_stubs", "imported_modules",
           "imported_names", "manual_cells", "read_notebook", "read_submission", "release_plan", "with_parameters"]
PARAMETERS_TAG, SETUP_TAG = "parameters", "setup"


@dataclass
class StubMatch:
    source: str
    how: str  # "grade_id", "name" (no cell had the stub's grade_id) or "below" (a later cell, its own untouched)
    problem: str = ""
    """Why the matched cell cannot be run (see :class:`autograder.core.intake.CodeCell`), or empty."""


def _nbgrader(cell) -> dict:
    meta = cell.get("metadata", {}).get("nbgrader", {})
    return meta if isinstance(meta, dict) else {}


def _tags(cell) -> list[str]:
    tags = cell.get("metadata", {}).get("tags", [])
    return tags if isinstance(tags, list) else []


def read_notebook(path: str | Path) -> nbformat.NotebookNode:
    """Parse a trusted notebook (a solution or a release); errors here are the course's bugs."""
    return nbformat.read(str(path), as_version=4)


def read_submission(path: str | Path) -> tuple[nbformat.NotebookNode, list[str]]:
    """A submitted notebook, for the outputs that show it (the nbgrader gradebook); with notes.

    Read as :func:`autograder.core.intake.read_cells` reads it (no link followed, within the size cap,
    parsed in a child process within its budget): every cell's type, source, tags, nbgrader metadata
    and Markdown attachments, and no outputs. Raises :class:`NotebookError` with the reason.
    Grading itself needs only the code cells: :func:`autograder.core.intake.read_code_cells`.
    """
    cells, notes = read_cells(path)
    made = {"code": nbformat.v4.new_code_cell, "markdown": nbformat.v4.new_markdown_cell,
            "raw": nbformat.v4.new_raw_cell}
    nb = nbformat.v4.new_notebook()
    for cell in cells:
        new = made[cell["cell_type"]](cell["source"], metadata=cell["metadata"])
        if "attachments" in cell:
            new.attachments = cell["attachments"]
        nb.cells.append(new)
    return nb, notes


def code_cells(nb: SubmittedNotebook | nbformat.NotebookNode) -> list[CodeCell]:
    """The code cells with the names each defines; a cell over :data:`MAX_CELL_BYTES` is read only up to the cap
    for its names and marked unrunnable, as grading reads it (parsing a 12 MB cell cost the sync 4 GB)."""
    if isinstance(nb, SubmittedNotebook):
        return nb.cells
    out = []
    for c in nb.cells:
        if c.get("cell_type") != "code":
            continue
        source = c.get("source", "")
        if len(source) > MAX_CELL_BYTES:
            out.append(CodeCell(source, _nbgrader(c).get("grade_id"), defined_names(source[:MAX_CELL_BYTES]),
                                f"the cell holds over {MAX_CELL_BYTES // 1024**2} MB of code: it was not run"))
        else:
            out.append(CodeCell(source, _nbgrader(c).get("grade_id"), defined_names(source)))
    return out


UNTOUCHED_MARK = "raise NotImplementedError"
"""What a stub cell as released still holds (nbgrader's placeholder) until the student writes the stub."""


def _parses(source: str) -> bool:
    """Whether a cell is plain Python (a cell with a syntax error or an IPython magic is not an answer)."""
    try:
        ast.parse(source)
    except (SyntaxError, ValueError):
        return False
    return True


def find_stubs(nb: SubmittedNotebook | nbformat.NotebookNode, expected: list[str]) -> tuple[dict[str, StubMatch], list[str]]:
    """Match each expected stub to a code cell: by ``grade_id``, else by the name the cell defines.

    The stub's own cell (its ``grade_id``) is the answer, with one exception: while it is untouched (it still
    raises ``NotImplementedError``), the last cell below it that defines the stub again and parses is the answer,
    as running the notebook top to bottom would use it (a note says so). A finished stub is never replaced by a
    later cell: a debugging wrapper or an unfinished rewrite below it is not the answer. Without a ``grade_id``
    cell, the last parsing cell that defines the name is the answer (the last one at all if none parses).
    ``nb`` is what :func:`autograder.core.intake.read_code_cells` returns (grading), or a notebook from
    :func:`read_submission`.
    """
    found: dict[str, StubMatch] = {}
    own: dict[str, str] = {}  # each stub's own cell (by grade_id), the last one if several
    for cell in code_cells(nb):
        if cell.grade_id in expected:
            found[cell.grade_id] = own[cell.grade_id] = StubMatch(cell.source, "grade_id", cell.problem)
            continue
        names = [name for name in cell.defines if name in expected]
        parses = bool(names) and not cell.problem and _parses(cell.source)  # parsed only when it may be an answer
        for name in names:
            if name in own:
                if parses and UNTOUCHED_MARK in own[name].source:
                    found[name] = StubMatch(cell.source, "below", cell.problem)
            elif parses or name not in found:
                found[name] = StubMatch(cell.source, "name", cell.problem)
    notes = []
    for name in expected:
        if name in found and found[name].how == "below":
            notes.append(f"`{name}` was taken from a cell below its own stub cell, which was left as released: "
                         "running the notebook top to bottom would use that one")
        elif name in found and found[name].how == "name":
            notes.append(f"`{name}` was found by the name it defines (its cell's grading metadata was missing or changed)")
    return {name: found[name] for name in expected if name in found}, notes


@dataclass
class ReleaseCell:
    kind: str  # "parameters", "setup" or "stub"
    label: str
    source: str


def release_plan(nb: nbformat.NotebookNode) -> list[ReleaseCell]:
    """The cells the grader runs, in order: parameters, setup cells and stub positions."""
    plan = []
    for cell in nb.cells:
        if cell.get("cell_type") != "code":
            continue
        meta, tags = _nbgrader(cell), _tags(cell)
        if PARAMETERS_TAG in tags:
            plan.append(ReleaseCell("parameters", "parameters", cell.source))
        elif SETUP_TAG in tags:
            plan.append(ReleaseCell("setup", meta.get("grade_id", f"setup_{len(plan)}"), cell.source))
        elif meta.get("solution") and meta.get("grade_id"):
            plan.append(ReleaseCell("stub", meta["grade_id"], cell.source))
    return plan


def manual_cells(nb: nbformat.NotebookNode) -> list[tuple[str, float]]:
    """Hand-graded answers: ``(grade_id, points)`` of cells with ``grade`` and ``solution`` set, not code."""
    out = []
    for cell in nb.cells:
        meta = _nbgrader(cell)
        if meta.get("grade") and meta.get("solution") and cell.get("cell_type") == "markdown":
            out.append((meta.get("grade_id", "?"), float(meta.get("points", 0))))
    return out


def with_parameters(source: str, values: dict[str, object]) -> str:
    """The parameters cell followed by assignments that override it (papermill's convention)."""
    lines = [f"{name} = {value!r}" for name, value in values.items()]
    return source.rstrip() + "\n# injected by the course tools\n" + "\n".join(lines) + "\n"


def imported_modules(sources: list[str]) -> list[str]:
    """Top-level modules imported by trusted cells (to pre-import them in the sandbox's zygote)."""
    modules: list[str] = []
    for source in sources:
        try:
            tree = ast.parse(source)
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                modules += [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                modules.append(node.module)
    return list(dict.fromkeys(modules))


def imported_names(source: str, package: str | None = None) -> set[str]:
    """Every module a Python source may import, read from its AST (imports inside functions included):
    ``import a.b`` gives ``a`` and ``a.b``; ``from a import b`` gives ``a`` and ``a.b`` (``b`` may be a
    module); a relative import is resolved against ``package``. Unparsable source imports nothing."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return set()
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                names.update(".".join(parts[:k]) for k in range(1, len(parts) + 1))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                if package is None:
                    continue
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            parts = base.split(".")
            names.update(".".join(parts[:k]) for k in range(1, len(parts) + 1))
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names
