"""Student notebooks and the student release: in sync with solutions, and leak-free."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import sysconfig

import pytest

from autograder.core import course
from autograder.authoring.release import build_student_release, find_leaks, generate_assignments, notebook_signature
from conftest import REPO

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it


def test_committed_student_notebooks_equal_a_fresh_regeneration(tmp_path):
    ids = course.assignment_ids()
    generate_assignments(ids, release_dir=tmp_path)
    for assignment in ids:
        committed = course.release_notebook(assignment)
        assert committed.exists(), f"{committed} is missing: run `make assignments`"
        fresh = tmp_path / assignment / f"{assignment}.ipynb"
        assert notebook_signature(committed) == notebook_signature(fresh), \
            f"{committed} is out of date with solutions/: run `make assignments`"


def test_student_notebooks_carry_no_solutions_markers_or_outputs():
    assert find_leaks(REPO / "assignments") == []


def test_leak_detection_catches_markers_outputs_and_instructor_folders(tmp_path):
    (tmp_path / "solutions").mkdir()
    (tmp_path / "datasets" / "scripts").mkdir(parents=True)
    (tmp_path / "a.py").write_text("### BEGIN SOLUTION\n")
    problems = find_leaks(tmp_path)
    assert any("solutions/" in p for p in problems) and any("a.py" in p for p in problems)
    assert any("datasets/scripts/" in p for p in problems)


def test_student_release_is_clean_and_hw0_runs_there(tmp_path):
    out = build_student_release(tmp_path / "release")
    names = {p.name for p in out.iterdir()}
    assert names >= {"assignments", "rlcourse", "datasets", "README.md", "pyproject.toml"}
    assert not (out / "solutions").exists() and not (out / "autograder").exists()
    assert not list(out.rglob("test_*.py")) and not list(out.rglob("expected.json"))
    assert find_leaks(out) == []
    assert (out / "datasets" / "MANIFEST.json").exists() and not (out / "datasets" / "scripts").exists()
    # No released library code defines a function or class named like a stub of any assignment.
    stubs = {name for assignment in course.assignment_ids() for name in course.stub_names(assignment)}
    for path in out.rglob("*.py"):
        defined = set(re.findall(r"^\s*(?:def|class)\s+(\w+)", path.read_text(), flags=re.M))
        assert not defined & stubs, f"{path.relative_to(out)} defines {sorted(defined & stubs)}, which students write"
    assert "autograder*" not in (out / "pyproject.toml").read_text()  # the package list is rlcourse only
    # A Python that sees the installed stack but not this repository's editable rlcourse, so that the
    # release's own copy is the one a student's notebook imports.
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    (site / "stack.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = dict(os.environ, PYTHONPATH=f"{out}{os.pathsep}{REPO}")  # autograder (for the runner) from the repo
    where = subprocess.run([str(venv / "bin/python"), "-c", "import rlcourse; print(rlcourse.__file__)"], env=env, cwd=tmp_path,
                           capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(out)), f"the release's own rlcourse should be imported, got {where}"
    run = subprocess.run([str(venv / "bin/python"), "-m", "autograder", "run",
                          str(out / "assignments/hw0_setup/hw0_setup.ipynb"), "-p", "FAST=True", "--until-first-stub",
                          "--timeout", "300"], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=400)
    assert run.returncode == 0, run.stdout + run.stderr[-2000:]


def test_a_solution_file_in_the_release_is_refused(tmp_path, monkeypatch):
    import autograder.authoring.release as release

    monkeypatch.setattr(release.course, "STUDENT_RELEASE", (*release.course.STUDENT_RELEASE, "solutions"))
    with pytest.raises(SystemExit, match="leak"):
        build_student_release(tmp_path / "bad")


def test_make_assignments_writes_the_samples_again_with_the_release(tmp_path):
    """A solution edited and released with `make assignments` leaves no sample from the older release behind (the
    demo would grade setup cells a student no longer has); an assignment without samples gets none."""
    import shutil

    from conftest import FIXTURE_COURSE

    copy = tmp_path / "course"
    shutil.copytree(FIXTURE_COURSE, copy)
    shutil.copy(REPO / "nbgrader_config.py", copy / "nbgrader_config.py")  # the fixture's reaches up to it
    complete = copy / "autograder/samples/ex/complete.ipynb"
    fresh = complete.read_text()
    complete.write_text(fresh.replace("import numpy as np", "import numpy as np  # an older release"))
    env = {**os.environ, "RLCOURSE_REPO": str(copy), "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}"}
    done = subprocess.run([sys.executable, "-m", "autograder", "assignments"], cwd=copy, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert complete.read_text() == fresh, "the sample was not written again from the release"
    assert "samples/ex" in done.stdout and not (copy / "autograder/samples/fx").exists()
