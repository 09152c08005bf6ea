"""A grading's record on disk: ``result.json`` in each submission's folder, written atomically.

The record is the core's own state (a batch resumes from it), not an output: the writers in
:mod:`autograder.outputs` render a result into files for people; this module keeps the result
itself. Every write goes to a temporary file renamed into place, so a batch killed at any moment
never leaves half a record behind.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from autograder.core.results import GradeResult, result_from_dict, result_to_dict

RESULT_NAME = "result.json"
"""The full record of one submission's grading; its presence marks the submission as done."""


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8; anything unencodable as ``?``) to ``path`` through a temporary file in the same
    folder, then rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(text.encode("utf-8", "replace"))  # a lone surrogate becomes "?", never a failed write
    os.replace(tmp, path)


def save_result(result: GradeResult, folder: Path) -> None:
    """Record ``result`` in ``folder/result.json``."""
    atomic_write(Path(folder) / RESULT_NAME, json.dumps(result_to_dict(result), indent=2, ensure_ascii=False))


def load_result(folder: Path) -> GradeResult | None:
    """The result recorded in ``folder``, or None when there is none or it cannot be read."""
    try:
        return result_from_dict(json.loads((Path(folder) / RESULT_NAME).read_text(encoding="utf-8")))
    except (OSError, ValueError, KeyError, TypeError):
        return None
