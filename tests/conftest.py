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


@pytest.fixture(scope="module")
def fx_grader():
    """A grader of the fixture course's assignment ``fx``, built once per test module."""
    from autograder.core.grader import Grader

    saved, course.REPO = course.REPO, FIXTURE_COURSE
    try:
        grader = Grader("fx")
    finally:
        course.REPO = saved
    yield grader
    grader.close()


def _open_folder():
    path = Path(tempfile.mkdtemp(prefix="rlcourse-test-", dir="/tmp"))
    path.chmod(0o777)
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def open_tmp() -> Path:
    """A temporary folder that an unprivileged user may write (pytest's own tmp_path is private to root)."""
    yield from _open_folder()


@pytest.fixture(scope="module")
def open_module_tmp() -> Path:
    """:func:`open_tmp` for a whole test module (a batch graded once for all its tests)."""
    yield from _open_folder()


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


def check_hand_mutants(assignment: str, mutants: dict[str, dict[str, tuple[str, str]]], folder: Path) -> None:
    """Grade the complete sample with each hand-written mutant (``{stub: {label: (old text, new text)}}`` applied
    to the solution's stub) by the real grader: each must lose points on its own stub and nowhere else. With
    ``-s`` a table of kills per stub is printed."""
    from autograder.authoring.samples import solution_sources
    from autograder.outputs.files import grade_folder

    solved = solution_sources(assignment)
    complete = course.samples_dir(assignment) / "complete.ipynb"
    names = {}
    for stub, changes in mutants.items():
        for i, (label, (old, new)) in enumerate(changes.items()):
            assert solved[stub].count(old) >= 1, f"{stub} / {label}: the text to mutate is not in the solution"
            name = f"{stub}__{i}"
            names[name] = (stub, label)
            with_cells(complete, folder / "mutants" / f"{name}.ipynb", {stub: solved[stub].replace(old, new)})
    results = {r.submission: r for r in grade_folder(assignment, folder / "mutants", folder / "out", jobs=2,
                                                     progress=False)}
    survivors, leaks, report = [], [], {}
    for name, (stub, label) in names.items():
        scores = {s.name: (s.score, s.max_score) for s in results[name].stubs}
        killed = scores[stub][0] < scores[stub][1]
        report.setdefault(stub, []).append(killed)
        if not killed:
            survivors.append(f"{stub}: {label}")
        leaks += [f"{stub}: {label} cost {other}" for other, (got, top) in scores.items() if other != stub and got < top]
    print("\n| stub | mutants | killed |\n|---|---:|---:|")
    for stub, kills in report.items():
        print(f"| `{stub}` | {len(kills)} | {sum(kills)} ({sum(kills) / len(kills):.0%}) |")
    assert not leaks, leaks
    assert not survivors, f"mutants the suite does not catch: {survivors}"


_GRADERS: dict = {}
"""The last assignment's grader, kept for the next grading of the same assignment as a batch's worker keeps one for
all its submissions (a grading after the first skips the zygote's imports and the reference's trusted values); one
at a time, as the batch does, so that a worker does not hold a zygote per assignment."""


def graded_stubs(assignment: str, stubs: dict[str, str], path: Path) -> dict:
    """Grade ``assignment``'s solution notebook with ``stubs`` (name -> source) in place of those stub cells,
    written to ``path``: each stub's result by name (the grading must have a score)."""
    from autograder.authoring.samples import _with_stubs
    from autograder.core.grader import Grader

    nbformat.write(_with_stubs(assignment, stubs), str(path))
    if assignment not in _GRADERS:
        pytest_sessionfinish(None, None)  # the previous assignment's grader goes first
        _GRADERS[assignment] = Grader(assignment)
    result = _GRADERS[assignment].grade(path)
    assert result.has_score, result.error
    return {s.name: s for s in result.stubs}


def pytest_sessionfinish(session, exitstatus) -> None:
    """Close the graders :func:`graded_stubs` kept (their zygotes end with them)."""
    while _GRADERS:
        _GRADERS.popitem()[1].close()
