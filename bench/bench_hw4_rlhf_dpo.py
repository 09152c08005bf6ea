"""Benchmark of hw4_rlhf_dpo: true-reward PPO, RLHF and DPO from the same reference policy, over seeds,
plus the KL-coefficient and beta sweeps that the notebook plots as precomputed. Prints Markdown tables.

    python bench/bench_hw4_rlhf_dpo.py                 # 3 seeds + sweeps (about 10 minutes on 2 idle cores)
    python bench/bench_hw4_rlhf_dpo.py --seeds 0 --no-sweep --steps 20000   # a quick smoke run
    python bench/bench_hw4_rlhf_dpo.py --record        # also refresh datasets/hw4/precomputed.json + MANIFEST

Every run uses the solution notebook's own stubs (``solutions/hw4_rlhf_dpo``) and its budgets with
``FAST = False``: PPO for ``PPO_STEPS`` environment steps, DPO for ``DPO_STEPS`` steps. Every RLHF run
uses the shipped reward model (``datasets/hw4/reward_model.pt``), so RLHF's seeds vary PPO only, and
its wall time includes the model's recorded fit time. Final returns are deterministic (mean action) over 20 seeded
episodes (seed 1000, like the reference's recorded return); KL is the per-step
KL(pi || pi_ref) on the states those episodes visit. Wall times are per run, measured with ``--workers``
runs at a time on a shared 2-core machine, so they include contention: compare them with each other,
not with a solo run; the CPU seconds each run used (``cpu`` in the results, single-threaded torch) are
what a solo run on an idle core would take, roughly. Results go to ``bench/results/hw4_rlhf_dpo.json``.
Runs that an earlier invocation finished with the same settings (interrupted or not) are reused, so
a killed benchmark resumes; ``--fresh`` measures everything again.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from autograder.grader import build_reference

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results" / "hw4_rlhf_dpo.json"
PRECOMPUTED = REPO / "datasets" / "hw4" / "precomputed.json"
FINAL_EPISODES = 20


def solution_namespace() -> dict:
    """The solution notebook's parameters, setup and stub cells, run in a fresh namespace."""
    return build_reference("hw4_rlhf_dpo", {"FAST": os.environ.get("HW4_BENCH_FAST") == "1"})


def _final(ns: dict, policy, reference, reward_fn=None) -> dict:
    return ns["evaluate_policy"](policy, reference, reward_fn, n_episodes=FINAL_EPISODES)


def job(kind: str, seed: int, value: float, steps: int | None, offset: float | None = None) -> dict:
    """One run in a fresh worker: ``kind`` in {reward_model, ppo, rlhf, dpo}; ``value`` is the KL
    coefficient (rlhf) or beta (dpo); ``offset`` is the learned reward's per-step offset b (rlhf;
    default: the notebook's ``REWARD_OFFSET``)."""
    import torch

    ns = solution_namespace()
    torch.set_num_threads(1)
    ns["seed_everything"](seed)
    reference, prefs = ns["load_reference"](), ns["load_hopper_preferences"]()
    ppo_steps = steps or ns["PPO_STEPS"]
    out: dict = {"kind": kind, "seed": seed, "value": value, "steps": ppo_steps}
    cpu0 = time.process_time()
    reward_model = ns["load_reward_model"]()
    rf = ns["reward_function"](reward_model)
    if kind == "reward_model":  # the shipped model, measured here on the held-out pairs
        seg = rf(prefs.obs.reshape(-1, 11), prefs.act.reshape(-1, 3)).reshape(prefs.obs.shape[:2]).sum(1)
        i, j = prefs.test_pairs.T
        out.update(wall=reward_model.metadata["fit_seconds"], ceiling=prefs.info["bayes_ceiling_test"],
                   test_accuracy=ns["preference_accuracy"](seg[i], seg[j], prefs.test_mu))
        return out

    cfg = lambda **kw: ns["PPOConfig"](total_steps=ppo_steps, n_steps=ns["PPO_ENV_STEPS_PER_ROLLOUT"], seed=seed,
                                       eval_every=max(1, ppo_steps // 2048 // 5), **kw)
    curve_eval = lambda rf: (lambda p: ns["evaluate_policy"](p, reference, rf, n_episodes=5))
    if kind == "ppo":
        t0 = time.perf_counter()
        policy, log = ns["ppo"](reference, reference, ns["compute_gae"], ns["ppo_loss"], cfg(), evaluate=curve_eval(None),
                                verbose=False)
        out["wall"] = time.perf_counter() - t0
        out["final"] = _final(ns, policy, reference)
    elif kind == "rlhf":
        rm_wall = reward_model.metadata["fit_seconds"]
        meta = reward_model.metadata
        offset = ns["REWARD_OFFSET"] if offset is None else offset
        wrap = lambda envs: ns["LearnedRewardWrapper"](envs, rf, meta["step_mean"], meta["step_std"], offset)
        out["offset"] = offset
        t0 = time.perf_counter()
        policy, log = ns["ppo"](reference, reference, ns["compute_gae"], ns["ppo_loss"], cfg(kl_coef=value), wrap=wrap,
                                evaluate=curve_eval(rf), verbose=False)
        out["wall"] = time.perf_counter() - t0 + rm_wall
        out["rm_wall"] = rm_wall
        out["final"] = _final(ns, policy, reference, rf)
    elif kind == "dpo":
        pairs = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.train_pairs, prefs.train_mu)
        val = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.test_pairs, prefs.test_mu)
        n = ns["DPO_STEPS"]
        t0 = time.perf_counter()
        policy, log = ns["train_dpo"](reference, reference, ns["dpo_loss"], pairs, value, n_steps=n, val=val,
                                      evaluate=curve_eval(None), eval_every=max(1, n // 5), log_every=max(1, n // 30),
                                      seed=seed, verbose=False)
        out["wall"] = time.perf_counter() - t0
        out["final"] = _final(ns, policy, reference)
        out["val_accuracy"] = log.steps[-1].get("val_accuracy")
    else:
        raise ValueError(kind)
    out["curve"] = log.evals
    out["cpu"] = time.process_time() - cpu0
    return out


def _resumable(partial: Path, steps: int, offset: float) -> list[dict]:
    """Finished runs of an earlier invocation with the same budget: those of an interrupted one (``partial``),
    else those of the last complete one (the results file)."""
    if partial.exists():
        runs = json.loads(partial.read_text())
    elif RESULTS.exists():
        runs = json.loads(RESULTS.read_text())["runs"]
    else:
        return []
    runs = [r for r in runs if r.get("steps") == steps and (r["kind"] != "rlhf" or "offset" in r)]
    return runs


def run_all(jobs: list[tuple], workers: int, partial: Path | None = None, done: list[dict] | None = None) -> list[dict]:
    """Run ``jobs`` in ``workers`` processes; with ``partial``, rewrite that file (``done`` + the new results)
    after every finished job, so that an interrupted benchmark resumes where it stopped."""
    with ProcessPoolExecutor(workers) as pool:
        futures = {pool.submit(job, *j): j for j in jobs}
        results = list(done or [])
        for f in as_completed(futures):
            j, r = futures[f], f.result()
            fin = r.get("final", {})
            print(f"  done {j[0]:12s} seed {j[1]} value {j[2]:<6g} return {fin.get('return', float('nan')):7.1f} "
                  f"kl {fin.get('kl', float('nan')):.3f} wall {r['wall']:.0f} s", flush=True)
            results.append(r)
            if partial is not None:
                partial.write_text(json.dumps(results, indent=1))
    return results


def summarise(results: list[dict], ref_eval: dict, kl_main: float, beta_main: float, offset_main: float, steps: int,
              dpo_steps: int) -> dict:
    def pick(kind, value=None, offset=offset_main):
        return [r for r in results if r["kind"] == kind and (value is None or r["value"] == value)
                and r.get("offset", offset_main) == offset]
    rows = [{"method": "reference", "returns": [ref_eval["return"]], "kls": [0.0], "walls": [0.0]}]
    for method, kind, value in (("PPO, true reward", "ppo", 0.0), (f"RLHF (KL {kl_main:g})", "rlhf", kl_main),
                                (f"DPO (beta {beta_main:g})", "dpo", beta_main)):
        rs = pick(kind, value)
        rows.append({"method": method, "returns": [r["final"]["return"] for r in rs],
                     "kls": [r["final"]["kl"] for r in rs], "walls": [r["wall"] for r in rs],
                     "cpus": [r.get("cpu", np.nan) + r.get("rm_wall", 0.0) for r in rs],
                     "seeds": [r["seed"] for r in rs]})
    rows[0]["cpus"] = [0.0]
    for row in rows:
        row.update(return_mean=float(np.mean(row["returns"])), return_std=float(np.std(row["returns"])),
                   kl_mean=float(np.mean(row["kls"])), wall_mean=float(np.mean(row["walls"])),
                   cpu_mean=float(np.mean(row["cpus"])))
    frontier = {"RLHF": [], "DPO": []}
    for kind, name, param in (("rlhf", "RLHF", "kl"), ("dpo", "DPO", "beta")):
        for value in sorted({r["value"] for r in pick(kind)}):
            rs = pick(kind, value)
            frontier[name].append({"param": param, "value": value, "n_seeds": len(rs),
                                   "return": float(np.mean([r["final"]["return"] for r in rs])),
                                   "kl": float(np.mean([r["final"]["kl"] for r in rs]))})
    over = {}
    low = min((r["offset"] for r in results if r["kind"] == "rlhf" and "offset" in r), default=offset_main)
    for label, value, b in ((f"b = {offset_main:g}, KL {kl_main:g}", kl_main, offset_main),
                            (f"b = {offset_main:g}, no KL", 0.0, offset_main), (f"b = {low:g}, no KL", 0.0, low)):
        rs = [r for r in pick("rlhf", value, offset=b) if r["seed"] == 0]
        if rs and label not in over:
            over[label] = {k: [e[k] for e in rs[0]["curve"]] for k in ("step", "return", "learned_return", "kl", "length")}
    offsets = []
    for b in sorted({r.get("offset", offset_main) for r in results if r["kind"] == "rlhf"}):
        rs = pick("rlhf", kl_main, offset=b)
        if rs:
            fin = [r["final"] for r in rs]
            offsets.append({"offset": b, "kl_coef": kl_main, "seeds": [r["seed"] for r in rs],
                            "returns": [f["return"] for f in fin], "return": float(np.mean([f["return"] for f in fin])),
                            "return_std": float(np.std([f["return"] for f in fin])),
                            "kl": float(np.mean([f["kl"] for f in fin])), "length": float(np.mean([f["length"] for f in fin]))})
    budget = (f"{steps:,} PPO environment steps per run, {dpo_steps:,} DPO steps; final returns over "
              f"{FINAL_EPISODES} deterministic episodes; mean ± std over seeds; RLHF with reward offset "
              f"b = {offset_main:g} unless noted")
    return {"budget": budget, "reward_offset": offset_main, "table": rows, "frontier": frontier,
            "overoptimisation": over, "offsets": offsets}


def print_tables(summary: dict, rms: list[dict]) -> None:
    rows = summary["table"]
    ref, ceiling = rows[0]["return_mean"], rows[1]["return_mean"]
    print(f"\n### hw4_rlhf_dpo: true return from the same reference policy ({summary['budget']})\n")
    print("| method | seeds | true return | vs reference | % of true-reward PPO | KL to reference (nats/step) "
          "| wall time, shared (s) | CPU time (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for row in rows:
        n = len(row["returns"])
        print(f"| {row['method']} | {n} | {row['return_mean']:.0f} ± {row['return_std']:.0f} | "
              f"{row['return_mean'] - ref:+.0f} ({100 * (row['return_mean'] / ref - 1):+.0f}%) | "
              f"{100 * row['return_mean'] / ceiling:.0f}% | {row['kl_mean']:.3f} | {row['wall_mean']:.0f} | "
              f"{row.get('cpu_mean', float('nan')):.0f} |")
    if rms:
        rm = rms[0]
        print(f"\nReward model (datasets/hw4/reward_model.pt): held-out accuracy {rm['test_accuracy']:.3f} "
              f"(annotator's own rule: {rm['ceiling']:.3f}); recorded fit time {rm['wall']:.0f} s.")
    print("\n### Return–KL frontier (seed 0 unless noted)\n")
    print("| method | parameter | seeds | true return | KL (nats/step) |")
    print("|---|---|---:|---:|---:|")
    for name, pts in summary["frontier"].items():
        for p in pts:
            print(f"| {name} | {p['param']} = {p['value']:g} | {p['n_seeds']} | {p['return']:.0f} | {p['kl']:.3f} |")
    if summary.get("offsets"):
        print("\n### RLHF's reward offset b (KL coefficient as in the table)\n")
        print("| offset b | seeds | true return | per seed | episode length | KL (nats/step) |")
        print("|---:|---:|---:|---|---:|---:|")
        for o in summary["offsets"]:
            print(f"| {o['offset']:g} | {len(o['seeds'])} | {o['return']:.0f} ± {o['return_std']:.0f} | "
                  + ", ".join(f"{v:.0f}" for v in o["returns"]) + f" | {o['length']:.0f} | {o['kl']:.3f} |")
    for label, c in summary["overoptimisation"].items():
        print(f"\nOver-optimisation, {label}: true return " + " → ".join(f"{v:.0f}" for v in c["return"])
              + "; learned return " + " → ".join(f"{v:.0f}" for v in c["learned_return"]))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--steps", type=int, default=None, help="PPO steps per run (default: the notebook's PPO_STEPS)")
    p.add_argument("--kl", type=float, default=None, help="RLHF's KL coefficient in the table (default: KL_COEF)")
    p.add_argument("--beta", type=float, default=None, help="DPO's beta in the table (default: the notebook's BETA)")
    p.add_argument("--kl-sweep", type=float, nargs="*", default=[0.0, 0.01, 0.03, 0.1, 0.3])
    p.add_argument("--beta-sweep", type=float, nargs="*", default=[0.03, 0.3, 1.0])
    p.add_argument("--offset-sweep", type=float, nargs="*", default=[1.0, 3.0, 8.0],
                   help="other values of the learned reward's per-step offset b, run with --kl on every seed")
    p.add_argument("--no-sweep", action="store_true")
    p.add_argument("--fresh", action="store_true", help="measure every run again (by default, runs with the same "
                   "settings that an earlier invocation finished, interrupted or not, are reused)")
    p.add_argument("--workers", type=int, default=2, help="runs at a time (wall times grow when they share cores)")
    p.add_argument("--record", action="store_true", help="write datasets/hw4/precomputed.json and record it")
    p.add_argument("--smoke", action="store_true", help="the notebook's FAST budgets, results not written")
    p.add_argument("--tables-only", action="store_true", help="reprint (and with --record, re-record) the tables "
                   "from bench/results/hw4_rlhf_dpo.json without running anything")
    args = p.parse_args(argv)
    if args.smoke:
        os.environ["HW4_BENCH_FAST"] = "1"
        global RESULTS, FINAL_EPISODES
        RESULTS, FINAL_EPISODES = Path(os.environ.get("TMPDIR", "/tmp")) / "hw4_bench_smoke.json", 2

    ns = solution_namespace()
    steps, dpo_steps = args.steps or ns["PPO_STEPS"], ns["DPO_STEPS"]
    args.kl = ns["KL_COEF"] if args.kl is None else args.kl
    args.beta = ns["BETA"] if args.beta is None else args.beta
    offset = ns["REWARD_OFFSET"]
    if args.tables_only:
        saved = json.loads(RESULTS.read_text())
        ref_row = saved["summary"]["table"][0]
        summary = summarise(saved["runs"], {"return": ref_row["return_mean"]}, saved["args"]["kl"], saved["args"]["beta"],
                            saved["summary"].get("reward_offset", offset), steps, dpo_steps)
        RESULTS.write_text(json.dumps({**saved, "summary": summary}, indent=1))
        print_tables(summary, saved["reward_models"])
        if args.record:
            _record(summary, saved["args"])
        return
    start = time.perf_counter()
    rms = [job("reward_model", args.seeds[0], 0.0, None)]
    jobs = [(kind, s, v, steps) for s in args.seeds for kind, v in (("ppo", 0.0), ("rlhf", args.kl), ("dpo", args.beta))]
    if not args.no_sweep:
        jobs += [("rlhf", 0, v, steps) for v in args.kl_sweep if v != args.kl]
        jobs += [("dpo", 0, v, steps) for v in args.beta_sweep if v != args.beta]
        jobs += [("rlhf", s, args.kl, steps, b) for s in args.seeds for b in args.offset_sweep if b != offset]
        if args.offset_sweep:  # the over-optimisation panel: the smallest offset without the KL penalty
            jobs.append(("rlhf", 0, 0.0, steps, min(args.offset_sweep)))
    partial = RESULTS.with_suffix(".partial.json")
    done = [] if args.fresh else _resumable(partial, steps, offset)
    key = lambda kind, seed, value, offset_: (kind, seed, value, offset_ if kind == "rlhf" else None)
    finished = {key(r["kind"], r["seed"], r["value"], r.get("offset")) for r in done}
    todo = [j for j in jobs if key(j[0], j[1], j[2], j[4] if len(j) > 4 else offset) not in finished]
    print(f"{len(jobs)} runs ({len(jobs) - len(todo)} reused from an earlier invocation), {args.workers} at a time",
          flush=True)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    results = run_all(todo, args.workers, partial, done)
    reference = ns["load_reference"]()
    ref_eval = ns["evaluate_policy"](reference, reference, n_episodes=FINAL_EPISODES)
    summary = summarise(results, ref_eval, args.kl, args.beta, offset, steps, dpo_steps)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({"args": vars(args), "reward_models": rms, "runs": results, "summary": summary,
                                   "total_wall": time.perf_counter() - start}, indent=1))
    partial.unlink(missing_ok=True)
    print_tables(summary, rms)
    print(f"\nwrote {RESULTS}; total {time.perf_counter() - start:.0f} s")
    if args.record and not args.smoke:
        _record(summary, vars(args))


def _record(summary: dict, args: dict) -> None:
    """Write the notebook's precomputed file and record it in the MANIFEST."""
    from rlcourse import data

    PRECOMPUTED.write_text(json.dumps(summary, indent=1) + "\n")
    cmd = "python bench/bench_hw4_rlhf_dpo.py --record " + " ".join(
        [f"--seeds {' '.join(map(str, args['seeds']))}", f"--kl {args['kl']:g} --beta {args['beta']:g}",
         f"--kl-sweep {' '.join(f'{v:g}' for v in args['kl_sweep'])}",
         f"--beta-sweep {' '.join(f'{v:g}' for v in args['beta_sweep'])}",
         f"--offset-sweep {' '.join(f'{v:g}' for v in args.get('offset_sweep', []))}", f"--workers {args['workers']}"]
        + (["--no-sweep"] if args["no_sweep"] else []) + ([f"--steps {args['steps']}"] if args["steps"] else []))
    data.add(PRECOMPUTED, cmd, args["seeds"][0], {"note": "PRECOMPUTED sweep and seed results plotted by hw4_rlhf_dpo",
                                                  "budget": summary["budget"]})
    print(f"recorded {PRECOMPUTED.relative_to(REPO)}")


if __name__ == "__main__":
    main()
