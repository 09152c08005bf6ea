"""Reading notebooks as the grader needs them: tolerant of damage, exact about cells.

A submission may be anything a student's upload can be: not JSON, an old
nbformat, empty, huge, not UTF-8, with cells reordered or deleted and metadata
stripped. :func:`read_submission` turns each of those into a clear message
instead of a traceback, and :func:`find_stubs` matches cells by nbgrader
``grade_id`` first and by the name of the function or class a cell defines as a
fallback, so lost metadata costs nothing when the code is there.
"""
from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

MAX_NOTEBOOK_BYTES = 50 * 1024 * 1024
PARAMETERS_TAG, SETUP_TAG = "parameters", "setup"


class NotebookError(ValueError):
    """A file that cannot be read as a notebook; the message says why, for the student."""


@dataclass
class StubMatch:
    source: str
    how: str  # "grade_id" or "name"


@dataclass
class Submission:
    path: Path
    notebook: nbformat.NotebookNode | None
    stubs: dict[str, StubMatch] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    error: str | None = None


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
    """Parse an uploaded notebook; raise :class:`NotebookError` with a readable reason."""
    path = Path(path)
    notes: list[str] = []
    size = path.stat().st_size
    if size > MAX_NOTEBOOK_BYTES:
        raise NotebookError(f"the notebook is {size / 2**20:.0f} MB, over the {MAX_NOTEBOOK_BYTES // 2**20} MB limit "
                            "(clear the outputs: Kernel → Restart & Clear Output, then save)")
    raw = path.read_bytes()
    if not raw.strip():
        raise NotebookError("the file is empty")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
        notes.append("the file is not valid UTF-8; it was read as Latin-1 (save notebooks from Jupyter to avoid this)")
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError) as err:
        raise NotebookError(f"the file is not a Jupyter notebook (not valid JSON: {str(err)[:120]})") from None
    if not isinstance(data, dict) or "cells" not in data and "worksheets" not in data:
        raise NotebookError("the file is JSON but not a Jupyter notebook (it has no cells)")
    major = data.get("nbformat")
    if major not in (3, 4):
        raise NotebookError(f"unsupported notebook format version {major!r}; open and save it in a current Jupyter")
    try:
        nb = nbformat.reads(json.dumps(data), as_version=4)
    except Exception as err:  # noqa: BLE001 - nbformat raises many types on malformed input
        raise NotebookError(f"the notebook's structure is damaged: {str(err)[:200]}") from None
    if major == 3:
        notes.append("the notebook was in the old format 3 and was converted")
    if not nb.cells:
        raise NotebookError("the notebook has no cells")
    for cell in nb.cells:
        if not isinstance(cell.get("source"), str):
            cell["source"] = "".join(cell.get("source") or [])
    return nb, notes


def defined_names(source: str) -> list[str]:
    """Top-level functions and classes a cell defines (by regex when the cell does not parse)."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return re.findall(r"^(?:async\s+)?(?:def|class)\s+([A-Za-z_]\w*)", source, flags=re.M)
    return [node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]


def find_stubs(nb: nbformat.NotebookNode, expected: list[str]) -> tuple[dict[str, StubMatch], list[str]]:
    """Match each expected stub to a code cell: by ``grade_id``, else by the name the cell defines.

    When several cells match, the last one wins, as it would when the notebook runs top to bottom.
    """
    by_id: dict[str, StubMatch] = {}
    by_name: dict[str, StubMatch] = {}
    notes: list[str] = []
    for cell in nb.cells:
        if cell.get("cell_type") != "code":
            continue
        source = cell.get("source", "")
        grade_id = _nbgrader(cell).get("grade_id")
        if grade_id in expected:
            by_id[grade_id] = StubMatch(source, "grade_id")
            continue
        for name in defined_names(source):
            if name in expected:
                by_name[name] = StubMatch(source, "name")
    found = {}
    for name in expected:
        if name in by_id:
            found[name] = by_id[name]
        elif name in by_name:
            found[name] = by_name[name]
            notes.append(f"`{name}` was found by the name it defines (its cell's grading metadata was missing or changed)")
    return found, notes


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
