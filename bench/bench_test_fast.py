"""How long the edit-test loop takes: ``make test-fast``, timed once, recorded with the machine's load.

    python bench/bench_test_fast.py [--durations 15] [--record]

Runs ``make test-fast`` (every test not marked ``slow``) as a child process, with
``PYTEST_ADDOPTS=--durations=N`` so pytest also lists its N slowest tests, and measures the wall
time, the CPU time of the whole process tree (``resource.getrusage(RUSAGE_CHILDREN)``) and the load
average before and after. The counts (passed, failed, skipped, deselected) and the slowest tests
are read from pytest's own summary. ``--record`` writes ``bench/results/test_fast.json`` with a
``meta`` object; ``python bench/numbers_pages.py`` turns it into ``docs/numbers/test_fast.md``.

One run on a shared machine is one sample: the load recorded beside it says how shared it was.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402
RESULTS = REPO / "bench" / "results" / "test_fast.json"
COUNT = re.compile(r"(\d+) (passed|failed|skipped|deselected|errors?|xfailed|xpassed|warnings?)")
DURATION = re.compile(r"^\s*([\d.]+)s (call|setup|teardown)\s+(\S+)", re.M)

def parse_summary(output: str) -> dict:
    """pytest's counts from its last summary line ("370 passed, 45 deselected in 112.3s")."""
    lines = [line for line in output.splitlines() if re.search(r"\b(passed|failed|error)", line) and " in " in line]
    counts = {}
    if lines:
        for number, word in COUNT.findall(lines[-1]):
            counts[word.rstrip("s") if word.startswith(("error", "warning")) else word] = int(number)
    slowest = [{"seconds": float(s), "phase": phase, "test": test} for s, phase, test in DURATION.findall(output)]
    return {"counts": counts, "summary_line": lines[-1].strip("= ") if lines else None, "slowest": slowest}


def run(durations: int) -> dict:
    env = dict(os.environ, PYTEST_ADDOPTS=f"--durations={durations}")
    before = os.getloadavg()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(["make", "test-fast"], cwd=REPO, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    after = os.getloadavg()
    output = proc.stdout + proc.stderr
    return {"command": "make test-fast", "returncode": proc.returncode, "wall_seconds": round(wall, 1),
            "cpu_seconds": round((cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime), 1),
            "load_before": list(before), "load_after": list(after), **parse_summary(output)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", type=int, default=15, help="how many of the slowest tests to list")
    parser.add_argument("--record", action="store_true", help=f"write {RESULTS.relative_to(REPO)}")
    args = parser.parse_args()
    record = {**run(args.durations), "meta": meta()}
    print(f"make test-fast: {record['wall_seconds']} s wall, {record['cpu_seconds']} s CPU, "
          f"{record['summary_line']} (exit {record['returncode']}, load {record['load_before'][0]:.1f} "
          f"before, {record['load_after'][0]:.1f} after)")
    if args.record:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        print(f"wrote {RESULTS.relative_to(REPO)}")


if __name__ == "__main__":
    main()
