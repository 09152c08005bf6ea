"""Each hidden test's own time limit, from the reference's own time on that test.

    python -m autograder.authoring.limits ID [ID ...]     # or --all; --dry-run prints without writing

A looping submission costs a test's whole limit before it is stopped; with only the suite's ``test_seconds``
(minutes) and ``call_seconds`` that is up to a minute a stub. This grades the assignment's complete sample
once, with no per-test limits (``test_seconds`` as the suite sets it), and gives every test that passed

    limit = min(test_seconds, MULTIPLE * t + CONSTANT)     (rounded up to a tenth of a second)

where ``t`` is the test's own time in that run: its wall time from its start to its end (what its deadline
counts), less the time the worker and the grader waited for a busy CPU (the kernel's run delay), so a
loaded machine while measuring does not inflate the limits. At grading time the CPU-wait credit applies on
top of the limit as for every deadline (up to ``CPU_WAIT_STRETCH`` times it), so a loaded machine does not
fail an honest submission either. The limits go into the suite's ``limits.json`` under ``"tests"`` (by
pytest node id), and what they came from under ``"tests_reference"``; a test without one (new or renamed
since) keeps ``test_seconds``. Run it again after changing a suite's tests.

A re-measure does not loosen a limit by noise: where a test's earlier limit is lower than the new one by at
most ``NOISE_SECONDS``, the earlier limit and its record stay (listed in ``kept_earlier``, their runs in
``earlier_measured``). A test that became heavier by more than that gets its new limit; ``--fresh`` drops
every earlier record.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

from autograder.core import course

MULTIPLE = 10.0
"""How many times the reference's own time a test may take."""
CONSTANT = 5.0
"""Seconds every test may take besides (starting stand-ins, a slow first import, a cold cache)."""
NOISE_SECONDS = 0.5
"""How much higher a re-measured limit may come out than the earlier one and still count as noise (kept earlier)."""
SAMPLE = "complete"
"""The sample graded to measure the reference: the solution's own code in a student's notebook."""


def limit_for(own_seconds: float, test_seconds: float) -> float:
    """The rule: ``MULTIPLE`` times the reference's own seconds plus ``CONSTANT``, at most ``test_seconds``."""
    return min(float(test_seconds), math.ceil((MULTIPLE * max(0.0, own_seconds) + CONSTANT) * 10) / 10)


def own_seconds(stats: dict[str, float]) -> float:
    """A test's own time from what the grader recorded about it (:attr:`SuitePlugin.test_stats`): its span less
    the worker's and the grader's waits for a CPU."""
    span = stats.get("span", stats.get("seconds", 0.0))
    return max(0.0, span - stats.get("credit", 0.0) - stats.get("grader_wait", 0.0))


def measure(assignment: str, sample: str = SAMPLE) -> tuple[dict[str, dict[str, float]], dict, float]:
    """Grade the sample once without per-test limits: each test's stats, whether all passed (and the score),
    and the grading's wall time."""
    from autograder.core.grader import Grader

    grader = Grader(assignment, test_limits={})
    try:
        start = time.monotonic()
        result = grader.grade(course.samples_dir(assignment) / f"{sample}.ipynb")
        wall = time.monotonic() - start
        stats = grader.last_test_stats
    finally:
        grader.close()
    if not result.has_score:
        raise SystemExit(f"{assignment}: the {sample} sample could not be graded: {result.error}")
    all_passed = all(t.passed for s in result.stubs for t in s.tests)
    return stats, {"all": all_passed, "score": result.score, "max_score": result.max_score}, wall


def keep_earlier(earlier: dict, tests: dict[str, float], reference: dict[str, dict]) -> list[str]:
    """Where ``earlier`` (a ``limits.json`` as read) gave a test a limit lower than the new one by at most
    ``NOISE_SECONDS``, put the earlier limit and record back into ``tests`` and ``reference``; the tests kept."""
    old_tests = earlier.get("tests", {})
    old_records = earlier.get("tests_reference", {}).get("seconds", {})
    kept = []
    for node, limit in tests.items():
        old = old_tests.get(node)
        if old is not None and node in old_records and old < limit <= old + NOISE_SECONDS:
            tests[node], reference[node] = old, old_records[node]
            kept.append(node)
    return sorted(kept)


def write_limits(assignment: str, dry_run: bool = False, fresh: bool = False) -> dict:
    """Measure ``assignment``'s reference and write its per-test limits; what was written."""
    base = course.limits(assignment)
    stats, outcome, wall = measure(assignment)
    if not outcome["all"]:
        print(f"{assignment}: warning: the complete sample scored {outcome['score']}/{outcome['max_score']}, so "
              "some limits come from a failing run: fix the sample or the suite and run this again", file=sys.stderr)
    tests, reference = {}, {}
    for node, s in sorted(stats.items()):
        if "span" not in s:  # a test that never reached the sandbox (its stub's cell did not run)
            continue
        own = own_seconds(s)
        tests[node] = limit_for(own, base.test_seconds)
        reference[node] = {"own": round(own, 3), "span": round(s["span"], 3), "credit": round(s.get("credit", 0.0), 3),
                           "grader_wait": round(s.get("grader_wait", 0.0), 3),
                           "grader_cpu": round(s.get("grader_cpu", 0.0), 3),
                           "worker_cpu": round(s.get("worker_cpu", 0.0), 3), "messages": int(s.get("messages", 0))}
    path = course.suite_dir(assignment) / "limits.json"
    raw = json.loads(path.read_text()) if path.exists() else {}
    earlier = {} if fresh else raw
    kept = keep_earlier(earlier, tests, reference)
    previous = earlier.get("tests_reference", {})
    earlier_runs = [m for m in [previous.get("measured"), *previous.get("earlier_measured", [])] if m] if kept else []
    raw["tests"] = tests
    raw["tests_reference"] = {
        "rule": f"min(test_seconds, {MULTIPLE:g} * own + {CONSTANT:g}) s, own = the test's span less the worker's "
                "and the grader's CPU wait, from the complete sample graded once (autograder/authoring/limits.py); "
                f"a re-measure at most {NOISE_SECONDS:g} s higher keeps the earlier, lower limit (never loosened by "
                "noise): the tests in kept_earlier, from one of the runs in earlier_measured",
        "measured": {"commit": _commit(), "date": datetime.date.today().isoformat(), "load": list(os.getloadavg()),
                     "machine": "2-core CPU", "grading_seconds": round(wall, 2), "test_seconds": base.test_seconds},
        "seconds": reference, "earlier_measured": earlier_runs, "kept_earlier": kept}
    if not dry_run:
        path.write_text(json.dumps(raw, indent=1) + "\n")
    return raw


def _commit() -> str:
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          cwd=course.REPO).stdout.strip()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m autograder.authoring.limits", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("ids", nargs="*")
    parser.add_argument("--all", action="store_true", help="every assignment with a suite")
    parser.add_argument("--dry-run", action="store_true", help="print the limits, write nothing")
    parser.add_argument("--fresh", action="store_true", help="no earlier limit kept, however close (NOISE_SECONDS)")
    args = parser.parse_args(argv)
    ids = [i for i in course.assignment_ids() if course.suite_dir(i).is_dir()] if args.all else args.ids
    if not ids:
        parser.error("name an assignment, or --all")
    for assignment in ids:
        course.check_assignment(assignment)
        raw = write_limits(assignment, args.dry_run, args.fresh)
        limits = raw["tests"]
        longest = max(limits.values(), default=0.0)
        print(f"{assignment}: {len(limits)} tests, limits {min(limits.values(), default=0.0):.1f}-{longest:.1f} s "
              f"(test_seconds {course.limits(assignment).test_seconds:.0f} s)"
              + ("" if args.dry_run else f"; wrote {course.suite_dir(assignment) / 'limits.json'}"), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
