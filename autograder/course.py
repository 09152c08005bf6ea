"""Where an assignment's pieces live in this repository (or in the Gradescope bundle built from it)."""
from __future__ import annotations

import os
from pathlib import Path

INSTALLED = Path(__file__).resolve().parents[1]
"""The repository this package runs from."""
REPO = Path(os.environ.get("RLCOURSE_REPO", INSTALLED))
"""The course being graded: this repository, or another laid out the same way (tests use a small one)."""


def assignment_ids() -> list[str]:
    """Assignments that have a solution notebook, in order."""
    return sorted(p.name for p in (REPO / "solutions").iterdir() if (p / f"{p.name}.ipynb").exists())


def solution_notebook(assignment: str) -> Path:
    return REPO / "solutions" / assignment / f"{assignment}.ipynb"


def release_notebook(assignment: str) -> Path:
    return REPO / "assignments" / assignment / f"{assignment}.ipynb"


def suite_dir(assignment: str) -> Path:
    return REPO / "autograder" / "suites" / assignment


def samples_dir(assignment: str) -> Path:
    return REPO / "autograder" / "samples" / assignment


def check_assignment(assignment: str) -> None:
    """Fail early, with the list of known ids, on a mistyped assignment id."""
    if not release_notebook(assignment).exists() or not suite_dir(assignment).is_dir():
        known = ", ".join(i for i in assignment_ids() if suite_dir(i).is_dir())
        raise SystemExit(f"unknown or ungradable assignment {assignment!r}; gradable ones: {known}")


def stub_names(assignment: str) -> list[str]:
    """The graded stubs of an assignment, in notebook order (from its student notebook)."""
    from autograder.notebook import read_notebook, release_plan

    return [c.label for c in release_plan(read_notebook(release_notebook(assignment))) if c.kind == "stub"]


def limits(assignment: str) -> "Limits":
    """The sandbox limits of an assignment: defaults, overridden by its suite's ``limits.json``."""
    import json

    from autograder.sandbox import Limits

    path = suite_dir(assignment) / "limits.json"
    return Limits(**json.loads(path.read_text())) if path.exists() else Limits()


def secret_paths() -> list[Path]:
    """What a sandbox must never read: solutions, suites and samples."""
    roots = dict.fromkeys([REPO, INSTALLED])
    return [root / part for root in roots for part in ("solutions", "autograder/suites", "autograder/samples")]
