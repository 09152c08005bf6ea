"""What a submission hands the grader, taken in safely. Runs in the grader (trusted), and in a child of it.

A submission is whatever a student uploads, and Gradescope, git and zip files keep symbolic links, pipes
and devices. So the grader opens a submitted file only if it is a regular file, without following a
link, within the size cap, reading no more than the cap (:func:`open_regular`), and it walks a folder
of submissions without entering linked folders (:func:`walk_notebooks`): a link to the solution, or to
a device that never ends, is that submission's problem, named with its reason.

Reading a notebook's JSON and analysing its code are the next risks: JSON well under the size cap can
swell to gigabytes once parsed, and a cell with a very long expression can exhaust the recursion of
Python's parser. Both happen in a child process with its own memory, CPU and wall-clock budget; the
grader gets back only what it needs, as plain data no bigger than the file: the code cells with their
``grade_id`` and the names each defines (:func:`read_code_cells`, for grading), or every cell's type,
source, tags, nbgrader metadata and attachments, without outputs (:func:`read_cells`, for the outputs
that show a submission, such as the nbgrader gradebook). A child that runs out of its budget, or
crashes, costs that submission (an unreadable notebook, with the reason), never the grader.
"""
from __future__ import annotations

import ast
import json
import os
import re
import resource
import stat
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

MAX_NOTEBOOK_BYTES = 50 * 1024 * 1024
"""A submitted notebook is at most this big on disk (a notebook with its outputs cleared is far smaller)."""
MAX_CELL_BYTES = 1024 * 1024
"""A code cell holds at most this much source; a longer one is not run (its stub fails, saying why)."""
PARSE_MEMORY_BYTES = 768 * 1024**2
PARSE_CPU_SECONDS = 20
PARSE_WALL_SECONDS = 40.0
"""The child's budget: address space, CPU time, and the wall-clock time the grader waits for it."""
NAME_CHARS = 200
"""A ``grade_id`` or tag longer than this is cut (a real one is a short identifier)."""
NBGRADER_KEYS = ("grade", "solution", "locked", "task", "grade_id", "points", "schema_version")
"""The nbgrader metadata of a cell that is passed on (plain values only)."""
CHECKPOINTS = ".ipynb_checkpoints"


class NotebookError(ValueError):
    """A submission that cannot be read as a notebook; the message says why, for the student."""


@dataclass
class CodeCell:
    """A submitted code cell as the grader needs it: plain data, analysed in the child."""

    source: str
    grade_id: str | None = None
    defines: list[str] = field(default_factory=list)
    problem: str = ""
    """Why this cell cannot be run (over :data:`MAX_CELL_BYTES`, say), or empty."""


@dataclass
class SubmittedNotebook:
    """The code cells of a submitted notebook, in order."""

    cells: list[CodeCell]


# ------------------------------------------------------------------ files


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MB" if n >= 2**20 else f"{n} bytes"


def open_regular(path: str | Path, cap: int = MAX_NOTEBOOK_BYTES) -> int:
    """Open ``path`` for reading if it is a regular file of at most ``cap`` bytes, never following a link.

    Returns the descriptor; raises :class:`NotebookError` naming the reason otherwise. The file is
    checked before it is opened (a device or a pipe is never opened) and again once open (it was not
    swapped for something else in between).
    """
    name = Path(path).name
    try:
        before = os.lstat(path)
    except OSError as err:
        raise NotebookError(f"{name} could not be read ({err.strerror})") from None
    _check_regular(name, before, cap)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY)
    except OSError as err:
        raise NotebookError(f"{name} could not be opened ({err.strerror})") from None
    after = os.fstat(fd)
    if (after.st_dev, after.st_ino) != (before.st_dev, before.st_ino):
        os.close(fd)
        raise NotebookError(f"{name} changed while it was being opened")
    try:
        _check_regular(name, after, cap)
    except NotebookError:
        os.close(fd)
        raise
    os.set_blocking(fd, True)
    return fd


def _check_regular(name: str, st: os.stat_result, cap: int) -> None:
    if stat.S_ISLNK(st.st_mode):
        raise NotebookError(f"{name} is a symbolic link, not a notebook: the grader does not follow links")
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a device, pipe or socket"
        raise NotebookError(f"{name} is {kind}, not a regular file: it was not read")
    if st.st_size > cap:
        raise NotebookError(f"{name} is {_size(st.st_size)}, over the {_size(cap)} limit (clear the outputs: "
                            "Kernel → Restart & Clear Output, then save)")


def read_capped(path: str | Path, cap: int = MAX_NOTEBOOK_BYTES) -> bytes:
    """The bytes of a regular file, opened as :func:`open_regular` does; never more than ``cap``."""
    fd = open_regular(path, cap)
    try:
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(cap + 1)
    finally:
        os.close(fd)
    if len(data) > cap:
        raise NotebookError(f"{Path(path).name} grew over the {_size(cap)} limit while it was read")
    return data


MAX_WALK_DEPTH = 32
"""Folders below this many levels of a submission are not searched (a deeper tree is no one's work)."""
MAX_WALK_ENTRIES = 10_000
"""A submission's files and folders beyond this many are not searched."""


def walk_tree(folder: str | Path, skipped: list[str]) -> Iterator[tuple[str, list[str], list[str]]]:
    """``os.walk(folder)`` top-down, sorted, without following links and without recursion (Python 3.11's
    ``os.walk`` recurses once per level, so a submission nested a thousand folders deep stopped a batch),
    within :data:`MAX_WALK_DEPTH` levels and :data:`MAX_WALK_ENTRIES` entries; what it leaves out is
    appended to ``skipped``. As with ``os.walk``, a caller may prune the folder names it is given."""
    stack, seen = [(str(folder), 0)], 0
    while stack:
        root, depth = stack.pop()
        try:
            with os.scandir(root) as listing:
                entries = sorted(listing, key=lambda e: e.name)
        except OSError:
            continue
        if seen + len(entries) > MAX_WALK_ENTRIES:
            skipped.append(f"more than {MAX_WALK_ENTRIES:,} files and folders: the rest were not searched")
            entries, stack = entries[:max(0, MAX_WALK_ENTRIES - seen)], []
        seen += len(entries)
        dirs, files = [], []
        for entry in entries:
            try:
                (dirs if entry.is_dir() else files).append(entry.name)
            except OSError:
                files.append(entry.name)
        yield root, dirs, files
        below = [d for d in dirs if not os.path.islink(os.path.join(root, d))]
        if below and depth + 1 >= MAX_WALK_DEPTH:
            skipped.append(f"{Path(root).relative_to(folder).as_posix()}/ holds folders more than {MAX_WALK_DEPTH} "
                           "levels deep: not searched")
            continue
        stack.extend((os.path.join(root, d), depth + 1) for d in reversed(below))


def walk_notebooks(folder: str | Path) -> tuple[list[Path], list[str]]:
    """The ``.ipynb`` files (any case) under ``folder``, sorted, found without following links; and what was skipped.

    A link (to a notebook or a folder), or a notebook that is not a regular file, is left out and
    named in the second list, so the submission's feedback can say why it was not graded; so are the parts of a
    tree too deep or too large to search (:func:`walk_tree`).
    """
    found, skipped, checkpoints = [], [], []
    for root, dirs, files in walk_tree(folder, skipped):
        kept = []
        for name in sorted(dirs):
            if name == CHECKPOINTS:
                try:
                    saved = sum(f.lower().endswith(".ipynb") for f in os.listdir(os.path.join(root, name)))
                except OSError:
                    saved = 0
                if saved:
                    where = Path(root, name).relative_to(folder).as_posix()
                    checkpoints.append(f"{where}/ holds {saved} notebook(s), Jupyter's automatic checkpoints: "
                                       "not graded")
                continue
            if os.path.islink(os.path.join(root, name)):
                skipped.append(f"{Path(root, name).relative_to(folder).as_posix()} is a symbolic link: not followed")
            else:
                kept.append(name)
        dirs[:] = kept
        for name in sorted(f for f in files if f.lower().endswith(".ipynb")):
            path = Path(root) / name
            try:
                mode = os.lstat(path).st_mode
            except OSError:
                continue
            if stat.S_ISREG(mode):
                found.append(path)
            else:
                what = "a symbolic link: not followed" if stat.S_ISLNK(mode) else "not a regular file: not read"
                skipped.append(f"{path.relative_to(folder).as_posix()} is {what}")
    if not found:  # said only where they explain why nothing was graded
        skipped += checkpoints
    return sorted(found), skipped


# ------------------------------------------------------------------ parsing, in a child process


def read_code_cells(path: str | Path, cap: int = MAX_NOTEBOOK_BYTES, memory: int = PARSE_MEMORY_BYTES
                    ) -> tuple[SubmittedNotebook, list[str]]:
    """The code cells of the submitted notebook at ``path`` and notes about it, read within a budget.

    Raises :class:`NotebookError` for anything that is the submission's problem (not a regular file,
    too big, not a notebook, too costly to read); an error of the analysis itself is the grader's
    (:class:`~autograder.core.results.GraderError`).
    """
    data = _in_child(path, cap, "cells", memory)
    cells = []
    for raw in data["cells"]:
        cells.append(CodeCell(str(raw["source"]), raw["grade_id"] if isinstance(raw["grade_id"], str) else None,
                              [str(n) for n in raw["defines"]], str(raw["problem"])))
    return SubmittedNotebook(cells), [str(n) for n in data["notes"]]


def read_cells(path: str | Path, cap: int = MAX_NOTEBOOK_BYTES, memory: int = PARSE_MEMORY_BYTES
               ) -> tuple[list[dict[str, Any]], list[str]]:
    """Every cell of the submitted notebook at ``path`` as plain data, read in the child; and notes.

    Each cell is ``{"cell_type", "source", "metadata": {"tags", "nbgrader"}}`` (and ``"attachments"`` for
    Markdown), with no outputs: what an output that shows the submission (the nbgrader gradebook) needs.
    """
    data = _in_child(path, cap, "all", memory)
    return list(data["cells"]), [str(n) for n in data["notes"]]


def _in_child(path: str | Path, cap: int, mode: str, memory: int) -> dict[str, Any]:
    from autograder.core.results import GraderError

    fd = open_regular(path, cap)
    try:
        done = subprocess.run([sys.executable, "-m", "autograder.core.intake", mode, str(cap), str(memory)], stdin=fd,
                              capture_output=True, timeout=PARSE_WALL_SECONDS, cwd="/")
    except subprocess.TimeoutExpired:
        raise NotebookError(f"reading the notebook took over {PARSE_WALL_SECONDS:.0f} s; it was not graded") from None
    finally:
        os.close(fd)
    if done.returncode < 0:  # killed by a signal: its CPU limit, or a parser that overflowed the stack
        raise NotebookError("reading the notebook exceeded the grader's budget for it "
                            f"({_size(memory)} of memory, {PARSE_CPU_SECONDS} s of CPU): "
                            "it is not a notebook Jupyter saves")
    if done.returncode != 0:  # the reader itself could not run (it answers every submission's fault in JSON)
        raise GraderError("the notebook reader could not run: " + done.stderr.decode(errors="replace")[-500:])
    try:
        data = json.loads(done.stdout.decode("utf-8", "surrogatepass"))
    except ValueError:
        raise GraderError("the notebook reader's answer was not JSON: " + done.stderr.decode(errors="replace")[-500:]) from None
    if "fault" in data:
        raise GraderError(f"the notebook reader failed: {data['fault']}")
    if "error" in data:
        raise NotebookError(str(data["error"]))
    return data


def _limit_self(memory: int) -> None:
    for which, value in ((resource.RLIMIT_AS, memory), (resource.RLIMIT_CPU, PARSE_CPU_SECONDS),
                         (resource.RLIMIT_CORE, 0), (resource.RLIMIT_FSIZE, 0)):
        soft, hard = resource.getrlimit(which)
        value = value if hard == resource.RLIM_INFINITY else min(value, hard)
        resource.setrlimit(which, (value, value))


def _plain_nbgrader(meta: Any) -> dict[str, Any]:
    """A cell's nbgrader metadata reduced to its known keys with plain values (strings cut)."""
    if not isinstance(meta, dict):
        return {}
    out: dict[str, Any] = {}
    for key in NBGRADER_KEYS:
        value = meta.get(key)
        if isinstance(value, (bool, int, float)):
            out[key] = value
        elif isinstance(value, str):
            out[key] = value[:NAME_CHARS]
    return out


def _text(value: Any) -> str | None:
    """A cell's source as Jupyter stores it (a string, or a list of strings); None if it is neither."""
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(isinstance(line, str) for line in value):
        return "".join(value)
    return None


def defined_names(source: str) -> list[str]:
    """Top-level functions and classes a cell defines (by regex when the cell does not parse)."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return re.findall(r"^(?:async\s+)?(?:def|class)\s+([A-Za-z_]\w*)", source, flags=re.M)
    return [node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]


def _analyse(raw: bytes, mode: str) -> dict[str, Any]:
    """[child] What :func:`read_code_cells` returns, as JSON-able data, or ``{"error": ...}``."""
    notes: list[str] = []
    if not raw.strip():
        return {"error": "the file is empty"}
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
        notes.append("the file is not valid UTF-8; it was read as Latin-1 (save notebooks from Jupyter to avoid this)")
    del raw
    try:
        data = json.loads(text)
    except RecursionError:
        return {"error": "the file is not a Jupyter notebook (its JSON is nested too deeply)"}
    except ValueError as err:
        return {"error": f"the file is not a Jupyter notebook (not valid JSON: {str(err)[:120]})"}
    del text
    if not isinstance(data, dict) or ("cells" not in data and "worksheets" not in data):
        return {"error": "the file is JSON but not a Jupyter notebook (it has no cells)"}
    major = data.get("nbformat")
    if major not in (3, 4):
        return {"error": f"unsupported notebook format version {str(major)[:20]}; open and save it in a current Jupyter"}
    if major == 3:
        notes.append("the notebook was in the old format 3 and was converted")
        sheets = data.get("worksheets")
        raw_cells = [c for ws in sheets if isinstance(ws, dict) and isinstance(ws.get("cells"), list)
                     for c in ws["cells"]] if isinstance(sheets, list) else None
        source_key = "input"
    else:
        raw_cells, source_key = data.get("cells"), "source"
    if not isinstance(raw_cells, list):
        return {"error": "the notebook's structure is damaged (its cells are not a list)"}
    if not raw_cells:
        return {"error": "the notebook has no cells"}
    cells, damaged = [], 0
    for cell in raw_cells:
        if not isinstance(cell, dict):
            damaged += 1
            continue
        kind = cell.get("cell_type")
        kind = "markdown" if kind == "heading" else kind  # format 3's headings are Markdown in format 4
        source = _text(cell.get(source_key if kind == "code" else "source", ""))
        meta = cell.get("metadata")
        nbgrader = _plain_nbgrader(meta.get("nbgrader") if isinstance(meta, dict) else None)
        grade_id = nbgrader.get("grade_id") if isinstance(nbgrader.get("grade_id"), str) else None
        if source is None:
            damaged += 1
        if mode == "all":
            if kind not in ("code", "markdown", "raw"):
                damaged += 1
                continue
            tags = meta.get("tags") if isinstance(meta, dict) else None
            tags = [t[:NAME_CHARS] for t in tags if isinstance(t, str)] if isinstance(tags, list) else []
            out = {"cell_type": kind, "source": source or "", "metadata": {"tags": tags, "nbgrader": nbgrader}}
            attachments = cell.get("attachments")
            if kind == "markdown" and isinstance(attachments, dict) and all(
                    isinstance(v, dict) and all(isinstance(x, str) for x in v.values()) for v in attachments.values()):
                out["attachments"] = attachments
            cells.append(out)
            continue
        if kind != "code":
            continue
        if source is None:
            cells.append({"source": "", "grade_id": grade_id, "defines": [],
                          "problem": "the cell's source is not text (the notebook file is damaged)"})
        elif len(source.encode("utf-8", "surrogatepass")) > MAX_CELL_BYTES:
            cells.append({"source": "", "grade_id": grade_id, "defines": defined_names(source[:MAX_CELL_BYTES]),
                          "problem": f"the cell holds {_size(len(source))} of code, over the {_size(MAX_CELL_BYTES)} "
                                     "limit: it was not run"})
        else:
            cells.append({"source": source, "grade_id": grade_id, "defines": defined_names(source)[:100], "problem": ""})
    if damaged:
        notes.append(f"{damaged} cell(s) of the notebook are damaged (not a cell, or a source that is not text)")
    return {"cells": cells, "notes": notes}


def _child_main(mode: str, cap: int, memory: int) -> None:
    """[child] Read the notebook on standard input within the budget; write the analysis as JSON.

    Whatever the notebook does to this process (memory, recursion) is answered in JSON as the
    submission's problem; only a fault of this reader's own code is reported as one (``fault``).
    """
    _limit_self(memory)
    try:
        raw = sys.stdin.buffer.read(cap + 1)
        out = {"error": f"the notebook is over the {_size(cap)} limit"} if len(raw) > cap else _analyse(raw, mode)
        del raw
        encoded = json.dumps(out, ensure_ascii=False).encode("utf-8", "surrogatepass")
        if len(encoded) > 2 * cap + MAX_CELL_BYTES:  # sources of control characters, each escaped in six bytes
            encoded = json.dumps({"error": "the notebook's code is too large to grade"}).encode()
    except MemoryError:
        encoded = json.dumps({"error": f"reading the notebook needs more than the grader's {_size(memory)} for "
                                       "it; it is not a notebook Jupyter saves"}).encode()
    except RecursionError:
        encoded = json.dumps({"error": "the notebook's code is nested too deeply to analyse"}).encode()
    except Exception as err:  # noqa: BLE001 - a bug of this reader: the grader's fault, reported as such
        encoded = json.dumps({"fault": f"{type(err).__name__}: {str(err)[:300]}"}).encode()
    sys.stdout.buffer.write(encoded)


if __name__ == "__main__":  # python -m autograder.core.intake MODE CAP MEMORY < notebook
    _child_main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
