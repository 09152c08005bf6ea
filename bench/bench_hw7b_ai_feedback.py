"""Benchmark of hw7b_ai_feedback: offline, iterative and online DPO and PPO at matched KL, and a policy trained on a
learned judge with planted biases, with and without debiasing; 3 seeds.

    python bench/bench_hw7b_ai_feedback.py                 # seeds 0, 1, 2 one after the other, then the tables
    python bench/bench_hw7b_ai_feedback.py --seed 1        # one seed, to bench/results/hw7b_ai_feedback.seed1.json
    python bench/bench_hw7b_ai_feedback.py --merge         # merge the per-seed files into bench/results/hw7b_ai_feedback.json
    python bench/bench_hw7b_ai_feedback.py --budgets       # FAST notebook and one complete submission graded, timed
    python bench/bench_hw7b_ai_feedback.py --budgets --paired COMMIT   # and the grading with COMMIT's suite, alternately

Each seed executes every code cell of the solution notebook at its full budget (``FAST = False``) with
``SEED`` set to the seed, so the benchmark's numbers are the notebook's and the wall time of seed 0 is the
notebook's full budget. The notebook loads the judge and PPO's policies made by
``datasets/scripts/make_hw7b_models.py`` at seed 0; for the other seeds both are made again here with that
seed (the judge fitted to freshly drawn biased labels, PPO run again), by the same functions. The settings
(rounds, batch, beta, the step size, the KL levels of the matched comparison) are the notebook's, fixed before
the first run; the gold reward is only read.
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
NOTEBOOK = REPO / "solutions" / "hw7b_ai_feedback" / "hw7b_ai_feedback.ipynb"
RESULTS = REPO / "bench" / "results"


def seed_file(seed: int) -> Path:
    return RESULTS / f"hw7b_ai_feedback.seed{seed}.json"


def run_seed(seed: int, fast: bool = False) -> dict:
    """Execute the notebook's code cells with ``SEED = seed`` and read its results back."""
    import matplotlib

    matplotlib.use("Agg")
    import nbformat
    import torch

    sys.path.insert(0, str(REPO / "datasets" / "scripts"))
    import make_hw7b_models as M
    from rlcourse import ai_feedback as A
    from rlcourse.lm import load_sft

    torch.set_num_threads(1)
    made = {}
    if seed != 0:
        sft = load_sft()
        t0 = time.perf_counter()
        judge = M.fit_judge(sft, 3000, 150, seed)
        curve = {n: policy for n, (policy, _) in M.ppo_curve(sft, seed, 0.05).items()}
        for n, policy in curve.items():
            policy.metadata = {"iteration": n, "kl_coef": 0.05, "seed": seed}
        made["instructor_models_s"] = time.perf_counter() - t0
        made["judge_metadata"] = judge.metadata
        A.load_judge = lambda: judge                       # the notebook calls A.load_judge() and A.load_ppo_curve()
        A.load_ppo_curve = lambda: curve
    ns: dict = {"__name__": "__bench__"}
    t0 = time.perf_counter()
    for cell in nbformat.read(NOTEBOOK, as_version=4).cells:
        if cell.cell_type != "code":
            continue
        source = cell.source
        if "parameters" in cell.metadata.get("tags", []):
            source = f"FAST = {fast}\nSEED = {seed}"
        with contextlib.redirect_stdout(io.StringIO()) as out:
            exec(compile(source, f"<{cell.metadata.get('nbgrader', {}).get('grade_id', 'cell')}>", "exec"), ns)
        text = out.getvalue()
        if text.strip():
            print(text.rstrip(), file=sys.stderr, flush=True)
    notebook_s = time.perf_counter() - t0

    judge, pair_a, pair_b = ns["judge"], ns["pair_a"], ns["pair_b"]
    p_ab, p_ba = judge(pair_a, pair_b), judge(pair_b, pair_a)
    agreement = {"simulated person": A.agreement_with_gold(A.SimulatedPerson(seed=seed + 1), pair_a, pair_b),
                 "rule-list critic": A.agreement_with_gold(ns["critic"], pair_a, pair_b)}
    agreement.update({name: A.agreement_with_gold(f, pair_a, pair_b) for name, f in ns["annotators"].items()})
    return {
        "notebook_s": notebook_s, **made,
        "judge": {"position": judge.position, "first_preferred": float((p_ab > 0.5).float().mean()),
                  "consistent": float(ns["consistent"].float().mean()), "length_slope": ns["slope"]},
        "agreement": agreement,
        "matched": {name: {str(k): (None if np.isnan(g) else g) for k, g in zip(ns["TARGET_KLS"], v)}
                    for name, v in ns["matched"].items()},
        "curves": ns["curves"],
        "judge_table": ns["table"],
        "sft_gold": ns["sft_eval"]["gold"],
    }


def ms(values, fmt="{:+.3f}") -> str:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if len(v) == 0:
        return "–"
    text = (fmt + " ± " + fmt.replace("+", "")).format(v.mean(), v.std())
    return text + (f" ({len(v)} of {len(values)} seeds)" if len(v) < len(values) else "")


def print_tables(result: dict) -> None:
    seeds = result["seeds"]
    keys = sorted(seeds)
    kls = list(next(iter(seeds.values()))["matched"]["online DPO"])
    print(f"\n### Gold reward at matched KL ({len(keys)} seeds, mean ± sd; {result['settings']})\n")
    print("| method | " + " | ".join(f"gold at KL {k}" for k in kls) + " | final KL | final gold |")
    print("|---|" + "---:|" * (len(kls) + 2))
    for m in seeds[keys[0]]["matched"]:
        cells = [ms([seeds[s]["matched"][m][k] for s in keys]) for k in kls]
        fk = ms([seeds[s]["curves"][m][-1]["kl"] for s in keys], "{:.2f}")
        fg = ms([seeds[s]["curves"][m][-1]["gold"] for s in keys])
        print(f"| {m} | " + " | ".join(cells) + f" | {fk} | {fg} |")
    print(f"| SFT | | | | 0 | {ms([seeds[s]['sft_gold'] for s in keys])} |")
    print("\n### Online DPO on each annotator (end of run)\n")
    print("| annotator | length | gold | judge score | KL | judge's win rate vs SFT, policy first | both orders |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for m in seeds[keys[0]]["judge_table"]:
        col = lambda k: [seeds[s]["judge_table"][m][k] for s in keys]  # noqa: E731
        print(f"| {m} | {ms(col('length'), '{:.1f}')} | {ms(col('gold'))} | {ms(col('judge'), '{:+.2f}')} | "
              f"{ms(col('kl'), '{:.2f}')} | {ms(col('win_first'), '{:.2f}')} | {ms(col('win_both'), '{:.2f}')} |")
    print("\n### Annotators on held-out pairs of SFT samples\n")
    print("| annotator | agrees with gold (pairs it decides) | decided |")
    print("|---|---:|---:|")
    for m in seeds[keys[0]]["agreement"]:
        print(f"| {m} | {ms([seeds[s]['agreement'][m]['agreement'] for s in keys], '{:.3f}')} | "
              f"{ms([seeds[s]['agreement'][m]['decided'] for s in keys], '{:.2f}')} |")
    j = lambda k: [seeds[s]["judge"][k] for s in keys]  # noqa: E731
    print(f"\nJudge: fitted position offset {ms(j('position'), '{:.2f}')} (planted 1.0); prefers the review shown first on "
          f"{ms(j('first_preferred'), '{:.3f}')} of pairs; consistent verdicts {ms(j('consistent'), '{:.3f}')}; "
          f"score slope {ms(j('length_slope'), '{:.3f}')} logits per token (planted 0.25). Notebook wall time per seed: "
          f"{ms([seeds[s]['notebook_s'] for s in keys], '{:.0f}')} s.")


def merge() -> dict:
    from bench.run_record import meta

    seeds = {p.stem.split("seed")[-1]: json.loads(p.read_text()) for p in sorted(RESULTS.glob("hw7b_ai_feedback.seed*.json"))}
    if not seeds:
        raise SystemExit("no per-seed results: run with --seed N first")
    result = {"meta": meta(["solutions/hw7b_ai_feedback", "rlcourse/ai_feedback.py", "bench/bench_hw7b_ai_feedback.py"]),
              "command": "python bench/bench_hw7b_ai_feedback.py",
              "settings": "40 rounds of 64 pairs per DPO run (2,560 labels), beta 0.1, AdamW 2e-4, iterative: sampler "
                          "refreshed every 10 rounds; PPO: hw5's, KL coefficient 0.05, hw6's reward model, 30 iterations "
                          "of 64; 128 evaluation prompts",
              "seeds": seeds}
    (RESULTS / "hw7b_ai_feedback.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def _grade_once(tree: Path = REPO) -> dict:
    """``python -m autograder grade`` of the complete sample with the suite of ``tree`` (a checkout of the course, this
    one by default): wall seconds with start-up, the grading's own execution time, the load just before."""
    import os
    import subprocess
    import tempfile

    env = dict(os.environ)
    if tree != REPO:  # an earlier commit unpacked elsewhere: its code, suites and reference (PYTHONPATH wins over the
        env.update(RLCOURSE_REPO=str(tree), PYTHONPATH=str(tree))  # editable install)
    load = [round(x, 2) for x in os.getloadavg()]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "autograder", "grade", "hw7b_ai_feedback",
                        str(REPO / "autograder" / "samples" / "hw7b_ai_feedback" / "complete.ipynb"), "--out", tmp],
                       check=True, capture_output=True, cwd=tree, env=env)
        wall = time.perf_counter() - t0
        graded = json.loads((Path(tmp) / "results.json").read_text())
    return {"wall_s": round(wall, 2), "execution_time_s": graded["execution_time"], "score": graded["score"],
            "load_before": load}


def budgets(repeats: int = 2, paired: str | None = None) -> dict:
    """Wall time of the solution notebook with ``FAST = True`` in a real kernel, and of grading the complete sample
    (start-up included, ``python -m autograder grade``), each ``repeats`` times, with the load at the time. With
    ``paired`` (a commit), the grading is also timed with that commit's suite and code, alternating with this
    checkout's, so that both see the same load."""
    import os
    import subprocess
    import tempfile

    from autograder.authoring.nbrun import run_notebook
    from bench.run_record import meta

    fast, grade, fast_load = [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            fast_load.append([round(x, 2) for x in os.getloadavg()])
            t0 = time.perf_counter()
            report = run_notebook(NOTEBOOK, {"FAST": True}, timeout=300, cwd=Path(tmp))
            fast.append(round(time.perf_counter() - t0, 2))
            assert report.ok, report.describe("hw7b_ai_feedback")
        grade.append(_grade_once())
    out = {"meta": meta(), "fast_notebook_s": fast, "fast_load_before": fast_load,
           "complete_graded_s": [g["wall_s"] for g in grade], "complete_graded": grade,
           "load_after": [round(x, 2) for x in os.getloadavg()]}
    if paired:
        with tempfile.TemporaryDirectory() as old:
            archive = subprocess.run(["git", "archive", paired], cwd=REPO, capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", old], input=archive, check=True)
            rows = []
            for _ in range(repeats + 1):
                rows.append({"this": _grade_once(), "earlier": _grade_once(Path(old))})
        out["paired"] = {"earlier_commit": paired, "rows": rows,
                         "this_median_s": float(np.median([r["this"]["wall_s"] for r in rows])),
                         "earlier_median_s": float(np.median([r["earlier"]["wall_s"] for r in rows]))}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--seed", type=int, help="run this one seed and write its file")
    parser.add_argument("--merge", action="store_true", help="merge the per-seed files and print the tables")
    parser.add_argument("--budgets", action="store_true", help="time the FAST notebook and one grading, record them")
    parser.add_argument("--paired", metavar="COMMIT",
                        help="with --budgets: also time the grading with COMMIT's suite, alternating with this one's")
    parser.add_argument("--smoke", action="store_true", help="FAST budgets, results to a scratch folder (checks the script)")
    args = parser.parse_args()
    global RESULTS
    if args.smoke:
        RESULTS = Path("/tmp/hw7b_bench_smoke")
    RESULTS.mkdir(parents=True, exist_ok=True)
    if args.budgets:
        path = RESULTS / "hw7b_ai_feedback.json"
        result = json.loads(path.read_text())
        result["budgets"] = budgets(paired=args.paired)
        path.write_text(json.dumps(result, indent=1) + "\n")
        print(json.dumps(result["budgets"], indent=1))
        return
    todo = [] if args.merge else ([args.seed] if args.seed is not None else list(range(args.seeds)))
    for seed in todo:
        t0 = time.perf_counter()
        out = run_seed(seed, fast=args.smoke)
        out["seconds"] = time.perf_counter() - t0
        from bench.run_record import meta

        out["meta"] = meta(["solutions/hw7b_ai_feedback", "rlcourse/ai_feedback.py"])
        seed_file(seed).write_text(json.dumps(out) + "\n")
        print(f"seed {seed}: {out['seconds']:.0f} s", file=sys.stderr, flush=True)
    if args.seed is None:
        print_tables(merge())


if __name__ == "__main__":
    main()
