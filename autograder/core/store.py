"""A grading's record on disk: ``result.json`` in each submission's folder, written atomically.

The record is the core's own state (a batch resumes from it), not an output: the writers in
:mod:`autograder.outputs` render a result into files for people; this module keeps the result
itself. Every write goes to a temporary file renamed into place, so a batch killed at any moment
never leaves half a record behind.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from datetime import datetime, timezone
from pathlib import Path

from autograder.core.results import GradeResult, result_from_dict, result_to_dict

RESULT_NAME = "result.json"
"""The full record of one submission's grading; its presence marks the submission as done."""

PREVIOUS_DIR = "_previous"
"""Where a batch folder keeps earlier results that a later grading replaced, one folder per UTC time."""


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


def notebook_digest(path: Path, cap: int = 64 * 2**20) -> str:
    """SHA-256 of the file's first ``cap`` bytes and its size: which notebook a result graded, so that a batch
    run again can tell a notebook handed in anew from the one it graded (a larger file is ungradable anyway)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        digest.update(f.read(cap))
    digest.update(str(os.stat(path).st_size).encode())
    return digest.hexdigest()


def archive_results(out_dir: Path, names: list[str], files: list[str] = ()) -> Path:
    """Copy the named submissions' folders (and ``files`` of the batch folder, its gradebook say) into
    ``out_dir/_previous/<UTC time>/``, where they stay readable after a new grading replaces them."""
    out_dir = Path(out_dir)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    dest, n = out_dir / PREVIOUS_DIR / stamp, 2
    while dest.exists():
        dest, n = out_dir / PREVIOUS_DIR / f"{stamp}-{n}", n + 1
    dest.mkdir(parents=True)
    for name in names:
        if (out_dir / name).is_dir():
            shutil.copytree(out_dir / name, dest / name, symlinks=True)
    for name in files:
        if (out_dir / name).is_file():
            shutil.copy2(out_dir / name, dest / name)
    return dest
