"""PrairieLearn's external-grader route: results.json in its documented format, and a grader fault never a 0;
the question's info.json against PrairieLearn's schema, its timeout, its points; the grading image's Dockerfile;
and a question graded end to end as PrairieLearn lays a job out, by an image tree built from that Dockerfile."""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
import uuid
from pathlib import Path

import pytest

from autograder.core import course
from autograder.outputs import prairielearn
from autograder.core.results import GRADER_ERROR, GradeResult, GraderError, StubResult
from autograder.core.results import TestOutcome as Outcome
from conftest import REPO

SAMPLES = REPO / "autograder/samples/hw0_setup"


def check_format(results: dict) -> None:
    """PrairieLearn's "Grading results": score in [0, 1] when gradable; tests with points <= max_points; < 1 MB."""
    assert len(json.dumps(results).encode()) <= prairielearn.RESULTS_BYTES
    assert isinstance(results.get("gradable", True), bool)
    if results.get("gradable", True):
        assert 0.0 <= results["score"] <= 1.0
        for test in results.get("tests", []):
            assert {"name", "points", "max_points"} <= set(test)
            assert 0 <= test["points"] <= test["max_points"]
            assert all(isinstance(test.get(k, ""), str) for k in ("name", "description", "message", "output"))
    else:
        assert "score" not in results, "an ungraded submission carries no score at all"
        assert results["format_errors"] and results["message"]


def _result(status: str = "graded", error: str | None = None) -> GradeResult:
    tests = [Outcome("shape", "f", 2.0, True), Outcome("values", "f", 3.0, False, "off by one\x1b[31m", "the sum")]
    return GradeResult("hw0_setup", "s", [StubResult("f", tests)], [("written", 4.0)], ["note"], error, status=status)


def test_a_graded_result_is_a_fraction_with_one_test_per_hidden_test():
    results = prairielearn.prairielearn_results(_result())
    check_format(results)
    assert results["gradable"] is True and results["score"] == pytest.approx(2 / 5)
    assert [(t["points"], t["max_points"]) for t in results["tests"]] == [(2.0, 2.0), (0.0, 3.0)]
    assert "\x1b" not in results["tests"][1]["message"] and "off by one" in results["tests"][1]["message"]
    assert results["tests"][1]["output"] == "hint: the sum"
    assert "graded by hand" in results["message"]


def test_a_grader_fault_is_not_gradable_and_never_a_zero():
    results = prairielearn.prairielearn_results(_result(GRADER_ERROR, "the sandbox could not start"))
    check_format(results)
    assert results["gradable"] is False and "not your fault" in results["message"]
    ungradable = prairielearn.prairielearn_results(_result("ungradable", "not a notebook"))
    check_format(ungradable)
    assert ungradable["gradable"] is False and "not a notebook" in ungradable["format_errors"][0]


def test_huge_messages_are_cut_to_the_size_limit():
    result = _result()
    result.stubs[0].tests = [Outcome(f"t{i}", "f", 1.0, False, "x" * 5000, "y" * 5000) for i in range(600)]
    text = prairielearn._fit(prairielearn.prairielearn_results(result))
    assert len(text.encode()) <= prairielearn.RESULTS_BYTES
    check_format(json.loads(text))


SCHEMA = REPO / "tests/fixtures/schemas/prairielearn_infoQuestion.json"
DOCKERFILE = REPO / "docker/grader/Dockerfile"
FITS = [a for a in course.assignment_ids()
        if course.limits(a).submission_seconds + prairielearn.STARTUP_SECONDS <= prairielearn.PRAIRIELEARN_MAX_TIMEOUT]
QUICK = "hw5_lm_alignment"
"""A question that fits and grades in seconds: the one the quick tests write."""


def schema_errors(info: dict) -> list[str]:
    """What PrairieLearn's question schema (the vendored subset) says is wrong with ``info``: validated by jsonschema
    (nbformat's dependency, so always installed with the kit), plus the deprecated properties it marks."""
    import jsonschema

    schema = json.loads(SCHEMA.read_text())
    errors = [f"{'/'.join(map(str, e.path)) or '(top)'}: {e.message}"
              for e in jsonschema.Draft7Validator(schema).iter_errors(info)]

    def deprecated(value: dict, spec: dict, where: str) -> None:
        for key, sub in value.items():
            part = spec.get("properties", {}).get(key, {})
            if part.get("deprecated"):
                errors.append(f"{where}{key}: deprecated")
            if isinstance(sub, dict) and part.get("type") == "object":
                deprecated(sub, part, f"{where}{key}/")

    deprecated(info, schema, "")
    return errors


def test_the_schema_check_catches_what_prairielearn_refuses():
    """The check can fail: the question this kit wrote before (no uuid, the deprecated 'enabled') and bad types."""
    old = {"title": "hw0", "topic": "t", "type": "v3", "gradingMethod": "External",
           "externalGradingOptions": {"enabled": True, "image": "img", "timeout": 600}}
    errors = schema_errors(old)
    assert any("'uuid' is a required property" in e for e in errors), errors
    assert any("enabled: deprecated" in e for e in errors), errors
    bad = {"uuid": "not-a-uuid", "type": "v4", "title": 1, "topic": "t", "colour": "red",
           "externalGradingOptions": {"timeout": "600"}}
    assert len(schema_errors(bad)) >= 6, schema_errors(bad)


def _check_question(assignment: str, out: Path) -> dict:
    files = prairielearn.question_files(assignment, out)
    info = json.loads((out / "questions" / assignment / "info.json").read_text())
    assert schema_errors(info) == []
    assert info["gradingMethod"] == "External" and info["singleVariant"] is True
    options = info["externalGradingOptions"]
    timeout = options["timeout"]
    assert isinstance(timeout, int) and timeout <= prairielearn.PRAIRIELEARN_MAX_TIMEOUT
    assert timeout >= course.limits(assignment).submission_seconds + prairielearn.STARTUP_SECONDS
    folder = f"rlcourse-{assignment}"
    assert options["serverFilesCourse"] == [f"{folder}/"]
    assert options["entrypoint"] == f"/grade/serverFilesCourse/{folder}/run.sh"
    run_sh = out / "serverFilesCourse" / folder / "run.sh"
    assert run_sh in files and os.access(run_sh, os.X_OK)
    server = out / "serverFilesCourse" / folder
    for needed in (f"solutions/{assignment}/{assignment}.ipynb", f"assignments/{assignment}/{assignment}.ipynb",
                   f"autograder/suites/{assignment}"):
        assert (server / needed).exists(), needed
    assert not any(p.name == "__pycache__" for p in server.rglob("*"))
    # The same question, written again, keeps its UUID; another assignment's differs.
    again = prairielearn.question_files(assignment, out)
    assert json.loads(again[-1].read_text())["uuid"] == info["uuid"] == prairielearn.question_uuid(assignment)
    assert uuid.UUID(info["uuid"]).version == 5
    return info


def test_a_question_passes_prairielearn_schema_with_a_timeout_that_fits(tmp_path):
    info = _check_question(QUICK, tmp_path)
    assert info["uuid"] != prairielearn.question_uuid("hw0_setup")
    readme = (tmp_path / "questions" / QUICK / "README.md").read_text()
    entry = json.loads(re.search(r"```json\n(.*)\n```", readme).group(1))
    written = prairielearn.written_points(QUICK)
    assert written, "the quick question's assignment has written answers: manualPoints is what is checked"
    assert entry == {"id": QUICK, "autoPoints": prairielearn.automatic_points(QUICK),
                     "manualPoints": sum(p for _, p in written)}
    assert "manual grading" in readme and "manual_points" in readme


@pytest.mark.slow
@pytest.mark.parametrize("assignment", course.assignment_ids())
def test_every_question_fits_or_is_refused_before_anything_is_written(assignment, tmp_path):
    if assignment in FITS:
        _check_question(assignment, tmp_path)
        return
    with pytest.raises(SystemExit) as refusal:
        prairielearn.question_files(assignment, tmp_path)
    message = str(refusal.value)
    assert "600" in message and "submission_seconds" in message and "limits.json" in message, message
    assert not any(tmp_path.iterdir()), "nothing is written for a question that cannot fit"


def test_a_timeout_asked_for_must_fit_too(tmp_path):
    needed = prairielearn.question_timeout(QUICK)
    for timeout in (needed - 1, prairielearn.PRAIRIELEARN_MAX_TIMEOUT + 1):
        with pytest.raises(SystemExit):
            prairielearn.question_files(QUICK, tmp_path, timeout=timeout)
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------ the grading image

def _copies() -> list[tuple[list[str], str]]:
    """The Dockerfile's COPY instructions: (sources, destination)."""
    out = []
    for line in DOCKERFILE.read_text().splitlines():
        if line.startswith("COPY "):
            *sources, dest = shlex.split(line)[1:]
            assert not any(s.startswith("--") for s in sources), line
            out.append((sources, dest))
    return out


def test_the_dockerfile_builds_the_kit_with_cpu_torch_and_no_solution():
    text = DOCKERFILE.read_text()
    base = re.search(r"^FROM (\S+)", text, re.M).group(1)
    python = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["requires-python"]
    assert base.startswith("python:3.11") and ">=3.11" in python, (base, python)
    from autograder.outputs.gradescope import CPU_TORCH_INDEX, torch_requirement

    torch = re.search(r"pip install (torch==\S+) --index-url (\S+)", text)
    assert torch and torch.group(1) == torch_requirement() and torch.group(2) == CPU_TORCH_INDEX
    assert text.index(torch.group(0)) < text.index("pip install -e ."), "torch must come first, from the CPU index"
    # The entrypoint run.sh calls: /opt/rlcourse/.venv/bin/python -m autograder prairielearn ...
    assert "WORKDIR /opt/rlcourse" in text and "python -m venv .venv" in text
    run_sh = prairielearn.RUN_SH.format(assignment=QUICK, folder=f"rlcourse-{QUICK}")
    assert 'install="${RLCOURSE_INSTALL:-/opt/rlcourse}"' in run_sh and 'cd "$install"' in run_sh
    assert f"exec .venv/bin/python -m autograder prairielearn {QUICK}" in run_sh
    copied = {source for sources, _ in _copies() for source in sources}
    forbidden = ("solutions", "autograder/suites", "autograder/samples", ".", "autograder", "datasets",
                 *course.INSTRUCTOR_ONLY)
    assert not copied & set(forbidden), copied & set(forbidden)
    assert not any(c.startswith(("solutions", "autograder/suites", "autograder/samples", "datasets/scripts"))
                   for c in copied)
    # Every room and module of the grader, and every data folder but the instructor's, is in the image.
    rooms = {f"autograder/{p.name}" for p in (REPO / "autograder").iterdir()
             if (p.is_dir() and (p / "__init__.py").exists()) or p.suffix == ".py"}
    rooms -= {"autograder/suites", "autograder/samples"}
    data = {f"datasets/{p.name}" for p in (REPO / "datasets").iterdir() if not p.name.startswith(".")}
    data -= set(course.INSTRUCTOR_ONLY)
    assert rooms | data | {"rlcourse", "assignments", "pyproject.toml", "README.md"} <= copied, \
        (rooms | data) - copied


def _image_tree(target: Path) -> Path:
    """What the Dockerfile's COPY lines put in /opt/rlcourse, built here (the environment: this one's)."""
    for sources, dest in _copies():
        for source in sources:
            src = REPO / source
            # Docker's rules: a folder's contents go into the destination; a file goes into it when it ends in "/".
            where = target / dest / src.name if src.is_file() and dest.endswith("/") else target / dest
            if src.is_dir():
                shutil.copytree(src, where, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            else:
                where.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(src, where)
    os.symlink(Path(sys.prefix), target / ".venv")
    return target


def _grade(run_sh: Path, grade: Path, install: Path) -> tuple[int, dict]:
    done = subprocess.run(["bash", str(run_sh)], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PL_GRADE_ROOT=str(grade), RLCOURSE_INSTALL=str(install)))
    return done.returncode, json.loads((grade / "results" / "results.json").read_text())


@pytest.mark.slow
def test_a_question_grades_in_a_job_laid_out_as_prairielearn_lays_it_out(tmp_path):
    """The question's files copied where PrairieLearn copies them, run by its run.sh in a tree built from the
    Dockerfile (which holds no solution): the score is the automatic points' fraction, as the README states."""
    pl_course = tmp_path / "pl-course"
    prairielearn.question_files(QUICK, pl_course)
    install = _image_tree(tmp_path / "opt" / "rlcourse")
    assert not (install / "solutions").exists() and not (install / "autograder" / "suites").exists()
    grade = tmp_path / "grade"
    shutil.copytree(pl_course / "serverFilesCourse", grade / "serverFilesCourse")
    (grade / "student").mkdir()
    shutil.copy(course.samples_dir(QUICK) / "partial.ipynb", grade / "student" / f"{QUICK}.ipynb")
    run_sh = grade / "serverFilesCourse" / f"rlcourse-{QUICK}" / "run.sh"
    code, results = _grade(run_sh, grade, install)
    assert code == 0, results
    check_format(results)
    auto = prairielearn.automatic_points(QUICK)
    assert sum(t["max_points"] for t in results["tests"]) == auto
    expected = json.loads((course.samples_dir(QUICK) / "expected.json").read_text())["partial"]
    full = {name for name, verdict in expected.items() if verdict == "full"}
    earned = sum(t["points"] for t in results["tests"] if t["description"].removeprefix("stub ") in full)
    assert results["score"] == pytest.approx(earned / auto) and 0 < results["score"] < 1

    # A link to the solution is never followed: not gradable, with the reason.
    (grade / "student" / f"{QUICK}.ipynb").unlink()
    (grade / "student" / f"{QUICK}.ipynb").symlink_to(pl_course / "serverFilesCourse" / f"rlcourse-{QUICK}"
                                                      / "solutions" / QUICK / f"{QUICK}.ipynb")
    code, results = _grade(run_sh, grade, install)
    check_format(results)
    assert results["gradable"] is False and "link" in results["format_errors"][0]


def test_when_the_grader_cannot_start_the_results_say_so(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise GraderError("the reference solution could not be built")

    monkeypatch.setattr("autograder.core.batch.Grader", broken)
    (tmp_path / "student").mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", tmp_path / "student" / "hw0_setup.ipynb")
    assert prairielearn.run("hw0_setup", tmp_path) == 1
    results = json.loads((tmp_path / "results" / "results.json").read_text())
    check_format(results)
    assert results["gradable"] is False and "not your fault" in results["message"]
