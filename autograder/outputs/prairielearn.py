"""PrairieLearn's external-grader route: grade ``/grade/student`` into ``/grade/results/results.json``.

PrairieLearn copies a question's files into a container and runs its entrypoint, which must write
``/grade/results/results.json`` (format: PrairieLearn's "External Grading" page, "Grading results"):
``score`` in [0, 1], ``gradable``, ``message``, ``output`` and a ``tests`` list with ``name``,
``description``, ``points``, ``max_points``, ``message`` and ``output``, within 1 MB.

- A graded submission: one test per hidden test (its stub as the description), the score as a
  fraction of the automatic points.
- An ungradable one (no notebook, not a notebook, a link): ``gradable: false`` with the reason in
  ``format_errors``, PrairieLearn's way of saying the input was invalid (no attempt is used).
- A fault of the grader: ``gradable: false`` and a message that says so; never a score of 0.

``python -m autograder prairielearn ID --root /grade`` is the entrypoint's one command;
:func:`question_files` writes the question (``info.json``, ``question.html``, a README with the assessment's
points) and ``serverFilesCourse/rlcourse-<id>/`` (the entrypoint ``run.sh`` and the instructor-only files), for an
image built from ``docker/grader/Dockerfile`` (docs/instructors.md, "PrairieLearn").
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import uuid
from pathlib import Path
from typing import Any

from autograder.core import course
from autograder.outputs.text import MESSAGE_CHARS, NOTE_CHARS, cap, plain
from autograder.core.results import GRADER_ERROR, UNGRADABLE, GradeResult

RESULTS_BYTES = 1_000_000
"""PrairieLearn's limit on ``results.json``."""
GRADER_FAULT = ("The autograder itself failed on this submission, so it was not graded and no attempt was "
                "used. This is not your fault: tell the course staff, then submit again.")

RUN_SH = """\
#!/usr/bin/env bash
# PrairieLearn entrypoint of {assignment}: grade /grade/student into /grade/results/results.json.
# The image (docker/grader/Dockerfile) holds the kit and its .venv at /opt/rlcourse, without any
# solution or hidden suite; this folder (serverFilesCourse/{folder}/, copied into every grading job)
# holds this assignment's solution, hidden suite and release notebook: the course the grader reads.
set -u
grade="${{PL_GRADE_ROOT:-/grade}}"
mkdir -p "$grade/results"
install="${{RLCOURSE_INSTALL:-/opt/rlcourse}}"
export RLCOURSE_REPO="$grade/serverFilesCourse/{folder}" PYTHONPATH="$install${{PYTHONPATH:+:$PYTHONPATH}}"
cd "$install"
# Where the container refuses namespaces, the worker runs as a uid of its own and file modes are its walls:
# the hidden suite, the solution and the other grading folders readable by their owner only.
chmod 700 "$grade/results" "$grade/student" 2>/dev/null
.venv/bin/python -m autograder permissions --root "$RLCOURSE_REPO" --no-environment >/dev/null 2>&1
# and of the kit's library, only the modules grading {assignment} needs stay readable by others
.venv/bin/python -m autograder permissions --root "$install" --no-environment --assignment {assignment} >/dev/null 2>&1
exec .venv/bin/python -m autograder prairielearn {assignment} --root "$grade"
"""

QUESTION_HTML = """\
<pl-question-panel>
  <p>Upload your completed notebook <code>{assignment}.ipynb</code>. The hidden tests run when you submit.</p>
</pl-question-panel>
<pl-file-upload file-names="{assignment}.ipynb"></pl-file-upload>
<pl-submission-panel>
  <pl-external-grader-results></pl-external-grader-results>
  <pl-file-preview></pl-file-preview>
</pl-submission-panel>
"""


def _test(outcome: Any) -> dict[str, Any]:
    return {"name": cap(plain(outcome.name), 200), "description": f"stub {outcome.stub}",
            "points": outcome.points if outcome.passed else 0.0, "max_points": outcome.points,
            "message": "" if outcome.passed else cap(plain(outcome.message), MESSAGE_CHARS),
            "output": "" if outcome.passed or not outcome.hint else "hint: " + cap(plain(outcome.hint), NOTE_CHARS)}


def prairielearn_results(result: GradeResult) -> dict[str, Any]:
    """``results.json`` for one result (see the module docstring for the three cases)."""
    notes = [cap(plain(note), NOTE_CHARS) for note in result.notes]
    if result.status == GRADER_ERROR:
        return {"gradable": False, "message": GRADER_FAULT, "format_errors": [GRADER_FAULT],
                "output": "\n".join(notes)}
    if result.status == UNGRADABLE:
        reason = cap(plain(result.error or "the submission could not be read"), MESSAGE_CHARS)
        return {"gradable": False, "message": f"This submission could not be graded: {reason}",
                "format_errors": [reason], "output": "\n".join(notes)}
    tests = [_test(t) for stub in result.stubs for t in stub.tests]
    manual = sum(points for _, points in result.manual)
    message = f"Automatic score: {result.score:g} / {result.max_score:g}."
    if manual:
        message += f" Written answers ({manual:g} points) are graded by hand later."
    return {"gradable": True, "score": result.score / result.max_score if result.max_score else 0.0,
            "message": message, "output": "\n".join(notes), "tests": tests}


def _fit(results: dict[str, Any]) -> str:
    """The JSON text, cut to PrairieLearn's 1 MB by shortening test outputs and messages if it must be."""
    text = json.dumps(results, ensure_ascii=False)
    for limit in (400, 100, 0):
        if len(text.encode()) <= RESULTS_BYTES:
            break
        for test in results.get("tests", []):
            test["message"], test["output"] = cap(test["message"], limit), cap(test["output"], limit)
        results["output"] = cap(results.get("output", ""), limit)
        text = json.dumps(results, ensure_ascii=False)
    return text


def write_results(results: dict[str, Any], root: Path) -> Path:
    path = Path(root) / "results" / "results.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(_fit(results), encoding="utf-8")
    os.replace(tmp, path)
    return path


def run(assignment: str, root: Path) -> int:
    """Grade the submission under ``root/student``; always leaves a ``results.json`` (exit 0 when graded)."""
    from autograder.core.batch import grade_upload

    root = Path(root)
    try:
        course.check_assignment(assignment)
        result = grade_upload(assignment, root / "student", hide=[root / "student", root / "results"])
    except (SystemExit, Exception) as err:  # noqa: BLE001 - any fault here (a GraderError, say) is the grader's
        print(f"the autograder failed (not the submission's fault): {err}", file=sys.stderr)
        write_results(prairielearn_results(GradeResult(assignment, "submission", [], [], [], str(err),
                                                       status=GRADER_ERROR)), root)
        return 1
    write_results(prairielearn_results(result), root)
    if result.status == GRADER_ERROR:
        print(f"the autograder failed (not the submission's fault): {result.error}", file=sys.stderr)
        return 1
    return 0


PRAIRIELEARN_MAX_TIMEOUT = 600
"""PrairieLearn's ceiling on ``externalGradingOptions.timeout``, in seconds ("External Grading", ``timeout``)."""
STARTUP_SECONDS = 60
"""What a question's timeout allows beyond the sandbox's time for one submission: the container's start, the
interpreter's imports, the reference built from the solution and the suite collected
(``bench/bench_platform_routes.py`` measures the whole entrypoint on each assignment's untouched sample)."""
QUESTION_NAMESPACE = uuid.UUID("4d1f2ddc-c5a1-4506-8cc7-065b50d21571")
"""The namespace of the questions' UUIDs: ``uuid5(QUESTION_NAMESPACE, "rlcourse/<id>")``, so writing a question
again keeps the UUID PrairieLearn knows it by (a new one would be a new question, its students' scores apart)."""
TOPIC = "Learning from humans"


def question_uuid(assignment: str) -> str:
    """The UUID of ``assignment``'s question: the same every time it is written."""
    return str(uuid.uuid5(QUESTION_NAMESPACE, f"rlcourse/{assignment}"))


def question_timeout(assignment: str) -> int:
    """The question's timeout: the assignment's ``submission_seconds`` plus :data:`STARTUP_SECONDS`.

    Raises ``SystemExit``, saying why and what to change, when that passes PrairieLearn's 600 s: a submission
    that loops until the sandbox stops it would then be killed by PrairieLearn first, and its student would see a
    failed grading instead of a score."""
    seconds = course.limits(assignment).submission_seconds
    source = (f"autograder/suites/{assignment}/limits.json" if (course.suite_dir(assignment) / "limits.json").exists()
              else f"the default: {assignment} has no limits.json")
    needed = math.ceil(seconds + STARTUP_SECONDS)
    if needed > PRAIRIELEARN_MAX_TIMEOUT:
        raise SystemExit(
            f"not written: {assignment} gives a submission up to {seconds:g} s in the sandbox ({source}); with "
            f"{STARTUP_SECONDS} s for start-up its question needs a timeout of {needed} s, over PrairieLearn's "
            f"maximum of {PRAIRIELEARN_MAX_TIMEOUT} s, so a looping submission would be killed by PrairieLearn before "
            f"the grader could score it. Set \"submission_seconds\" to at most "
            f"{PRAIRIELEARN_MAX_TIMEOUT - STARTUP_SECONDS} in {course.suite_dir(assignment) / 'limits.json'} "
            "(every route then grades with it), or grade this assignment with batch or Gradescope.")
    return needed


def automatic_points(assignment: str) -> float:
    """The points of the hidden tests (collected from the suite, not run): the question's ``autoPoints``."""
    import contextlib
    import io

    import pytest

    from autograder.core.grader import UNUSED_PYTEST_PLUGINS, SuitePlugin

    suite = course.suite_dir(assignment)
    plugin = SuitePlugin(None, None, {})
    args = [str(suite), "--collect-only", "-q", "-p", "no:cacheprovider", "--import-mode=importlib", "-c", os.devnull,
            "--rootdir", str(suite), "-o", "python_files=test_*.py", "-W", "ignore::DeprecationWarning",
            *(f"-pno:{name}" for name in UNUSED_PYTEST_PLUGINS)]
    log = io.StringIO()
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        code = pytest.main(args, plugins=[plugin])
    for name in [m for m, mod in sys.modules.items() if str(getattr(mod, "__file__", "")).startswith(str(suite))]:
        del sys.modules[name]
    marked = [marker for marker, _ in plugin.collected if marker]
    if code != pytest.ExitCode.OK or not marked:
        raise SystemExit(f"not written: the hidden suite of {assignment} could not be collected (pytest exit {code}):\n"
                         + log.getvalue()[-2000:])
    return float(sum(float(marker.kwargs["points"]) for marker in marked))


def written_points(assignment: str) -> list[tuple[str, float]]:
    """The written answers graded by hand, ``(grade_id, points)``, from the release notebook."""
    from autograder.core.notebook import manual_cells, read_notebook

    return manual_cells(read_notebook(course.release_notebook(assignment)))


def _number(value: float) -> int | float:
    return int(value) if float(value).is_integer() else value


def _readme(assignment: str, folder: str, image: str, timeout: int, auto: float,
            written: list[tuple[str, float]]) -> str:
    manual = sum(p for _, p in written)
    entry = {"id": assignment, "autoPoints": _number(auto), **({"manualPoints": _number(manual)} if manual else {})}
    limits = course.limits(assignment)
    lines = [
        f"# {assignment} on PrairieLearn (written by `python -m autograder prairielearn {assignment} --question-files`)",
        "",
        f"- `info.json`: external grading in the image `{image}` (build it from the kit with",
        "  `docker build -f docker/grader/Dockerfile -t <account>/rlcourse-grader .` and push it to Docker Hub; it holds",
        "  no solution and no hidden suite), entrypoint",
        f"  `/grade/serverFilesCourse/{folder}/run.sh`, timeout {timeout} s: the {limits.submission_seconds:g} s a",
        f"  submission may spend in the sandbox plus {STARTUP_SECONDS} s for start-up, under PrairieLearn's maximum of",
        f"  {PRAIRIELEARN_MAX_TIMEOUT} s.",
        f"- `serverFilesCourse/{folder}/`: copy it into your course's `serverFilesCourse/`. It holds the solution, the",
        "  hidden suite and the release notebook of this assignment (PrairieLearn copies it into each grading job, never",
        "  to a student); keep the course repository private.",
        f"- The UUID `{question_uuid(assignment)}` is derived from the assignment's id, so writing the question again",
        "  keeps it: PrairieLearn goes on treating it as the same question.",
        "",
        "## Points: automatic and by hand",
        "",
        f"The hidden tests are worth {auto:g} points; the external grader reports their fraction as the score, which",
        "PrairieLearn multiplies by the question's `autoPoints`. Points go in the assessment, not in `info.json`: in",
        "`infoAssessment.json`, list the question as",
        "",
        "```json",
        json.dumps(entry),
        "```",
        "",
    ]
    if written:
        lines += [
            f"The written answers ({manual:g} points: "
            + ", ".join(f"`{gid}` {p:g}" for gid, p in written)
            + ") are graded by hand: `manualPoints`",
            "adds them to the question, and PrairieLearn's manual grading applies to the last submission. Graders",
            "read each student's notebook (the submission panel's file preview, or the assessment's",
            "`<assessment>_files_for_manual_grading.zip` from the Downloads tab, opened in JupyterLab) and give",
            "the points in the manual grading page, or in the `manual_points` column of the scores CSV they upload",
            "(Students tab, \"Upload question scores\"). The automatic score is never changed by that.",
        ]
    else:
        lines.append("This assignment has no written answers: leave `manualPoints` out.")
    return "\n".join(lines) + "\n"


def _copy_tree(source: Path, target: Path) -> None:
    for path in sorted(source.rglob("*")):
        if path.is_file() and not path.is_symlink() and "__pycache__" not in path.parts \
                and not path.name.endswith((".pyc", ".tmp")):
            dest = target / path.relative_to(source)
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, dest)


def question_files(assignment: str, out: Path, image: str = "rlcourse-grader", timeout: int | None = None) -> list[Path]:
    """Write ``assignment``'s PrairieLearn question under ``out`` (a PrairieLearn course's root).

    ``questions/<id>/`` gets ``info.json`` (PrairieLearn's question schema: a stable ``uuid``, ``type``,
    ``title``, ``topic``, external grading with a timeout that fits), ``question.html`` and ``README.md`` (the
    assessment entry, ``autoPoints`` and ``manualPoints``, and how the written answers are graded by hand);
    ``serverFilesCourse/rlcourse-<id>/`` gets the entrypoint ``run.sh`` and the instructor-only files grading
    needs. Refuses, before writing anything, an assignment whose limits cannot fit PrairieLearn's timeout."""
    course.check_assignment(assignment)
    needed = question_timeout(assignment)
    if timeout is None:
        timeout = needed
    elif not needed <= timeout <= PRAIRIELEARN_MAX_TIMEOUT:
        raise SystemExit(f"not written: a timeout of {timeout} s must lie between the {needed} s {assignment} needs "
                         f"and PrairieLearn's maximum of {PRAIRIELEARN_MAX_TIMEOUT} s")
    auto, written = automatic_points(assignment), written_points(assignment)
    out = Path(out)
    folder = f"rlcourse-{assignment}"
    server = out / "serverFilesCourse" / folder
    if server.exists():
        shutil.rmtree(server)  # this folder is the course of one assignment: nothing of an earlier version may stay
    for source, target in ((course.solution_notebook(assignment).parent, f"solutions/{assignment}"),
                           (course.suite_dir(assignment), f"autograder/suites/{assignment}"),
                           (course.release_notebook(assignment).parent, f"assignments/{assignment}")):
        _copy_tree(source, server / target)
    if course.common_helpers().is_file():
        shutil.copyfile(course.common_helpers(), server / "autograder" / "suites" / course.common_helpers().name)
    run_sh = server / "run.sh"
    run_sh.write_text(RUN_SH.format(assignment=assignment, folder=folder))
    run_sh.chmod(0o755)
    question = out / "questions" / assignment
    question.mkdir(parents=True, exist_ok=True)
    html = question / "question.html"
    html.write_text(QUESTION_HTML.format(assignment=assignment))
    readme = question / "README.md"
    readme.write_text(_readme(assignment, folder, image, timeout, auto, written))
    info = question / "info.json"
    info.write_text(json.dumps({
        "uuid": question_uuid(assignment), "type": "v3", "title": f"{assignment}: upload your notebook",
        "topic": TOPIC, "tags": ["rlcourse", assignment], "singleVariant": True, "gradingMethod": "External",
        "externalGradingOptions": {"image": image, "serverFilesCourse": [f"{folder}/"],
                                   "entrypoint": f"/grade/serverFilesCourse/{folder}/run.sh", "timeout": timeout}},
        indent=2) + "\n")
    return [run_sh, html, readme, info]
