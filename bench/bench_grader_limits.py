"""The grader's peak memory and wall time per submission, over the adversarial corpus.

Each submission of the corpus (``tests/core/test_adversarial.py``: its cheating and harmful cases and its
hostile files) is graded alone, in a fresh grading process of the fixture course's ``fx`` assignment,
and compared with the untouched release notebook graded the same way. The grader's peak resident
memory must stay within twice the untouched notebook's, and its wall time within the assignment's
stated limits (the submission's time in the sandbox, plus the notebook reader's own budget and a
worker start).

    python bench/bench_grader_limits.py                 # the whole corpus: a table, and bench/results/grader_limits.json
    python bench/bench_grader_limits.py --case NAME ... # some cases only
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO / "tests"), str(REPO / "tests" / "core")]  # conftest, and the corpus of test_adversarial
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

GRADE_ONE = """
import json, resource, sys, time
from autograder.core.grader import Grader
start = time.monotonic()
grader = Grader("fx")
try:
    result = grader.grade(sys.argv[1])
finally:
    grader.close()
failures = [t.message for s in result.stubs for t in s.tests if not t.passed and "not implemented" not in t.message]
print(json.dumps({"status": result.status, "score": result.score, "seconds": time.monotonic() - start,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "why": (failures or [result.error or ""])[0][:200]}))
"""
MEMORY_RATIO = 2.0
"""The grader's peak memory on any submission, as a multiple of the untouched notebook's."""


@contextlib.contextmanager
def fixture_course():
    """The course tools pointed at the fixture course (they may be imported already, under pytest say)."""
    from autograder.core import course
    from conftest import FIXTURE_COURSE

    repo, course.REPO = course.REPO, FIXTURE_COURSE
    try:
        yield course
    finally:
        course.REPO = repo


def wall_bound() -> float:
    """Seconds a submission of ``fx`` may take in all: its sandbox time, the reader's budget, worker starts."""
    from autograder.core.intake import PARSE_WALL_SECONDS
    from autograder.core.session import START_SECONDS

    with fixture_course() as course:
        return course.limits("fx").submission_seconds + PARSE_WALL_SECONDS + START_SECONDS


def grade_alone(notebook: Path, timeout: float) -> dict:
    """Grade one notebook in a fresh process; its status, score, wall time and the grader's peak memory."""
    from conftest import FIXTURE_COURSE

    env = dict(os.environ, RLCOURSE_REPO=str(FIXTURE_COURSE))
    try:
        done = subprocess.run([sys.executable, "-c", GRADE_ONE, str(notebook)], capture_output=True, text=True,
                              timeout=timeout, env=env, cwd=REPO)
    except subprocess.TimeoutExpired:
        return {"status": "hung", "score": None, "seconds": timeout, "peak_mb": None}
    if done.returncode != 0:
        return {"status": "crashed", "score": None, "seconds": None, "peak_mb": None, "error": done.stderr[-500:]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def write_corpus(folder: Path) -> tuple[Path, dict[str, Path | None]]:
    """Every corpus submission in ``folder``/submissions, and the notebook batch grading would open for
    each (None where it opens nothing: a link, a pipe), found as ``batch`` finds them."""
    from autograder.core.batch import discover
    from conftest import FIXTURE_COURSE, with_cells
    from test_adversarial import CASES, _case_source, _hostile_files

    port = socket.socket()
    port.bind(("127.0.0.1", 0))
    submissions = folder / "submissions"
    for name, code in CASES.items():
        cells = code if isinstance(code, dict) else {"scaled_sum": code}
        with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", submissions / f"{name}.ipynb",
                   {c: _case_source(s, port.getsockname()[1], folder) for c, s in cells.items()})
    _hostile_files(submissions, folder)
    port.close()
    untouched = with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", folder / "untouched.ipynb", {})
    with fixture_course() as course:
        entries = discover(submissions, "fx", course.stub_names("fx"))
    return untouched, {e.name: e.notebook for e in entries}


def measure(names: list[str] | None = None) -> list[dict]:
    """Rows of the table: per submission, status, score, wall time, peak memory and the bounds."""
    bound = wall_bound()
    with tempfile.TemporaryDirectory(prefix="rlcourse-bench-") as tmp:
        folder = Path(tmp)
        folder.chmod(0o777)
        untouched, notebooks = write_corpus(folder)
        base = grade_alone(untouched, bound * 2)
        rows = [{"submission": "(untouched)", **base}]
        for name, notebook in notebooks.items():
            if names and name not in names:
                continue
            if notebook is None:  # refused before anything is read: a link, a pipe, a linked folder
                rows.append({"submission": name, "status": "refused", "score": 0, "seconds": 0.0, "peak_mb": None})
            else:
                rows.append({"submission": name, **grade_alone(notebook, bound * 2)})
    for row in rows:
        row["memory_ratio"] = None if row["peak_mb"] is None else row["peak_mb"] / base["peak_mb"]
        row["within_memory"] = row["memory_ratio"] is None or row["memory_ratio"] <= MEMORY_RATIO
        row["within_time"] = row["seconds"] is not None and row["seconds"] <= bound
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", action="append", default=None, help="a corpus case (repeatable); default all")
    args = parser.parse_args(argv)
    rows = measure(args.case)
    print(f"{'submission':<42} {'status':<12} {'score':>5} {'wall s':>7} {'peak MB':>8} {'x untouched':>11}")
    for r in rows:
        peak = "-" if r["peak_mb"] is None else f"{r['peak_mb']:.0f}"
        ratio = "-" if r["memory_ratio"] is None else f"{r['memory_ratio']:.2f}"
        seconds = "-" if r["seconds"] is None else f"{r['seconds']:.1f}"
        print(f"{r['submission']:<42} {str(r['status'])[:12]:<12} {str(r['score']):>5} {seconds:>7} {peak:>8} {ratio:>11}")
    worst = max((r["memory_ratio"] or 0) for r in rows)
    slowest = max((r["seconds"] or 0) for r in rows)
    print(f"worst peak memory: {worst:.2f}x the untouched notebook's (bound {MEMORY_RATIO}x); "
          f"slowest: {slowest:.1f} s (bound {wall_bound():.0f} s)")
    if not args.case:
        out = REPO / "bench" / "results" / "grader_limits.json"
        out.write_text(json.dumps({"meta": meta(), "memory_ratio_bound": MEMORY_RATIO, "wall_bound_s": wall_bound(),
                                   "rows": rows}, indent=2) + "\n")
        print(f"wrote {out.relative_to(REPO)}")
    return 0 if all(r["within_memory"] and r["within_time"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
