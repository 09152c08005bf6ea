"""Answers that know nothing of any stub, in every stub at once or in one stub at a time: what they earn.

    python bench/bench_generic_answers.py [--ids hw0_setup ...] [--record]
    python bench/bench_generic_answers.py --one-stub [--record]   # each stub alone, the rest solved (~15 min)

Each suite ships one trivial answer per stub (``trivial_answers.py``, graded by
``tests/core/test_adversarial_suites.py``). This is the wider, generic family a student tries before reading a
docstring: every stub of a student notebook replaced by a function (or, for a class stub, a class whose every
method) that returns the same thing whatever it is given: the first argument back, zeros or ones shaped like it,
0, 0.5, its mean, None, an empty list or dict, a torch zero with a gradient, random numbers shaped like it, its
sum over the last axis. Each (assignment, answer) notebook
is graded in one batch over all the assignments (``python -m autograder batch ID,ID,...``), and the record is the
points each earned and which stub and test gave them. Every one should earn nothing; the script exits 1 if any
did. ``--record`` writes ``bench/results/generic_answers.json``.

``--one-stub`` asks the same of each stub alone: every other stub is the solution's, so a test of the generic stub that
also runs a classmate stub (its own ``train_bc`` inside ``dagger``, say) finds that one correct, which is how a
student who finished all but one stub hands in. Only the generic stub's points count (the solved ones earn theirs).
``--record`` then writes ``bench/results/generic_answers_one_stub.json``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

RESULTS = REPO / "bench" / "results" / "generic_answers.json"
RESULTS_ONE_STUB = REPO / "bench" / "results" / "generic_answers_one_stub.json"
ANSWERS = {
    "first argument": "args[0] if args else None",
    "zeros like it": "np.zeros_like(np.asarray(args[0], dtype=float)) if args else 0.0",
    "ones like it": "np.ones_like(np.asarray(args[0], dtype=float)) if args else 1.0",
    "0": "0.0",
    "0.5": "0.5",
    "its mean": "float(np.mean(np.asarray(args[0], dtype=float))) if args else 0.0",
    "None": "None",
    "[]": "[]",
    "{}": "{}",
    "torch zero with a gradient": "__import__('torch').zeros((), requires_grad=True)",
    "random like it": "np.random.default_rng().normal(size=np.shape(args[0])) if args else 0.0",
    "its sum over the last axis": "np.asarray(args[0], dtype=float).sum(axis=-1) if args else 0.0",
}
"""Each generic answer, as the expression every stub returns."""


def stub_source(name: str, value: str) -> str:
    """A stub cell that returns ``value`` whatever it is given (a class stub: from every method)."""
    if name[:1].isupper():
        return (f"import numpy as np\nclass {name}:\n    def __init__(self, *args, **kwargs):\n        pass\n"
                f"    def __getattr__(self, attr):\n        def any_method(*args, **kwargs):\n            return {value}\n"
                f"        return any_method\n    def __call__(self, *args, **kwargs):\n        return {value}\n")
    return f"import numpy as np\ndef {name}(*args, **kwargs):\n    return {value}\n"


def slug(answer: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in answer).strip("_") or "answer"


def notebooks(ids: list[str], one_stub: bool) -> list[tuple[str, str | None, str, object]]:
    """(assignment, the generic stub or None for all of them, answer, notebook) for every case."""
    from autograder.authoring.samples import _with_stubs, solution_sources
    from autograder.core import course

    cases = []
    for assignment in ids:
        if one_stub:
            solved = solution_sources(assignment)
            for stub in solved:
                for answer, value in ANSWERS.items():
                    cases.append((assignment, stub, answer,
                                  _with_stubs(assignment, {**solved, stub: stub_source(stub, value)})))
        else:
            for answer, value in ANSWERS.items():
                cases.append((assignment, None, answer, _with_stubs(
                    assignment, {n: stub_source(n, value) for n in course.stub_names(assignment)})))
    return cases


def main() -> int:
    import nbformat

    from autograder.core import course
    from autograder.core.store import load_result

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ids", nargs="*", help="assignments (default: every one with a hidden suite)")
    parser.add_argument("--one-stub", action="store_true", help="each stub alone generic, the others solved")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--record", action="store_true")
    args = parser.parse_args()
    ids = args.ids or [a for a in course.assignment_ids() if course.suite_dir(a).is_dir()]
    run_meta = meta(["autograder", "solutions", "assignments"])
    cases = notebooks(ids, args.one_stub)
    with tempfile.TemporaryDirectory() as tmp:
        folder, out = Path(tmp) / "handed_in", Path(tmp) / "graded"
        names = []
        for assignment, stub, answer, notebook in cases:
            name = f"{stub}__{slug(answer)}" if stub else slug(answer)
            (folder / assignment).mkdir(parents=True, exist_ok=True)
            nbformat.write(notebook, str(folder / assignment / f"{name}.ipynb"))
            names.append(name)
        print(f"grading {len(cases)} notebooks over {len(ids)} assignments", flush=True)
        start = time.monotonic()
        submitted = folder if len(ids) > 1 else folder / ids[0]  # several: ID/ each; one: its notebooks
        done = subprocess.run([sys.executable, "-m", "autograder", "batch", ",".join(ids), str(submitted), "--out",
                               str(out), "--jobs", str(args.jobs)], cwd=REPO, capture_output=True, text=True)
        seconds = time.monotonic() - start
        if done.returncode != 0:
            print(done.stdout[-2000:], done.stderr[-2000:], sep="\n")
            return 2
        rows, earners = [], 0
        for (assignment, stub, answer, _), name in zip(cases, names):
            graded = out / assignment if len(ids) > 1 else out
            result = load_result(graded / name)  # scores as the grader computes them (result.json holds tests only)
            if result is None:
                raise SystemExit(f"the batch left no readable result for {assignment}/{name}")
            earned = {s.name: [t.name for t in s.tests if t.passed]
                      for s in result.stubs if s.score > 0 and stub in (None, s.name)}
            row = {"assignment": assignment, "answer": answer, "graded": result.has_score and not result.error}
            if stub:  # the solved stubs' full marks are not the generic answer's
                row.update(stub=stub, stub_score=next((s.score for s in result.stubs if s.name == stub), None))
            else:
                row.update(score=result.score, max_score=result.max_score)
            rows.append({**row, "earned": earned})
            earners += bool(earned) or not row["graded"]
    for row in rows:
        if row["earned"] or not row["graded"]:
            print(f"{row['assignment']} / {row.get('stub', 'every stub')} / {row['answer']}: {row['earned']}")
    what = "stubs, each alone" if args.one_stub else "assignment(s)"
    count = len({(r["assignment"], r.get("stub")) for r in rows})
    print(f"{len(rows)} notebooks ({count} {what} x {len(ANSWERS)} answers) graded in {seconds:.0f} s; "
          f"{earners} earned a point or were not graded")
    if args.record:
        run_meta["load_at_end"] = [round(x, 2) for x in __import__("os").getloadavg()]
        description = ("Generic answers (the same value whatever the input) in one stub at a time, every other stub "
                       "the solution's: the points the generic stub earned, and from which test. Every one should "
                       "earn nothing." if args.one_stub else
                       "Generic answers (the same value whatever the input) in every stub of each assignment: "
                       "the points each earned, and from which stub and test. Every one should earn nothing.")
        path = RESULTS_ONE_STUB if args.one_stub else RESULTS
        path.write_text(json.dumps({
            "description": description,
            "command": f"python bench/bench_generic_answers.py{' --one-stub' if args.one_stub else ''} --record",
            "answers": ANSWERS, "notebooks": len(rows), "earned_or_not_graded": earners,
            "seconds": round(seconds, 1), "rows": rows, "meta": run_meta}, indent=1) + "\n")
        print(f"wrote {path}")
    return 1 if earners else 0


if __name__ == "__main__":
    sys.exit(main())
