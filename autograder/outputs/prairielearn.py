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
:func:`question_files` writes the ``run.sh`` and ``info.json`` a question needs (README, "PrairieLearn").
"""
from __future__ import annotations

import json
import os
import sys
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
# PrairieLearn entrypoint: grade /grade/student into /grade/results/results.json.
# The image has the course kit installed at $RLCOURSE_REPO (default /opt/rlcourse), as in README.
mkdir -p /grade/results
cd "${{RLCOURSE_REPO:-/opt/rlcourse}}"
exec .venv/bin/python -m autograder prairielearn {assignment} --root /grade
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


def question_files(assignment: str, out: Path, image: str = "rlcourse-grader", timeout: int = 600) -> list[Path]:
    """Write a question's ``info.json`` (external grading on) and the entrypoint ``run.sh`` under ``out``."""
    course.check_assignment(assignment)
    out = Path(out)
    server = out / "serverFilesCourse" / "rlcourse"
    server.mkdir(parents=True, exist_ok=True)
    run_sh = server / f"run_{assignment}.sh"
    run_sh.write_text(RUN_SH.format(assignment=assignment))
    run_sh.chmod(0o755)
    question = out / "questions" / assignment
    question.mkdir(parents=True, exist_ok=True)
    html = question / "question.html"
    html.write_text(QUESTION_HTML.format(assignment=assignment))
    info = question / "info.json"
    info.write_text(json.dumps({
        "title": f"{assignment}: upload your notebook", "topic": "Learning from humans", "type": "v3",
        "singleVariant": True, "gradingMethod": "External",
        "externalGradingOptions": {"enabled": True, "image": image, "serverFilesCourse": ["rlcourse/"],
                                   "entrypoint": f"/grade/serverFilesCourse/rlcourse/run_{assignment}.sh",
                                   "timeout": timeout}}, indent=2) + "\n")
    return [run_sh, html, info]
