"""Wall time of the hosted graders' entry points, start to exit, as PrairieLearn and Gradescope run them.

    python bench/bench_platform_routes.py [--repeats 2] [--ids hw0_setup ...] [--record]

Settings, fixed before any run:
- PrairieLearn: each assignment's ``untouched`` sample (every stub raises at once: what is left is start-up,
  the interpreter's imports, the reference built from the solution, the suite collected and run) and, for the
  assignments whose question fits PrairieLearn's 600 s, its ``infinite_loop`` sample (every stub loops until
  the sandbox stops it: the longest a submission can take), each graded ``--repeats`` times by the process a
  question's ``run.sh`` starts, ``python -m autograder prairielearn ID --root DIR``, timed from outside. Beside
  each: the question's timeout (``submission_seconds`` + ``STARTUP_SECONDS``), or why there is none.
- Gradescope: hw0's ``partial`` sample graded ``--repeats`` times by ``run_autograder`` in a bundle unpacked
  as Gradescope lays it out, timed from outside, beside the ``execution_time`` its ``results.json`` reports.

Every child runs under ``nice -n 10`` with one thread per library. ``--record`` writes
``bench/results/platform_routes.json`` (per-run values and a ``meta`` object). One run on a shared machine is
one sample: the load recorded beside it says how shared it was.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402
RESULTS = REPO / "bench" / "results" / "platform_routes.json"
THREADS = {name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
RUN_LIMIT = 1200.0
"""A run still going after this long is stopped and recorded as such."""

def timed(command: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, int | None, float]:
    """Wall seconds, exit status (None when stopped at RUN_LIMIT) and the 1-minute load when it started."""
    load = os.getloadavg()[0]
    start = time.perf_counter()
    try:
        code = subprocess.run(["nice", "-n", "10", *command], cwd=cwd, env=env, capture_output=True,
                              timeout=RUN_LIMIT).returncode
    except subprocess.TimeoutExpired:
        code = None
    return time.perf_counter() - start, code, load


def prairielearn_runs(ids: list[str], repeats: int) -> list[dict]:
    from autograder.core import course
    from autograder.outputs import prairielearn

    rows = []
    for assignment in ids:
        try:
            timeout, why = prairielearn.question_timeout(assignment), None
        except SystemExit as refusal:
            timeout, why = None, str(refusal)
        samples = ["untouched"] + (["infinite_loop"] if timeout is not None else [])
        for sample in samples:
            notebook = course.samples_dir(assignment) / f"{sample}.ipynb"
            if not notebook.exists():
                continue
            for repeat in range(repeats):
                with tempfile.TemporaryDirectory() as tmp:
                    root = Path(tmp)
                    (root / "student").mkdir()
                    shutil.copy(notebook, root / "student" / f"{assignment}.ipynb")
                    wall, code, load = timed([sys.executable, "-m", "autograder", "prairielearn", assignment,
                                              "--root", str(root)], REPO, dict(os.environ, **THREADS))
                    results_file = root / "results" / "results.json"
                    results = json.loads(results_file.read_text()) if results_file.exists() else {}
                rows.append({"assignment": assignment, "sample": sample, "repeat": repeat, "wall_seconds": round(wall, 2),
                             "exit": code, "load_at_start": round(load, 2), "gradable": results.get("gradable"),
                             "score": results.get("score"), "timeout": timeout, "refused": why,
                             "submission_seconds": course.limits(assignment).submission_seconds,
                             "within_timeout": None if timeout is None else wall <= timeout})
                print(json.dumps(rows[-1]), flush=True)
    return rows


def gradescope_runs(repeats: int) -> list[dict]:
    from autograder.core import course
    from autograder.outputs.gradescope import build_bundle

    rows = []
    for repeat in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp) / "autograder"
            source = root / "source"
            with zipfile.ZipFile(build_bundle("hw0_setup", Path(tmp) / "bundle.zip")) as bundle:
                bundle.extractall(source)
            os.symlink(Path(sys.prefix), source / ".venv")  # setup.sh's environment: this one stands in
            (root / "submission").mkdir()
            shutil.copy(course.samples_dir("hw0_setup") / "partial.ipynb", root / "submission" / "work.ipynb")
            wall, code, load = timed(["bash", str(source / "run_autograder")], Path(tmp),
                                     dict(os.environ, GRADESCOPE_ROOT=str(root), **THREADS))
            results = json.loads((root / "results" / "results.json").read_text())
        rows.append({"assignment": "hw0_setup", "sample": "partial", "repeat": repeat, "wall_seconds": round(wall, 2),
                     "execution_time": results["execution_time"], "exit": code, "load_at_start": round(load, 2),
                     "score": results["score"]})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> None:
    from autograder.core import course

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--ids", nargs="*", default=None, help="assignments (default: every one)")
    parser.add_argument("--record", action="store_true", help=f"write {RESULTS.relative_to(REPO)}")
    args = parser.parse_args()
    ids = args.ids or course.assignment_ids()
    started = meta()
    record = {"args": vars(args), "prairielearn": prairielearn_runs(ids, args.repeats),
              "gradescope": gradescope_runs(args.repeats)}
    record["meta"] = {**started, "load_after": list(os.getloadavg())}
    for row in record["prairielearn"]:
        print(f"prairielearn {row['assignment']:18s} {row['sample']:14s} {row['wall_seconds']:7.1f} s"
              f"  timeout {row['timeout'] or '-'}")
    for row in record["gradescope"]:
        print(f"gradescope   hw0_setup partial: {row['wall_seconds']:.1f} s wall, execution_time {row['execution_time']}")
    if args.record:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        print(f"wrote {RESULTS.relative_to(REPO)}")


if __name__ == "__main__":
    main()
