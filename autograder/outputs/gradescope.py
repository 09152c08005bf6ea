"""The Gradescope autograder bundle: build it here, run it there.

Gradescope unzips the bundle into ``/autograder/source``, runs ``setup.sh`` once
to build the image, then, for each submission, ``run_autograder``, which grades
``/autograder/submission/*.ipynb`` into ``/autograder/results/results.json``.
The bundle holds the course library, the grader, this assignment's hidden
suite, solution and student notebook, and the datasets; setup installs the same
pins as this repository, torch from PyTorch's CPU index.

``results.json`` (Gradescope's "Autograder Specifications"): one test per stub, whose
``visibility`` the bundle fixes (``--visibility``: ``visible``, the default, ``hidden``,
``after_due_date`` or ``after_published``); ``execution_time`` is the whole run's wall time,
from ``run_autograder``'s first line (interpreter, imports, the reference and the suite
included), not just the suite's; the top-level output says how isolated the submission ran.

  python -m autograder.outputs.gradescope bundle ID [--out ZIP] [--visibility V]   build the zip
  python -m autograder.outputs.gradescope grade ID [--visibility V]                what run_autograder runs
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tomllib
import zipfile
from pathlib import Path
from typing import Any

from autograder.core import course
from autograder.core.results import GradeResult, StubResult
from autograder.outputs.text import MESSAGE_CHARS, NOTE_CHARS, cap, points, quoted_lines


GRADESCOPE_NAME = "results.json"
"""Gradescope's result file; the batch writes one per submission too."""
VISIBILITIES = ("visible", "hidden", "after_due_date", "after_published")
"""Gradescope's visibility settings of a test: always shown; never shown (Gradescope still shows the total score:
its documentation keeps ``hidden`` for tests that carry no points); shown once the due date has passed; shown
once the grades are published. With either of the last two, students do not see their total score before."""
DEFAULT_VISIBILITY = "visible"
CPU_TORCH_INDEX = "https://download.pytorch.org/whl/cpu"
"""PyTorch's index of CPU-only wheels: the default index's torch pulls several GB of CUDA libraries."""
STARTED_ENV = "GRADESCOPE_STARTED"
"""Set by ``run_autograder``'s first line (``date +%s.%N``): when the run began, for ``execution_time``."""
ISOLATION = {
    "full": "Isolation: full (the submission ran in a sandbox of its own: no network, a file system that shows "
            "only the course's release and the Python environment, its own processes, an unprivileged user, "
            "resource limits).",
    "user-namespace": "Isolation: user-namespace (the same sandbox, built inside a user namespace: no network, "
                      "a file system that shows only the course's release and the Python environment, its own "
                      "processes, resource limits).",
    "none": "Isolation: none, partial (this container refuses the namespaces the sandbox is built from, so the "
            "submission ran under resource limits, as a user of its own where the grader is root, with the "
            "container's network and the files its modes let every user read).",
}
"""The top-level output's line for each isolation level the sandbox reports."""


def check_visibility(visibility: str) -> str:
    if visibility not in VISIBILITIES:
        raise SystemExit(f"unknown visibility {visibility!r}: one of {', '.join(VISIBILITIES)}")
    return visibility


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


def gradescope_results(result: GradeResult, visibility: str = DEFAULT_VISIBILITY,
                       execution_time: float | None = None) -> dict[str, Any]:
    """Gradescope's ``results.json``: one test entry per stub, with each check listed in its output.

    Every output is plain text (``output_format`` and the tests' formats say so: Gradescope renders
    nothing in it as Markdown or HTML), and a student's text is quoted line by line and cut. ``visibility``
    is every stub's (the top-level output, which says why a submission could not be graded, stays visible);
    ``execution_time`` the run's wall time in seconds (default: the grading's own, ``result.seconds``).
    """
    check_visibility(visibility)
    tests = []
    for number, stub in enumerate(result.stubs, start=1):
        tests.append({
            "name": stub.name, "number": str(number), "score": stub.score, "max_score": stub.max_score,
            "status": "passed" if stub.tests and stub.score == stub.max_score else "failed",
            "output": _stub_output(stub), "output_format": "text", "visibility": visibility,
        })
    seconds = result.seconds if execution_time is None else execution_time
    return {
        "score": result.score, "execution_time": round(seconds, 2), "output": _overall_output(result),
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
    if result.isolation in ISOLATION:  # "unknown" when nothing of the submission ran (no notebook, say)
        parts.append(ISOLATION[result.isolation])
    return "\n".join(parts)

SETUP_SH = """\
#!/usr/bin/env bash
# Gradescope image set-up (Ubuntu base): Python 3.11, EGL for headless MuJoCo, the course's pins
# (torch from PyTorch's CPU index first: the default index's torch pulls several GB of CUDA wheels).
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
.venv/bin/python -m pip install --quiet {torch} --index-url {index}
.venv/bin/python -m pip install --quiet -e .
# Gradescope's containers refuse namespaces: the worker runs as a uid of its own, walled off the hidden
# suites and solutions by their modes alone.
.venv/bin/python -m autograder permissions --assignment {assignment}
"""

RUN_AUTOGRADER = """\
#!/usr/bin/env bash
# Grade the submission of one student into /autograder/results/results.json (tests' visibility: {visibility}).
export GRADESCOPE_STARTED="$(date +%s.%N)"
cd "${{GRADESCOPE_ROOT:-/autograder}}/source"
export PYTHONPATH="$PWD" RLCOURSE_REPO="$PWD"
exec .venv/bin/python -m autograder.outputs.gradescope grade {assignment} --visibility {visibility}
"""


def torch_requirement(pyproject: Path | None = None) -> str:
    """The course's torch pin, as ``pyproject.toml`` states it (``torch==2.13.0``)."""
    data = tomllib.loads(Path(pyproject or course.REPO / "pyproject.toml").read_text())
    pins = [d.replace(" ", "") for d in data["project"]["dependencies"] if d.replace(" ", "").startswith("torch==")]
    if len(pins) != 1:
        raise SystemExit("pyproject.toml pins no torch (torch==X.Y.Z): setup.sh could not install it from the CPU index")
    return pins[0]


def setup_script(assignment: str) -> str:
    """``setup.sh`` of the bundle of ``assignment``."""
    return SETUP_SH.format(torch=torch_requirement(), index=CPU_TORCH_INDEX, assignment=assignment)


def build_bundle(assignment: str, out: Path | None = None, visibility: str = DEFAULT_VISIBILITY) -> Path:
    """Write ``build/gradescope/<id>.zip`` (or ``out``) for ``assignment``; its tests show with ``visibility``."""
    course.check_assignment(assignment)
    check_visibility(visibility)
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
    for path in sorted(course.library_modules(assignment)):  # the library grading it needs, and nothing else
        members.append((path, path.relative_to(repo).as_posix()))
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
        for name, text in (("setup.sh", setup_script(assignment)),
                           ("run_autograder", RUN_AUTOGRADER.format(assignment=assignment, visibility=visibility))):
            info = zipfile.ZipInfo(name)
            info.external_attr = 0o755 << 16
            bundle.writestr(info, text)
    return out


def run_started() -> float:
    """When this grading run began (``time.time()`` seconds): ``run_autograder``'s first line, else this process's
    start as the kernel reports it, else now."""
    now = time.time()
    try:
        started = float(os.environ.get(STARTED_ENV, ""))
        if now - 86400 < started <= now:
            return started
    except ValueError:
        pass
    try:
        with open("/proc/self/stat") as f:
            ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime, in clock ticks since boot
        with open("/proc/stat") as f:
            boot = next(int(line.split()[1]) for line in f if line.startswith("btime "))
        started = boot + ticks / os.sysconf("SC_CLK_TCK")
        if now - 86400 < started <= now + 1:
            return min(started, now)
    except (OSError, ValueError, IndexError, StopIteration):
        pass
    return now


def run(assignment: str, root: Path, visibility: str = DEFAULT_VISIBILITY) -> int:
    """Grade the one submission under ``root/submission`` into ``root/results/results.json``.

    When the grader itself fails, no ``results.json`` is written and the exit status is non-zero:
    Gradescope then shows "The autograder failed to execute correctly" (and the student may
    resubmit), never a score of 0 for a fault that is not theirs.
    """
    from autograder.core.batch import grade_upload
    from autograder.core.results import GraderError

    started = run_started()
    check_visibility(visibility)

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
    tmp.write_text(json.dumps(gradescope_results(result, visibility, time.time() - started), indent=2,
                              ensure_ascii=False))
    os.replace(tmp, results)
    return 0


def _cmd_bundle(args: argparse.Namespace) -> int:
    print(f"wrote {build_bundle(args.assignment, args.out, args.visibility)} (tests' visibility: {args.visibility})")
    return 0


def _cmd_grade(args: argparse.Namespace) -> int:
    """Grade, then leave at once: ``results.json`` is written and closed, and the interpreter's own shutdown
    (torch's, mostly) would add seconds of wall time to every run that ``execution_time`` cannot count."""
    code = run(args.assignment, Path(os.environ.get("GRADESCOPE_ROOT", "/autograder")), args.visibility)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _visibility_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--visibility", choices=VISIBILITIES, default=DEFAULT_VISIBILITY,
                   help="when students see each stub's test: visible (default), hidden (never: the total score "
                        "still shows), after_due_date or after_published (the total score hidden until then too)")


def add_command(sub: argparse._SubParsersAction) -> None:
    """``python -m autograder gradescope ID [--out ZIP] [--visibility V]`` on the course tools' sub-parsers."""
    p = sub.add_parser("gradescope", help="build the Gradescope autograder zip")
    p.add_argument("assignment")
    p.add_argument("--out", type=Path, default=None)
    _visibility_option(p)
    p.set_defaults(fn=_cmd_bundle)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in ("bundle", "grade", "-h", "--help"):
        argv.insert(0, "grade")  # the form of bundles built before the subcommands: ``... gradescope ID``
    parser = argparse.ArgumentParser(prog="python -m autograder.outputs.gradescope", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("bundle", help="build the Gradescope autograder zip")
    p.add_argument("assignment")
    p.add_argument("--out", type=Path, default=None)
    _visibility_option(p)
    p.set_defaults(fn=_cmd_bundle)
    p = sub.add_parser("grade", help="grade $GRADESCOPE_ROOT/submission (default /autograder), as run_autograder does")
    p.add_argument("assignment")
    _visibility_option(p)
    p.set_defaults(fn=_cmd_grade)
    args = parser.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
