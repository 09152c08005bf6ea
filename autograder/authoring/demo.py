"""The README's main job: grade every assignment's sample submissions, show the gradebooks, and check
each sample against its ``expected.json`` (the demo is the instructor's self-check of the kit)."""
from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

from autograder.core import course
from autograder.core.batch import GRADEBOOK_NAME
from autograder.outputs.files import grade_folder
from autograder.outputs.feedback import FEEDBACK_NAME
from autograder.core.results import GradeResult


def _table(path: Path) -> str:
    rows = list(csv.reader(path.open()))
    header, body = rows[0], rows[1:]
    keep = [i for i, h in enumerate(header) if h != "reason"]
    widths = [max(len(r[i]) for r in rows) for i in keep]
    line = lambda r: "  ".join(r[i].ljust(w) for i, w in zip(keep, widths))  # noqa: E731
    return "\n".join([line(header), line(["-" * w for w in widths] + [""] * len(header)), *map(line, body)])


def differences(results: list[GradeResult], expected: dict[str, dict[str, str]]) -> list[str]:
    """Every way the graded samples differ from ``expected.json`` ("full" or "zero" per stub)."""
    by_name = {r.submission: r for r in results}
    problems = [f"{name}: expected in expected.json, not graded" for name in sorted(set(expected) - set(by_name))]
    problems += [f"{name}: graded, but expected.json says nothing of it" for name in sorted(set(by_name) - set(expected))]
    for name in sorted(set(expected) & set(by_name)):
        result = by_name[name]
        if not result.has_score:
            problems.append(f"{name}: not graded, the grader failed: {result.error}")
            continue
        stubs = {s.name: s for s in result.stubs}
        for stub, outcome in expected[name].items():
            got = stubs.get(stub)
            if got is None or got.max_score == 0:
                problems.append(f"{name}: `{stub}` has no hidden tests")
                continue
            want = got.max_score if outcome == "full" else 0
            if got.score != want:
                why = next((t.message for t in got.tests if not t.passed), "")
                problems.append(f"{name}: `{stub}` scored {got.score:g}/{got.max_score:g}, expected {outcome}"
                                + (f" ({why[:120]})" if why else ""))
    return problems


def run_demo(out: Path, jobs: int = 2) -> int:
    """Batch-grade ``autograder/samples/<id>/`` for every assignment that has samples (in one batch); print each
    gradebook.

    Returns non-zero when any sample grades differently from its ``expected.json``.
    """
    ids = [i for i in course.assignment_ids() if course.samples_dir(i).is_dir() and course.suite_dir(i).is_dir()]
    if not ids:
        raise SystemExit("no assignment has sample submissions yet (python -m autograder samples ID)")
    problems = []
    # one batch over all of them: its processes import the grader once, not once per assignment
    graded = grade_folder(ids, course.samples_root(), Path(out), jobs=jobs)
    for assignment in ids:
        target = Path(out) / assignment
        results = graded[assignment]
        print(f"\n{assignment}: gradebook {target / GRADEBOOK_NAME}\n")
        print(_table(target / GRADEBOOK_NAME))
        print(f"\nper-student feedback: {target}/<submission>/{FEEDBACK_NAME} "
              f"(e.g. {target / 'partial' / FEEDBACK_NAME}); Gradescope JSON beside it as results.json")
        expected_path = course.samples_dir(assignment) / "expected.json"
        if expected_path.exists():
            problems += [f"{assignment}/{p}" for p in differences(results, json.loads(expected_path.read_text()))]
    if problems:
        print(f"\nDEMO FAILED: {len(problems)} sample result(s) differ from expected.json:", file=sys.stderr)
        for problem in problems:
            print(f"  {problem}", file=sys.stderr)
        return 1
    print(f"\nevery sample of {len(ids)} assignments graded as its expected.json says")
    return 0
