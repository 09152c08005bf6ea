"""``python -m autograder new ID`` makes an assignment the whole kit accepts (issue 33): in a copy of the
course, the new skeleton passes the fast tests that read the whole course and its own slow ones (its notebook
runs, its samples grade as their expected.json says, its trivial answers earn nothing)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow

NEW = "hw9_example"
LEFT_OUT = (".venv", ".git", "build", "lectures/_build", "__pycache__", ".pytest_cache")
COURSE_WIDE = ("tests/authoring", "tests/lectures", "tests/test_readme.py", "tests/test_notebook_budgets.py",
               "tests/test_numbers_pages.py", "tests/test_packaging.py", "tests/core/test_given_code.py",
               "tests/core/test_suite_helpers.py", "tests/core/test_adversarial_suites.py",
               "tests/outputs/test_prairielearn.py")
"""The fast tests that read the whole course (every notebook, suite, lecture and page): the ones a new assignment can
break. The rest test the grader's machinery on the fixture course, which a new assignment does not touch."""


def _copy_course(target: Path) -> None:
    """The working tree (what a contributor has), without the environment, history and build outputs."""
    def left_out(folder: str, names: list[str]) -> set[str]:
        here = Path(folder).relative_to(REPO)
        return {n for n in names if n in LEFT_OUT or (here / n).as_posix() in LEFT_OUT}

    shutil.copytree(REPO, target, symlinks=True, ignore=left_out)


def test_new_writes_an_assignment_that_passes(tmp_path):
    copy = tmp_path / "course copy"
    _copy_course(copy)
    env = {**os.environ, "PYTHONPATH": str(copy), "RLCOURSE_REPO": str(copy),
           "PATH": f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}"}
    done = subprocess.run([sys.executable, "-m", "autograder", "new", NEW, "--title", "an example"], cwd=copy,
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    for path in (f"solutions/{NEW}/{NEW}.ipynb", f"assignments/{NEW}/{NEW}.ipynb", f"autograder/suites/{NEW}",
                 f"autograder/samples/{NEW}/expected.json", f"autograder/suites/{NEW}/trivial_answers.py"):
        assert (copy / path).exists(), path
    again = subprocess.run([sys.executable, "-m", "autograder", "new", NEW], cwd=copy, env=env,
                           capture_output=True, text=True, timeout=600)
    assert again.returncode != 0 and "never overwrites" in again.stderr
    own = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", NEW, "tests"],
                         cwd=copy, env=env, capture_output=True, text=True, timeout=1800)
    assert own.returncode == 0, own.stdout[-4000:]
    summary = own.stdout.strip().splitlines()[-1]
    assert int(summary.split(" passed")[0].split()[-1]) >= 4, f"the new assignment's own tests did not run: {summary}"
    assert (copy / f"autograder/suites/{NEW}/limits.json").exists(), "new wrote no per-test limits"
    fast = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "not slow", "-x",
                           *COURSE_WIDE], cwd=copy, env=env, capture_output=True, text=True, timeout=1800)
    assert fast.returncode == 0, fast.stdout[-4000:]

