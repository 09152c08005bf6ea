"""Benchmark of hw7_verifier_rl: zero-shot -> SFT -> expert iteration -> GRPO / Dr. GRPO / RLOO on a pass/fail
checker, with pass@1 and pass@k (k up to 64) against the samples drawn, three seeds.

    python bench/bench_hw7_verifier_rl.py                 # the solution notebook's full budget, all its seeds
    python bench/bench_hw7_verifier_rl.py --fast          # the same at FAST = True (a smoke run: numbers meaningless)
    python bench/bench_hw7_verifier_rl.py --budgets --mutants   # also: FAST under a kernel, one grading, the mutants
    python bench/bench_hw7_verifier_rl.py --budgets-only --full-kernel   # only the budgets (full notebook too), merged in

Every number is the solution notebook's own: its code cells (setup, your-function stubs with the reference
solutions, experiments) are executed in order in this process with ``FAST`` set, so the settings are the
notebook's settings cell (recorded in ``budget``) and seed ``s`` here is seed ``s`` of the notebook. Per stage and
seed the file holds pass@k for every k in ``KS``, the format rate and the mean answer length; per method and seed
the pass@k curve against the samples drawn, the fraction of all-equal groups and the answer length over training;
and the sharpening verdict of the notebook (pass@1 and pass@64 minus SFT's, problems lost and gained). The wall
time of the whole execution is ``exec_seconds`` (the full budget: every code cell, in order, in one process);
``--budgets`` adds the FAST notebook's wall time under a real kernel (``autograder.authoring.nbrun``) and the time
to grade the complete sample submission; ``--mutants`` records the mutation report.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

NOTEBOOK = REPO / "solutions" / "hw7_verifier_rl" / "hw7_verifier_rl.ipynb"
RESULTS = REPO / "bench" / "results"
SETTINGS = ("SEEDS", "N_SFT", "SFT_STEPS", "N_EVAL", "N_SAMPLES", "KS", "GROUP", "RL_PROMPTS", "RL_ITERS", "RL_LR",
            "EI_ROUNDS", "EI_PROMPTS", "EI_STEPS", "EI_KEEP", "N_EVALS")


def execute(fast: bool) -> tuple[dict, float]:
    """The notebook's code cells run in order in a fresh namespace (FAST set in place of its parameters cell)."""
    import matplotlib
    import nbformat

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ns: dict = {"__name__": "__bench__"}
    t0 = time.perf_counter()
    for i, cell in enumerate(nbformat.read(NOTEBOOK, as_version=4).cells):
        if cell.cell_type != "code":
            continue
        src = f"FAST = {fast}" if "parameters" in cell.metadata.get("tags", []) else cell.source
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(src, f"<cell {i}>", "exec"), ns)
        plt.close("all")
        print(f"  cell {i}: {time.perf_counter() - t0:.0f} s", flush=True)
    return ns, time.perf_counter() - t0


def summarise(ns: dict) -> dict:
    """Per-seed values of every stage and method, in plain JSON types."""
    def ev(e: dict) -> dict:
        return {"pass": {str(k): float(v) for k, v in e["pass"].items()}, "format": float(e["format"]),
                "length": float(e["length"]), "solved_once": int((np.asarray(e["c"]) > 0).sum())}

    stages = {name: {str(s): ev(e) for s, e in per_seed.items()} for name, per_seed in ns["stages"].items()}
    curves = {}
    for name, per_seed in ns["runs"].items():
        curves[name] = {}
        for s, run in per_seed.items():
            log = run["log"]
            curves[name][str(s)] = {
                "eval_samples": [int(n) for n, _ in run["curve"]],
                "eval_pass": {str(k): [float(e["pass"][k]) for _, e in run["curve"]] for k in ns["KS"]},
                "samples": [int(x) for x in log["samples"]], "reward": [float(x) for x in log["reward"]],
                "equal_groups": [float(x) for x in log["equal_groups"]], "length": [float(x) for x in log["length"]],
                "train_seconds": float(log["seconds"][-1])}
    verdict = {name: {str(s): {k: (bool(v) if isinstance(v, (bool, np.bool_)) else float(v)) for k, v in row.items()}
                      for s, row in zip(ns["SEEDS"], rows)} for name, rows in ns["verdict"].items()}
    return {"stages": stages, "curves": curves, "verdict": verdict}


def table(result: dict) -> str:
    k = str(result["budget"]["KS"][-1])
    lines = [f"| stage | pass@1 | pass@{k} | well-formed | length |", "|---|---:|---:|---:|---:|"]
    for name, per_seed in result["stages"].items():
        def ms(key, sub=None):
            v = np.array([(e[key][sub] if sub else e[key]) for e in per_seed.values()])
            return f"{v.mean():.3f} ± {v.std(ddof=1) if len(v) > 1 else 0.0:.3f}"
        lines.append(f"| {name} | {ms('pass', '1')} | {ms('pass', k)} | {ms('format')} | {ms('length')} |")
    return "\n".join(lines)


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's reaped children: the kernel, once it has been shut down. On a
    busy machine the wall time of a run says more about the other jobs than about the notebook; its CPU time is
    what an idle machine would need (the notebook runs torch on one thread)."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def budgets(full_kernel: bool = False) -> dict:
    """The notebook under a Jupyter kernel at FAST = True (and at the full budget with ``full_kernel``), and one
    grading of the complete sample submission, each timed with the load beside it."""
    import subprocess
    import tempfile

    from autograder.authoring.nbrun import run_notebook

    out = {}
    for name, fast in (("notebook_fast", True),) + ((("notebook_full", False),) if full_kernel else ()):
        load_before, cpu_before = meta()["load"], _children_cpu()
        with tempfile.TemporaryDirectory() as tmp:
            report = run_notebook(NOTEBOOK, {"FAST": fast}, timeout=3600, cwd=tmp)
        assert report.ok, report
        out[name] = {"seconds": round(report.seconds, 1), "load_before": load_before, "load": meta()["load"],
                     "kernel_cpu_seconds": round(_children_cpu() - cpu_before, 1)}
        print(f"{name}: {report.seconds:.1f} s (load before {load_before}, after {out[name]['load']})", flush=True)
    sample = REPO / "autograder" / "samples" / "hw7_verifier_rl" / "complete.ipynb"
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "autograder", "grade", "hw7_verifier_rl", str(sample), "--out", tmp],
                              cwd=REPO, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
    assert done.returncode == 0, done.stderr
    out["grade_complete"] = {"seconds": round(seconds, 1), "load": meta()["load"],
                             "summary": done.stdout.strip().splitlines()[0]}
    return out


def mutants() -> dict:
    """``python -m autograder mutants hw7_verifier_rl``, run now: per stub, mutants made, equivalent, killed."""
    import subprocess

    subprocess.run([sys.executable, "-m", "autograder", "mutants", "hw7_verifier_rl"], cwd=REPO, check=True,
                   capture_output=True)
    report = json.loads((REPO / "build" / "mutants" / "hw7_verifier_rl" / "report.json").read_text())
    return {stub: {k: row[k] for k in ("made", "equivalent", "killed_by_suite", "killed_by_check", "survivors",
                                       "suite_kill_rate")} for stub, row in report.items()}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fast", action="store_true", help="FAST = True (a smoke run; written to a .fast.json)")
    parser.add_argument("--budgets", action="store_true",
                        help="also time the notebook under a Jupyter kernel at FAST = True, and one grading")
    parser.add_argument("--full-kernel", action="store_true", help="with --budgets: the full notebook under a kernel too")
    parser.add_argument("--mutants", action="store_true", help="also run the mutation report and record it")
    parser.add_argument("--budgets-only", action="store_true",
                        help="only the budgets (with --full-kernel: the full notebook too), merged into the results file")
    args = parser.parse_args(argv)
    if args.budgets_only:
        out = RESULTS / "hw7_verifier_rl.json"
        result = json.loads(out.read_text())
        result["budgets"] = {"meta": meta(["rlcourse", "solutions/hw7_verifier_rl", "datasets/hw7", "autograder"]),
                             **budgets(full_kernel=args.full_kernel)}
        out.write_text(json.dumps(result, indent=1) + "\n")
        print(json.dumps(result["budgets"], indent=1))
        return
    ns, seconds = execute(args.fast)
    result = {"meta": meta(["rlcourse", "solutions/hw7_verifier_rl", "datasets/hw7"]),
              "command": "python bench/bench_hw7_verifier_rl.py" + (" --fast" if args.fast else ""),
              "budget": {k: ns[k] for k in SETTINGS}, "base": dict(ns["base"].metadata),
              "exec_seconds": round(seconds, 1), **summarise(ns)}
    if args.budgets:
        result["budgets"] = budgets(full_kernel=args.full_kernel)
    if args.mutants:
        result["mutants"] = mutants()
    out = RESULTS / ("hw7_verifier_rl.fast.json" if args.fast else "hw7_verifier_rl.json")
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(table(result))
    for name, per_seed in result["verdict"].items():
        print(name, {s: (round(r["d_pass1"], 3), round(r["d_passK"], 3), int(r["lost"]), int(r["gained"]))
                     for s, r in per_seed.items()})
    print(f"-> {out} ({seconds:.0f} s)")


if __name__ == "__main__":
    main()
