"""Shared fixtures: the small fixture course, world-writable temporary folders, notebook surgery."""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import nbformat
import pytest

from autograder.core import course

REPO = Path(__file__).resolve().parents[1]
FIXTURE_COURSE = REPO / "tests" / "fixtures" / "course"


@pytest.fixture
def fixture_course(monkeypatch: pytest.MonkeyPatch) -> Path:
    """Point the course tools at the fixture course (assignment ``fx``)."""
    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    return FIXTURE_COURSE


@pytest.fixture
def open_tmp() -> Path:
    """A temporary folder that an unprivileged user may write (pytest's own tmp_path is private to root)."""
    path = Path(tempfile.mkdtemp(prefix="rlcourse-test-", dir="/tmp"))
    path.chmod(0o777)
    yield path
    shutil.rmtree(path, ignore_errors=True)


def with_cells(source_nb: Path, out: Path, replacements: dict[str, str | None]) -> Path:
    """Copy a notebook, replacing (or, with None, deleting) the code cells with the given grade_ids."""
    nb = nbformat.read(str(source_nb), as_version=4)
    kept = []
    for cell in nb.cells:
        grade_id = cell.metadata.get("nbgrader", {}).get("grade_id")
        if grade_id in replacements:
            if replacements[grade_id] is None:
                continue
            cell.source = replacements[grade_id]
        kept.append(cell)
    nb.cells = kept
    out.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, str(out))
    os.chmod(out, 0o644)
    return out
