"""How long the edit-test loop takes: ``make test-fast``, timed once, recorded with the machine's load; and,
with ``--make-test``, what CI runs: ``make test`` in a fresh clone of HEAD, set-up included.

    python bench/bench_test_fast.py [--durations 15] [--record]
    python bench/bench_test_fast.py --make-test [--record]      # bench/results/make_test.json

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
from bench.run_record import head_commit, meta  # noqa: E402
RESULTS = REPO / "bench" / "results" / "test_fast.json"
MAKE_TEST_RESULTS = REPO / "bench" / "results" / "make_test.json"
LAST_RUN = REPO / "build" / "bench" / "make_test_last.json"
"""The last --make-test run, recorded or not (build/ is not committed)."""
PYTEST_TIME = re.compile(r"\bin ([\d.]+)s\b")
COUNT = re.compile(r"(\d+) (passed|failed|skipped|deselected|errors?|xfailed|xpassed|warnings?)")
DURATION = re.compile(r"^\s*([\d.]+)s (call|setup|teardown)\s+(\S+)", re.M)

def pytest_runs(output: str) -> list[dict]:
    """Each pytest invocation's summary line, counts and own seconds (``make test`` runs two)."""
    lines = [line for line in output.splitlines()
             if re.search(r"\b(passed|failed|error|deselected)", line) and PYTEST_TIME.search(line)]
    runs = []
    for line in lines:
        counts = {(w.rstrip("s") if w.startswith(("error", "warning")) else w): int(n) for n, w in COUNT.findall(line)}
        runs.append({"summary_line": line.strip("= "), "counts": counts,
                     "seconds": float(PYTEST_TIME.search(line)[1])})
    return runs


def parse_summary(output: str) -> dict:
    """pytest's counts from its last summary line ("370 passed, 45 deselected in 112.3s"), and the slowest tests."""
    last = (pytest_runs(output) or [{"counts": {}, "summary_line": None}])[-1]
    slowest = [{"seconds": float(s), "phase": phase, "test": test} for s, phase, test in DURATION.findall(output)]
    return {"counts": last["counts"], "summary_line": last["summary_line"], "slowest": slowest}


def machine_cpu_seconds() -> tuple[float, float]:
    """The whole machine's busy and idle CPU seconds since boot (``/proc/stat``): unlike a process's own accounts,
    busy time counts every process, sandbox workers whose CPU reaches no parent's accounts included."""
    fields = [float(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    tick = os.sysconf("SC_CLK_TCK")
    idle = fields[3] + fields[4]  # idle and iowait
    return (sum(fields[:8]) - idle) / tick, idle / tick


def run(durations: int, target: str = "test-fast", cwd: Path = REPO) -> dict:
    env = dict(os.environ, PYTEST_ADDOPTS=f"--durations={durations}")
    before = os.getloadavg()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    busy0, idle0 = machine_cpu_seconds()
    start = time.perf_counter()
    proc = subprocess.run(["make", target], cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    busy1, idle1 = machine_cpu_seconds()
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    after = os.getloadavg()
    output = proc.stdout + proc.stderr
    return {"command": f"make {target}", "returncode": proc.returncode, "wall_seconds": round(wall, 1),
            "cpu_seconds": round((cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime), 1),
            "machine_busy_seconds": round(busy1 - busy0, 1), "machine_idle_seconds": round(idle1 - idle0, 1),
            "load_before": list(before), "load_after": list(after), "pytest_runs": pytest_runs(output),
            "failures": [line.strip() for line in output.splitlines() if line.startswith(("FAILED ", "ERROR "))][:50],
            **parse_summary(output)}


def make_test_in_a_clone(durations: int) -> dict:
    """``make test`` in a fresh clone of HEAD (its own ``.venv``: the set-up is timed too), as CI runs it."""
    import shutil
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="rlcourse-make-test-"))
    try:
        subprocess.run(["git", "clone", "--quiet", str(REPO), str(folder / "clone")], check=True)
        commit = head_commit(folder / "clone")
        record = run(durations, "test", folder / "clone")
        record["cloned_commit"] = commit  # the meta names it too: HEAD may move while the clone is tested
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    record["pytest_seconds"] = round(sum(r["seconds"] for r in record["pytest_runs"]), 1)
    record["setup_and_other_seconds"] = round(record["wall_seconds"] - record["pytest_seconds"], 1)
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", type=int, default=15, help="how many of the slowest tests to list")
    parser.add_argument("--record", action="store_true", help="write the results file")
    parser.add_argument("--make-test", action="store_true",
                        help=f"time make test in a fresh clone of HEAD instead ({MAKE_TEST_RESULTS.relative_to(REPO)})")
    args = parser.parse_args()
    if args.make_test:
        record = make_test_in_a_clone(args.durations)
        os.environ["BENCH_COMMIT"] = record["cloned_commit"]
        record["meta"] = meta()
        print(f"make test in a fresh clone: {record['wall_seconds']} s wall ({record['pytest_seconds']} s in pytest, "
              f"{record['setup_and_other_seconds']} s set-up and the rest), {record['cpu_seconds']} s CPU "
              f"(the machine busy {record['machine_busy_seconds']} s, idle {record['machine_idle_seconds']} s); "
              + "; ".join(r["summary_line"] for r in record["pytest_runs"])
              + f" (exit {record['returncode']}, load {record['load_before'][0]:.1f} before, "
              f"{record['load_after'][0]:.1f} after)")
        for line in record["failures"]:
            print(line)
        LAST_RUN.parent.mkdir(parents=True, exist_ok=True)
        LAST_RUN.write_text(json.dumps(record, indent=1) + "\n")  # kept unrecorded too: its failures and durations
        if args.record:
            MAKE_TEST_RESULTS.write_text(json.dumps(record, indent=1) + "\n")
            print(f"wrote {MAKE_TEST_RESULTS.relative_to(REPO)}")
        return
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
