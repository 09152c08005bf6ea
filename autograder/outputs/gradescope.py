"""The Gradescope autograder bundle: build it here, run it there.

Gradescope unzips the bundle into ``/autograder/source``, runs ``setup.sh`` once
to build the image, then, for each submission, ``run_autograder``, which grades
``/autograder/submission/*.ipynb`` into ``/autograder/results/results.json``.
The bundle holds the course library, the grader, this assignment's hidden
suite, solution and student notebook, and the datasets; setup installs the same
pins as this repository.
"""
from __future__ import annotations

import json
import os
import sys
import zipfile
from pathlib import Path

from typing import Any

from autograder.core import course
from autograder.core.results import GradeResult, StubResult
from autograder.outputs.text import MESSAGE_CHARS, NOTE_CHARS, cap, points, quoted_lines


GRADESCOPE_NAME = "results.json"
"""Gradescope's result file; the batch writes one per submission too."""


def _stub_output(stub: StubResult) -> str:
    lines = []
    for test in stub.tests:
        mark = "✓" if test.passed else "✗"
        lines.append(f"{mark} {test.name} ({points(test.points if test.passed else 0)}/{points(test.points)})")
        if not test.passed:
            lines += quoted_lines(cap(test.message, MESSAGE_CHARS))
            if test.hint:
                lines.append(f"    hint: {test.hint}")
    return "\n".join(lines)


def gradescope_results(result: GradeResult) -> dict[str, Any]:
    """Gradescope's ``results.json``: one test entry per stub, with each check listed in its output.

    Every output is plain text (``output_format`` and the tests' formats say so: Gradescope renders
    nothing in it as Markdown or HTML), and a student's text is quoted line by line and cut.
    """
    tests = []
    for number, stub in enumerate(result.stubs, start=1):
        tests.append({
            "name": stub.name, "number": str(number), "score": stub.score, "max_score": stub.max_score,
            "status": "passed" if stub.tests and stub.score == stub.max_score else "failed",
            "output": _stub_output(stub), "output_format": "text", "visibility": "visible",
        })
    return {
        "score": result.score, "execution_time": round(result.seconds, 2), "output": _overall_output(result),
        "output_format": "text", "test_output_format": "text", "test_name_format": "text",
        "visibility": "visible", "stdout_visibility": "hidden", "tests": tests,
    }


def _overall_output(result: GradeResult) -> str:
    parts = []
    if result.error:
        parts.append("This submission could not be graded automatically:")
        parts += quoted_lines(cap(result.error, MESSAGE_CHARS))
    for note in result.notes:
        parts.append("Note:")
        parts += quoted_lines(cap(note, NOTE_CHARS))
    if result.manual:
        total = sum(p for _, p in result.manual)
        parts.append(f"Written answers graded by hand later ({points(total)} points): "
                     + ", ".join(f"{gid} ({points(p)})" for gid, p in result.manual))
    return "\n".join(parts)

SETUP_SH = """\
#!/usr/bin/env bash
# Gradescope image set-up (Ubuntu base): Python 3.11, EGL for headless MuJoCo, the course's pins.
set -euo pipefail
cd /autograder/source
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq software-properties-common
add-apt-repository -y ppa:deadsnakes/ppa >/dev/null 2>&1 || true
apt-get update -qq
apt-get install -y -qq python3.11 python3.11-venv libegl1 libegl-mesa0 libgl1-mesa-dri libgles2
python3.11 -m venv .venv
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e .
"""

RUN_AUTOGRADER = """\
#!/usr/bin/env bash
# Grade the submission of one student into /autograder/results/results.json.
cd "${{GRADESCOPE_ROOT:-/autograder}}/source"
export PYTHONPATH="$PWD" RLCOURSE_REPO="$PWD"
exec .venv/bin/python -m autograder.outputs.gradescope {assignment}
"""


def build_bundle(assignment: str, out: Path | None = None) -> Path:
    """Write ``build/gradescope/<id>.zip`` (or ``out``) for ``assignment``."""
    course.check_assignment(assignment)
    out = Path(out or course.REPO / "build" / "gradescope" / f"{assignment}.zip")
    out.parent.mkdir(parents=True, exist_ok=True)
    repo = course.REPO
    members: list[tuple[Path, str]] = []

    def add_tree(folder: Path, prefix: str) -> None:
        for path in sorted(folder.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and not path.name.endswith((".pyc", ".tmp")):
                members.append((path, f"{prefix}/{path.relative_to(folder).as_posix()}"))

    for name in ("pyproject.toml", "README.md"):
        members.append((repo / name, name))
    add_tree(repo / "rlcourse", "rlcourse")
    for path in sorted((repo / "autograder").rglob("*.py")):
        if "suites" not in path.relative_to(repo / "autograder").parts and "__pycache__" not in path.parts:
            members.append((path, path.relative_to(repo).as_posix()))
    add_tree(course.suite_dir(assignment), f"autograder/suites/{assignment}")
    if course.common_helpers().is_file():
        members.append((course.common_helpers(), "autograder/suites/sandbox_common.py"))
    add_tree(course.solution_notebook(assignment).parent, f"solutions/{assignment}")
    add_tree(course.release_notebook(assignment).parent, f"assignments/{assignment}")
    if (repo / "datasets").is_dir():
        add_tree(repo / "datasets", "datasets")
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as bundle:
        for path, name in members:
            bundle.write(path, name)
        for name, text in (("setup.sh", SETUP_SH), ("run_autograder", RUN_AUTOGRADER.format(assignment=assignment))):
            info = zipfile.ZipInfo(name)
            info.external_attr = 0o755 << 16
            bundle.writestr(info, text)
    return out


def run(assignment: str, root: Path) -> int:
    """Grade the one submission under ``root/submission`` into ``root/results/results.json``.

    When the grader itself fails, no ``results.json`` is written and the exit status is non-zero:
    Gradescope then shows "The autograder failed to execute correctly" (and the student may
    resubmit), never a score of 0 for a fault that is not theirs.
    """
    from autograder.core.batch import grade_upload
    from autograder.outputs.gradescope import gradescope_results
    from autograder.core.results import GraderError

    results = root / "results" / "results.json"
    results.parent.mkdir(parents=True, exist_ok=True)
    results.unlink(missing_ok=True)
    try:
        result = grade_upload(assignment, root / "submission")
    except GraderError as err:
        print(f"the autograder failed (not the submission's fault): {err}", file=sys.stderr)
        return 1
    if not result.has_score:
        print(f"the autograder failed (not the submission's fault): {result.error}", file=sys.stderr)
        return 1
    tmp = results.with_suffix(".tmp")
    tmp.write_text(json.dumps(gradescope_results(result), indent=2, ensure_ascii=False))
    os.replace(tmp, results)
    return 0


if __name__ == "__main__":
    sys.exit(run(sys.argv[1], Path(os.environ.get("GRADESCOPE_ROOT", "/autograder"))))
