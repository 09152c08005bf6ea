"""Throughput of grading a whole class: every assignment, a realistic mix, ``batch --jobs 2``.

    python bench/bench_class_throughput.py [--n 20] [--jobs 2] [--ids hw0_setup ...] [--record]
    python bench/bench_class_throughput.py --overhead   # one warm grading of an untouched hw0 notebook

For each assignment, a class of N copies of its sample submissions in the issue's mix (per 20: 10
complete, 6 partial, 2 untouched, 1 raising an exception, 1 looping forever) is graded by
``python -m autograder batch ID FOLDER --out DIR --jobs J`` in a fresh process, timed from start to
gradebook. A class of 200 is extrapolated from it: the batch's start-up (building each worker's
grader, measured as the time to grade a class of one untouched notebook) is paid once, and the rest
grows with the number of submissions:

    T(200) = T(start) + (T(N) - T(start)) * 200 / N

Prints a Markdown table; ``--record`` writes ``bench/results/class_throughput.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
MIX = {"complete": 10, "partial": 6, "untouched": 2, "broken_exception": 1, "infinite_loop": 1}


def make_class(folder: Path, assignment: str, n: int, kinds: dict[str, int] | None = None) -> None:
    """N submissions in the mix (scaled from 20), named student000..."""
    samples = REPO / "autograder" / "samples" / assignment
    kinds = kinds or {k: max(1, round(v * n / 20)) if v else 0 for k, v in MIX.items()}
    folder.mkdir(parents=True)
    i = 0
    for kind, count in kinds.items():
        for _ in range(count):
            shutil.copy(samples / f"{kind}.ipynb", folder / f"student{i:03d}.ipynb")
            i += 1


def timed_batch(assignment: str, folder: Path, out: Path, jobs: int) -> tuple[float, float]:
    """Wall seconds and CPU seconds (this batch's processes) of one ``batch`` run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", assignment, str(folder), "--out", str(out),
                           "--jobs", str(jobs)], capture_output=True, text=True, cwd=REPO)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"batch {assignment} failed:\n{done.stderr[-3000:]}")
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def overhead(assignment: str = "hw0_setup", sample: str = "untouched", repeats: int = 3) -> float:
    """Median seconds to grade one sample with one warm Grader: what every submission pays besides its tests."""
    from autograder.core.grader import Grader

    grader = Grader(assignment)
    path = REPO / "autograder" / "samples" / assignment / f"{sample}.ipynb"
    grader.grade(path)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        grader.grade(path)
        times.append(time.perf_counter() - start)
    grader.close()
    return sorted(times)[repeats // 2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--record", action="store_true")
    parser.add_argument("--overhead", action="store_true",
                        help="only time grading hw0's untouched sample with a warm grader (median of 3)")
    parser.add_argument("--no-reference-cache", action="store_true",
                        help="recompute the reference's answers for every submission (as if hidden inputs varied)")
    args = parser.parse_args()
    from autograder.core import course

    if args.no_reference_cache:
        os.environ["AUTOGRADER_REFERENCE_CACHE_BYTES"] = "0"
    if args.overhead:
        print(f"grading hw0's untouched sample, warm grader: {overhead():.2f} s (median of 3, load "
              f"{os.getloadavg()[0]:.1f})")
        return

    ids = args.ids or [i for i in course.assignment_ids() if course.suite_dir(i).is_dir()]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for assignment in ids:
            root = Path(tmp) / assignment
            make_class(root / "one", assignment, 1, {"untouched": 1})
            start_wall, _ = timed_batch(assignment, root / "one", root / "one_out", args.jobs)
            make_class(root / "class", assignment, args.n)
            wall, cpu = timed_batch(assignment, root / "class", root / "out", args.jobs)
            n = len(list((root / "class").iterdir()))
            rows.append({"assignment": assignment, "n": n, "wall": wall, "cpu": cpu, "start": start_wall,
                         "extrapolated_200": start_wall + (wall - start_wall) * 200 / n,
                         "load": os.getloadavg()[0]})
            print(f"{assignment}: {n} in {wall:.0f} s (start-up {start_wall:.0f} s, CPU {cpu:.0f} s)", flush=True)
    total, total_200 = sum(r["wall"] for r in rows), sum(r["extrapolated_200"] for r in rows)
    print(f"\n| assignment | class | wall | CPU | start-up (a class of 1) | 200 students (extrapolated) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['assignment']} | {r['n']} | {r['wall']:.0f} s | {r['cpu']:.0f} s | {r['start']:.0f} s | "
              f"{r['extrapolated_200'] / 60:.1f} min |")
    print(f"| all | {sum(r['n'] for r in rows)} | {total:.0f} s | {sum(r['cpu'] for r in rows):.0f} s | | "
          f"{total_200 / 60:.1f} min |")
    if args.record:
        name = "class_throughput_no_cache.json" if args.no_reference_cache else "class_throughput.json"
        out = REPO / "bench" / "results" / name
        out.write_text(json.dumps({"args": vars(args), "mix_per_20": MIX, "rows": rows, "total_wall": total,
                                   "extrapolated_200_total": total_200}, indent=1) + "\n")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
