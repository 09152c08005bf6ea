"""Similar stub code at class scale: the similarity pass of ``class-report`` on a class of N hw1 notebooks.

    python bench/bench_similarity.py [--n 100] [--jobs 2] [--seed 0]

The class is built from the student release: for each student and stub, the stub is left untouched
(one time in five) or replaced by a mutant of the solution (``autograder.authoring.mutants.make_mutants``: the
solution with one operator changed), drawn at random. Every submission thus derives from one
solution, the worst case for this pass: most pairs are flagged, and side-by-side pages are written
for the most similar (``class_report.MAX_PAGES``). Times the two halves of ``class_report.find_similar`` (reading each notebook in its own
child process and matching its stubs; fingerprinting and comparing every pair and writing the
pages) and prints a Markdown table with the load average and the CPU time (this process and its
children).
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import nbformat
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from autograder.core import course  # noqa: E402
from autograder.authoring.mutants import make_mutants  # noqa: E402
from autograder.core.notebook import read_notebook  # noqa: E402
from autograder.outputs.class_report import compare_and_write  # noqa: E402
from autograder.outputs.similarity import read_stub_code  # noqa: E402

ASSIGNMENT = "hw1_imitation"
UNTOUCHED = 0.2


def build_class(folder: Path, n: int, seed: int) -> None:
    """``n`` notebooks in ``folder``: each stub untouched or a random mutant of the solution."""
    rng = np.random.default_rng(seed)
    stubs = course.stub_names(ASSIGNMENT)
    solution = {c.metadata["nbgrader"]["grade_id"]: c.source for c in read_notebook(
        REPO / "solutions" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").cells
        if c.metadata.get("nbgrader", {}).get("grade_id") in stubs}
    pools = {stub: [m.source for m in make_mutants(stub, solution[stub])] for stub in stubs}
    release = read_notebook(course.release_notebook(ASSIGNMENT))
    for i in range(n):
        nb = nbformat.from_dict(release)
        for cell in nb.cells:
            stub = cell.metadata.get("nbgrader", {}).get("grade_id")
            if stub in pools and rng.random() >= UNTOUCHED:
                cell.source = pools[stub][rng.integers(len(pools[stub]))]
        nbformat.write(nb, str(folder / f"student{i:03d}.ipynb"))


def cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="bench-similarity-"))
    try:
        folder = root / "submissions"
        folder.mkdir()
        build_class(folder, args.n, args.seed)
        load = os.getloadavg()
        cpu0, start = cpu_seconds(), time.perf_counter()
        codes = read_stub_code(ASSIGNMENT, folder, jobs=args.jobs)
        read = time.perf_counter() - start
        found = compare_and_write(ASSIGNMENT, codes, root / "report")
        wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu0
    finally:
        shutil.rmtree(root, ignore_errors=True)
    pairs = args.n * (args.n - 1) // 2
    print("| submissions | pairs | with stub code | flagged | read notebooks (s) | compare + pages (s) "
          "| total wall (s) | CPU (s) | load average (1, 5, 15 min) |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {args.n} | {pairs} | {found.compared} | {len(found.pairs)} | {read:.1f} | {wall - read:.1f} | "
          f"{wall:.1f} | {cpu:.1f} | {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} |")


if __name__ == "__main__":
    main()
