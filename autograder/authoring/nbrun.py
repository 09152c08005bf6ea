"""Execute a notebook with injected parameters under a time budget, and say exactly what failed.

Parameters follow papermill's convention: a cell tagged ``parameters`` holds
the defaults, and the runner inserts a cell right after it that overrides them
(``FAST = True`` for tests). When a cell fails, the report names the cell, the
line of its source and the error, instead of a page of kernel traceback.

    python -m autograder run solutions/hw0_setup/hw0_setup.ipynb -p FAST=True --timeout 300
"""
from __future__ import annotations

import ast
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError, CellTimeoutError, DeadKernelError
from nbformat.v4 import new_code_cell

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


@dataclass
class RunReport:
    ok: bool
    seconds: float
    cells_run: int
    failed_cell: int | None = None
    """The failing cell's number among the notebook's own code cells (the injected parameters not counted)."""
    failed_source_line: str = ""
    error: str = ""
    failed_label: str = ""
    """The failing cell's nbgrader ``grade_id`` (or its tag), when it has one."""
    cell_seconds: dict[str, float] = field(default_factory=dict)
    """Wall seconds of each code cell that ran, keyed by its nbformat cell id (benchmarks state them)."""

    def describe(self, path: str | Path) -> str:
        if self.ok:
            return f"{path}: ran {self.cells_run} code cells in {self.seconds:.1f} s"
        where = f"code cell {self.failed_cell}" if self.failed_cell is not None else "the notebook"
        where += f" (`{self.failed_label}`)" if self.failed_label else ""
        line = f"\n    at: {self.failed_source_line}" if self.failed_source_line else ""
        return f"{path}: FAILED in {where} after {self.seconds:.1f} s{line}\n    {self.error}"


def parse_value(text: str) -> Any:
    """``True``, ``3``, ``0.5``, ``'x'`` as Python literals; anything else as a string."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def inject_parameters(nb: nbformat.NotebookNode, parameters: dict[str, Any]) -> None:
    """Insert an ``injected-parameters`` cell after the ``parameters`` cell (or first, if there is none)."""
    if not parameters:
        return
    source = "# Parameters injected by the course tools\n" + "\n".join(f"{k} = {v!r}" for k, v in parameters.items())
    cell = new_code_cell(source, metadata={"tags": ["injected-parameters"]})
    index = next((i + 1 for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", [])), 0)
    nb.cells.insert(index, cell)


def _is_stub(cell: nbformat.NotebookNode) -> bool:
    meta = cell.metadata.get("nbgrader", {})
    return cell.cell_type == "code" and bool(meta.get("solution"))


def _failing_line(cell_source: str, traceback_lines: list[str]) -> str:
    """The source line of the executed cell that the traceback points at, if it can be found."""
    text = _ANSI.sub("", "\n".join(traceback_lines))
    numbers = re.findall(r"(?:line |^-*> ?)(\d+)", text, flags=re.M)
    lines = cell_source.splitlines()
    for number in reversed(numbers):
        n = int(number)
        if 1 <= n <= len(lines):
            return f"line {n}: {lines[n - 1].strip()}"
    return ""


def run_notebook(path: str | Path, parameters: dict[str, Any] | None = None, timeout: float = 600,
                 cwd: str | Path | None = None, until_first_stub: bool = False,
                 output: str | Path | None = None) -> RunReport:
    """Run ``path`` top to bottom (or up to its first stub) within ``timeout`` seconds in total."""
    nb = nbformat.read(str(path), as_version=4)
    if until_first_stub:
        first = next((i for i, c in enumerate(nb.cells) if _is_stub(c)), len(nb.cells))
        nb.cells = nb.cells[:first]
    inject_parameters(nb, parameters or {})
    cwd = Path(cwd or Path(path).parent)
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(cwd)}})
    start, count = time.monotonic(), 0
    report: RunReport | None = None
    cell_seconds: dict[str, float] = {}
    with client.setup_kernel():
        for index, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            injected = "injected-parameters" in cell.metadata.get("tags", [])
            count += not injected
            client.timeout = max(1, math.ceil(timeout - (time.monotonic() - start)))
            cell_start = time.monotonic()
            try:
                client.execute_cell(cell, index)
            except CellTimeoutError:
                report = RunReport(False, time.monotonic() - start, count, count, "",
                                   f"the notebook ran past its budget of {timeout:.0f} s in this cell")
            except DeadKernelError as err:
                report = RunReport(False, time.monotonic() - start, count, count, "", f"the kernel died: {err}")
            except CellExecutionError as err:
                error_output = next((o for o in cell.get("outputs", []) if o.get("output_type") == "error"), {})
                message = f"{error_output.get('ename', 'Error')}: {error_output.get('evalue', str(err))}"
                report = RunReport(False, time.monotonic() - start, count, count,
                                   _failing_line(cell.source, error_output.get("traceback", [])), message[:2000])
            if not injected and cell.get("id"):
                cell_seconds[cell["id"]] = round(time.monotonic() - cell_start, 2)
            if report is not None:
                tags = [t for t in cell.metadata.get("tags", []) if t not in ("setup", "check", "experiment")]
                report.failed_label = cell.metadata.get("nbgrader", {}).get("grade_id") or (tags[0] if tags else "")
                report.failed_cell = max(count, 1)
                break
    if output is not None:
        nbformat.write(nb, str(output))
    report = report or RunReport(True, time.monotonic() - start, count)
    report.cell_seconds = cell_seconds
    return report
