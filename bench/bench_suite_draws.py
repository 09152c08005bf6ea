"""Does the reference pass its own hidden suite on every draw of the hidden inputs?

    python bench/bench_suite_draws.py [--draws 20] [--ids hw3_preferences ...] [--record]

A test's ``rng`` inputs are seeded by the submission's stub code (``input_key``), so each submission meets its
own draw. A statistical threshold that the reference misses on one draw in fifty fails one correct submission
in fifty: a grade the student did nothing to earn. For each assignment the solution's own namespace is graded
as the student (in this process, no sandbox, as ``bench_class_throughput.py --per-test`` does) under
``--draws`` input keys, and every test that fails on any of them is listed with the keys it failed on.
``--record`` writes ``bench/results/suite_draws.json``; ``tests/core/test_suite_draws.py`` re-runs a few
draws of the quick assignments.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

FIRST_KEY = 1_000_003
"""Draws use keys FIRST_KEY, FIRST_KEY + 1, ...: none is the key of a sample submission."""


def student_transport(namespace: dict, helpers: str | None):
    """The reference's namespace behind a transport that reports what it raises as a student's error, as a
    sandbox does (a test that expects a ``ValueError`` for bad input then sees one)."""
    from autograder.core.session import LocalTransport, StudentError

    class AsStudent(LocalTransport):
        def request(self, header, blobs, timeout=None):
            try:
                return super().request(header, blobs, timeout)
            except Exception as err:  # noqa: BLE001 - the "student" raised it
                cause = err.__cause__ or err
                raise StudentError(type(cause).__name__, str(cause)) from cause

    return AsStudent(namespace, helpers)


def reference_draws(assignment: str, draws: int, first: int = FIRST_KEY) -> dict:
    """The tests the reference fails, by input key, over ``draws`` keys, and the seconds it took."""
    from autograder.core.grader import Grader, SuitePlugin, build_reference
    from autograder.core.session import LocalTransport, Namespace, ReferenceCache

    grader = Grader(assignment)
    try:
        alone = build_reference(assignment)
        failures: dict[str, list[int]] = {}
        messages: dict[str, str] = {}
        tests = 0
        start = time.perf_counter()
        for key in range(first, first + draws):
            plugin = SuitePlugin(Namespace(student_transport(alone, grader.helpers), "student"),
                                 Namespace(LocalTransport(grader.reference_ns, grader.helpers, ReferenceCache()),
                                           "reference"), {}, None, grader.dependencies, key)
            grader._run_suite(plugin)
            tests = len(plugin.outcomes)
            for outcome in plugin.outcomes:
                if not outcome.passed:
                    failures.setdefault(outcome.name, []).append(key)
                    messages.setdefault(outcome.name, str(outcome.message)[:300])
        seconds = time.perf_counter() - start
    finally:
        grader.close()
    return {"draws": draws, "first_key": first, "tests": tests, "seconds": round(seconds, 2),
            "failing": {name: {"keys": keys, "rate": round(len(keys) / draws, 3), "message": messages[name]}
                        for name, keys in sorted(failures.items())}}


def main() -> None:
    from autograder.core import course

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=20)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--record", action="store_true")
    args = parser.parse_args()
    ids = args.ids or [a for a in course.assignment_ids() if course.suite_dir(a).is_dir()]
    out = REPO / "bench" / "results" / "suite_draws.json"
    record = json.loads(out.read_text()) if args.record and out.exists() else {}
    record.setdefault("assignments", {})
    for assignment in ids:
        row = reference_draws(assignment, args.draws)
        row["meta"] = meta()
        record["assignments"][assignment] = row
        bad = ", ".join(f"{n} ({len(v['keys'])}/{args.draws})" for n, v in row["failing"].items()) or "none"
        print(f"{assignment}: {row['tests']} tests x {args.draws} draws in {row['seconds']:.0f} s; "
              f"failing on some draw: {bad}", flush=True)
        if args.record:
            record["meta"] = meta()
            out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
