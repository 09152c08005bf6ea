"""The student's waits in JupyterLab, measured by the browser test, recorded with the machine's load.

    python bench/bench_browser.py [--record] [-k EXPRESSION]

Runs ``tests/test_browser.py`` (headless Chromium driving JupyterLab on a student release) with
``BROWSER_TIMINGS`` set, so the tests write what they measure: for hw3's "be the annotator" widget,
how long its first pair took to render and the wait after each of five clicks, the simulated
student having watched each pair for ``WATCH`` seconds (the next pair renders meanwhile); for hw1's
behaviour-cloning sweep at the full budget, when its output changed in the first minutes. The load
average before and after is recorded beside them: the figures are only as idle as the machine was.
``--record`` writes ``bench/results/browser.json`` with a ``meta`` object; ``python
bench/numbers_pages.py`` turns it into ``docs/numbers/browser.md``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

RESULTS = REPO / "bench" / "results" / "browser.json"


def run(select: str) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        timings = Path(folder) / "timings.json"
        env = dict(os.environ, BROWSER_TIMINGS=str(timings))
        before = os.getloadavg()
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_browser.py",
                               "-k", select], cwd=REPO, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        after = os.getloadavg()
        figures = json.loads(timings.read_text()) if timings.exists() else {}
    summary = [line for line in (proc.stdout + proc.stderr).splitlines() if " in " in line and ("passed" in line
                                                                                               or "failed" in line)]
    return {"command": f"pytest tests/test_browser.py -k '{select}'", "returncode": proc.returncode,
            "summary_line": summary[-1].strip("= ") if summary else None, "wall_seconds": round(wall, 1),
            "load_before": [round(x, 2) for x in before], "load_after": [round(x, 2) for x in after], **figures}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-k", default="annotator or sweep", help="which browser tests to run (pytest -k)")
    parser.add_argument("--record", action="store_true", help=f"write {RESULTS.relative_to(REPO)}")
    args = parser.parse_args()
    result = run(args.k)
    print(json.dumps(result, indent=1))
    if args.record:
        RESULTS.write_text(json.dumps({"meta": meta(["rlcourse", "tests/test_browser.py"]), **result}, indent=1) + "\n")
        print(f"wrote {RESULTS.relative_to(REPO)}")


if __name__ == "__main__":
    main()
