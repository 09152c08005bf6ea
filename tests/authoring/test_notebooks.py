"""Every solution notebook runs end to end in fast mode; every student notebook runs up to its first stub."""
from __future__ import annotations

import pytest

from autograder.core import course
from autograder.authoring.nbrun import run_notebook

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

IDS = course.assignment_ids()


@pytest.mark.parametrize("assignment", IDS)
def test_solution_runs_in_fast_mode(assignment, tmp_path):
    report = run_notebook(course.solution_notebook(assignment), {"FAST": True}, timeout=300, cwd=tmp_path)
    assert report.ok, report.describe(assignment)


@pytest.mark.parametrize("assignment", IDS)
def test_student_notebook_setup_runs(assignment, tmp_path):
    report = run_notebook(course.release_notebook(assignment), {"FAST": True}, timeout=300, cwd=tmp_path,
                          until_first_stub=True)
    assert report.ok, report.describe(assignment)
