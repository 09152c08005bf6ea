"""Autograder numbers: per-submission overhead, batch throughput against nbgrader, and resume.

    python bench/bench_autograder.py [--n 100] [--nbgrader-n 20] [--jobs 2]

1. Overhead: grading one complete hw0 submission (sandbox start-up, cell execution, every hidden
   test through the sandbox) against running the same hidden suite on the reference alone.
2. Batch: N mixed submissions (complete, partial, untouched, syntax error, exception) graded with
   `--jobs 2`, and `nbgrader autograde` on the first M of the same submissions in the same run.
3. Resume: the same batch killed with SIGKILL halfway, restarted, and checked for every submission
   graded exactly once (results finished before the kill are not rewritten).
Prints a Markdown table.
"""
from __future__ import annotations

import argparse
import csv
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "autograder" / "samples" / "hw0_setup"
MIX = ["complete"] * 4 + ["partial"] * 3 + ["untouched", "broken_syntax", "broken_exception"]


def overhead(repeats: int = 5) -> tuple[float, float]:
    """Median seconds: a full grade of the complete sample, and the suite run against the reference only."""
    from autograder.core.grader import Grader, SuitePlugin
    from autograder.core.session import LocalTransport, Namespace

    grader = Grader("hw0_setup")
    full, reference_only = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        result = grader.grade(SAMPLES / "complete.ipynb")
        full.append(time.perf_counter() - start)
        assert result.score == result.max_score
        ns = Namespace(LocalTransport(grader.reference_ns), "reference")
        start = time.perf_counter()
        grader._run_suite(SuitePlugin(ns, ns, {}))
        reference_only.append(time.perf_counter() - start)
    grader.close()
    return sorted(full)[repeats // 2], sorted(reference_only)[repeats // 2]


def make_batch(folder: Path, n: int) -> None:
    folder.mkdir(parents=True)
    for i in range(n):
        shutil.copy(SAMPLES / f"{MIX[i % len(MIX)]}.ipynb", folder / f"student{i:03d}.ipynb")


def run_ours(folder: Path, out: Path, jobs: int) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out),
                    "--jobs", str(jobs)], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def run_nbgrader(folder: Path, n: int, work: Path) -> float:
    """nbgrader autograde on the first ``n`` submissions: it executes every notebook in full."""
    course = work / "nbgrader_course"
    (course / "source" / "hw0_setup").mkdir(parents=True)
    shutil.copy(REPO / "solutions/hw0_setup/hw0_setup.ipynb", course / "source/hw0_setup/hw0_setup.ipynb")
    (course / "nbgrader_config.py").write_text("c = get_config()\nc.CourseDirectory.root = '.'\n"
                                               "c.ExecutePreprocessor.timeout = 300\n")
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nbgrader = str(Path(sys.executable).parent / "nbgrader")
    subprocess.run([nbgrader, "generate_assignment", "hw0_setup", "--force"], cwd=course, env=env, check=True,
                   capture_output=True)
    for path in sorted(folder.glob("*.ipynb"))[:n]:
        target = course / "submitted" / path.stem / "hw0_setup"
        target.mkdir(parents=True)
        shutil.copy(path, target / "hw0_setup.ipynb")
    start = time.perf_counter()
    subprocess.run([nbgrader, "autograde", "hw0_setup", "--create", "--force"], cwd=course, env=env, check=True,
                   capture_output=True)
    return time.perf_counter() - start


def resume(folder: Path, out: Path, jobs: int, n: int) -> tuple[int, int, int, bool]:
    """Kill a batch halfway with SIGKILL, restart it; return (done before, rows, unique rows, none regraded)."""
    command = [sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out),
               "--jobs", str(jobs)]
    first = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while len(list(out.glob("*/result.json"))) < n // 2 and first.poll() is None:
        time.sleep(0.1)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    before = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/result.json")}
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rows = [r["submission"] for r in csv.DictReader((out / "gradebook.csv").open())]
    untouched = all((out / name / "result.json").stat().st_mtime_ns == t for name, t in before.items())
    return len(before), len(rows), len(set(rows)), untouched


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--nbgrader-n", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-autograder-"))
    try:
        full, reference_only = overhead()
        folder = work / "submissions"
        make_batch(folder, args.n)
        ours = run_ours(folder, work / "out", args.jobs)
        theirs = run_nbgrader(folder, args.nbgrader_n, work)
        killed_after, rows, unique, untouched = resume(folder, work / "out_resume", args.jobs, args.n)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    per_ours, per_theirs = ours / args.n, theirs / args.nbgrader_n
    print("| measure | value |\n|---|---|")
    print(f"| grade one complete hw0 submission (median of 5) | {full:.2f} s |")
    print(f"| its hidden suite on the reference alone | {reference_only:.2f} s |")
    print(f"| overhead of the sandbox (worker start-up included) | {full - reference_only:.2f} s |")
    print(f"| batch of {args.n} mixed submissions, --jobs {args.jobs} | {ours:.1f} s ({per_ours:.2f} s per submission) |")
    print(f"| nbgrader autograde, first {args.nbgrader_n} of them | {theirs:.1f} s ({per_theirs:.2f} s per submission) |")
    print(f"| nbgrader / ours, per submission | {per_theirs / per_ours:.1f}x |")
    print(f"| resume: killed after {killed_after}/{args.n}, restarted | {rows} rows, {unique} unique, "
          f"{'no' if untouched else 'some'} finished result rewritten |")


if __name__ == "__main__":
    main()
