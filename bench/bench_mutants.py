"""Mutation figures of every hidden suite, recorded: what share of each stub's wrong answers its suite catches.

    python bench/bench_mutants.py [--ids hw3_preferences ...] [--max-per-stub N] [--seed 0]

Runs ``python -m autograder mutants ID --max-per-stub N --seed S`` (``autograder/authoring/mutants.py``: each
mutant of the solution's stub cells graded by the hidden suite and the public check, mutants the suite marks
equivalent left out) and merges each assignment's ``report.json`` into ``bench/results/mutants.json``, per
stub: made, graded, equivalent, killed by the suite, killed by the public check, survivors, kill rate. The
target is a suite kill rate of at least 90% per stub. By default every mutant is graded (835 over the course, about
ten minutes on two cores); ``--max-per-stub N`` grades a seeded sample of N per stub instead.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

RESULTS = REPO / "bench" / "results" / "mutants.json"
TARGET = 0.9


def run(assignment: str, per_stub: int, seed: int) -> dict:
    out = REPO / "build" / "mutants" / assignment
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "autograder", "mutants", assignment, "--max-per-stub", str(per_stub),
                           "--seed", str(seed), "--out", str(out)], cwd=REPO, capture_output=True, text=True)
    if done.returncode not in (0, 1) or not (out / "report.json").exists():
        raise SystemExit(f"mutants {assignment} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    stubs = json.loads((out / "report.json").read_text())
    keep = ("made", "mutants", "equivalent", "killed_by_suite", "killed_by_check", "survivors", "suite_kill_rate")
    return {"max_per_stub": per_stub, "seed": seed, "seconds": round(time.perf_counter() - start, 1),
            "stubs": {name: {k: (round(v, 3) if isinstance(v, float) else v) for k, v in d.items() if k in keep}
                      for name, d in stubs.items()}, "meta": meta()}


def main() -> None:
    from autograder.core import course

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--max-per-stub", type=int, default=1000, help="a seeded sample of at most N per stub")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    ids = args.ids or [a for a in course.assignment_ids() if course.suite_dir(a).is_dir()]
    for assignment in ids:
        row = run(assignment, args.max_per_stub, args.seed)
        data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {"target_kill_rate": TARGET, "assignments": {}}
        data["assignments"][assignment] = row
        data["meta"] = meta()
        RESULTS.write_text(json.dumps(data, indent=1) + "\n")
        low = [f"{s} {d['suite_kill_rate']:.0%}" for s, d in row["stubs"].items() if d["suite_kill_rate"] < TARGET]
        print(f"{assignment}: {len(row['stubs'])} stubs in {row['seconds']:.0f} s; below {TARGET:.0%}: "
              f"{', '.join(low) or 'none'}", flush=True)


if __name__ == "__main__":
    main()
