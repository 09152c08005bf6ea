"""Reading what ``python -m autograder batch`` wrote: one folder per submission holding ``result.json``.

A batch's output folder (``--out DIR``) holds ``gradebook.csv`` and one folder per submission,
named by the submission's safe name (``autograder.core.batch.unique_safe_names``). Names made safe
never start with ``_`` or ``.``, so this room keeps its own files under names that do:
``_previous/<stamp>/`` (results archived by a regrade) and ``_students.json`` (which nbgrader
student each submission belongs to, written by the gradebook sync).
"""
from __future__ import annotations

import json
from pathlib import Path

from autograder.core.store import PREVIOUS_DIR, RESULT_NAME
from autograder.core.results import GradeResult, result_from_dict

"""Where a regrade archives the results it replaces: ``DIR/_previous/<UTC stamp>/<submission>/``."""
STUDENTS_NAME = "_students.json"
"""``{submission: [student id, ...]}``, written by the gradebook sync for the commands after it."""


def read_result(folder: Path) -> GradeResult | None:
    """The result recorded in ``folder/result.json``, or None when there is none (or it is unreadable)."""
    try:
        return result_from_dict(json.loads((Path(folder) / RESULT_NAME).read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def read_results(out_dir: Path) -> dict[str, GradeResult]:
    """Every submission's result in a batch output folder, by submission name, sorted by name."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise SystemExit(f"{out_dir} is not a batch output folder (run `python -m autograder batch` first)")
    results = {}
    for folder in sorted(out_dir.iterdir()):
        if folder.is_dir() and not folder.name.startswith(("_", ".")):
            result = read_result(folder)
            if result is not None:
                results[folder.name] = result
    return results


def archived_runs(out_dir: Path) -> list[Path]:
    """The archived earlier results of a batch folder, oldest first."""
    previous = Path(out_dir) / PREVIOUS_DIR
    return sorted(p for p in previous.iterdir() if p.is_dir()) if previous.is_dir() else []


def read_students(out_dir: Path) -> dict[str, list[str]]:
    """The submission-to-students map the last gradebook sync wrote (empty before any sync)."""
    try:
        return json.loads((Path(out_dir) / STUDENTS_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
