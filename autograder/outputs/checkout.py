"""One checkout at a time: refuse to grade when the sandbox would run another checkout's code than this grader.

A virtual environment with the kit installed in editable mode points at the checkout it was made
in. Grading another copy of the course with it (``/a/.venv/bin/python -m autograder batch ...`` run
in ``/b``) runs ``/b``'s grader and suites, while workers started from ``/`` would import
``autograder.sandbox`` and ``rlcourse`` from ``/a``. The zygote therefore starts with the grader's own
checkout first on ``PYTHONPATH`` (:func:`autograder.core.supervisor.zygote_environment`), so that both
import one checkout; :func:`checkout_problem` checks that it does, asking a fresh interpreter started
as the workers are (same executable, the zygote's environment, from ``/``) where it finds both packages,
and refuses, naming both paths, if that ever fails.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from autograder.core.supervisor import zygote_environment

_FIND = ("import importlib.util, json\n"
         "out = {}\n"
         "for name in ('autograder', 'rlcourse'):\n"
         "    spec = importlib.util.find_spec(name)\n"
         "    out[name] = None if spec is None or not spec.submodule_search_locations else "
         "list(spec.submodule_search_locations)[0]\n"
         "print(json.dumps(out))\n")


def worker_packages() -> dict[str, Path | None]:
    """Where an interpreter started as the sandbox's workers are (this executable, this environment, from ``/``)
    finds the ``autograder`` and ``rlcourse`` packages (found, not imported)."""
    done = subprocess.run([sys.executable, "-c", _FIND], cwd="/", env=zygote_environment(), capture_output=True,
                          text=True, timeout=60)
    if done.returncode != 0:
        raise SystemExit(f"cannot tell where the sandbox imports the grader from:\n{done.stderr[-1000:]}")
    found = json.loads(done.stdout.strip().splitlines()[-1])
    return {name: Path(path).resolve() if path else None for name, path in found.items()}


def checkout_problem(course_root: Path | None = None, found: dict[str, Path | None] | None = None) -> str | None:
    """Why grading here would mix two checkouts (naming both paths), or None when it would not.

    Refused: the workers would import ``autograder`` from another folder than this process's; or the course
    being graded (``course_root``, default the course ``autograder.core.course`` grades) is a checkout of the
    kit with its own ``rlcourse/`` and the workers would import ``rlcourse`` from elsewhere.
    """
    import autograder
    from autograder.core import course

    found = worker_packages() if found is None else found
    here = Path(autograder.__file__).resolve().parent
    root = Path(course_root or course.REPO).resolve()
    fix = ("Use this checkout's own environment (make setup here), install this checkout into it "
           f"(pip install -e {here.parent}), or put {here.parent} first on PYTHONPATH.")
    worker = found.get("autograder")
    if worker != here:
        return (f"refused: this grader runs from {here}, but the sandbox's workers (started from / with "
                f"{sys.executable} and this environment's PYTHONPATH) would import the grader's sandbox from "
                f"{worker or 'nowhere'}: the environment is installed from another checkout. {fix}")
    library = found.get("rlcourse")
    if (root / "rlcourse" / "__init__.py").is_file() and library != (root / "rlcourse").resolve():
        return (f"refused: the course being graded is {root}, with its own rlcourse, but the sandbox's workers "
                f"would import rlcourse from {library or 'nowhere'}. {fix}")
    return None


def require_one_checkout(course_root: Path | None = None) -> None:
    """Exit with :func:`checkout_problem`'s message when there is one (for the commands that grade)."""
    problem = checkout_problem(course_root)
    if problem:
        raise SystemExit(problem)
