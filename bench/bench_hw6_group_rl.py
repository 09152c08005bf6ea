"""Benchmark of hw6_group_rl: critic-free RL (GRPO, Dr. GRPO, RLOO) against PPO at the same number of sampled
sequences, on the gold reward (a program) and on the learned proxy; IPO, KTO and DPO; best-of-n; and Gao et al.
(2022)'s over-optimisation laws fitted on part of the curves and checked as predictions on the rest.

    python bench/bench_hw6_group_rl.py                    # 3 seeds one after the other, then the tables
    python bench/bench_hw6_group_rl.py --seed 1           # one seed, written to bench/results/hw6_group_rl.seed1.json
    python bench/bench_hw6_group_rl.py --merge            # merge the per-seed files into bench/results/hw6_group_rl.json
    python bench/bench_hw6_group_rl.py --all-variants     # also Dr. GRPO, RLOO and PPO on the proxy

Every number comes from the reference solutions: hw6's notebook (its setup and stub cells, executed here) for
the critic-free runs, IPO, KTO and DPO, and hw5's for PPO with its value head, passed to the given loops of
``rlcourse.lm_training`` (``critic_free_train``, ``pairwise_train``, ``kto_train``, ``ppo_train``), all on
the shipped SFT model and preference set, with hw6's full budgets. The reward model (refitted per seed) and DPO
come from ``datasets/scripts/make_hw6_models.py``, whose seed-0 results the notebook loads ready-made
(``datasets/hw6/``), so seed 0 here is the notebook's run. ``bench/results/hw6_group_rl.json`` holds,
per method and seed, ``gold``, ``proxy``, ``kl`` and ``wall_s`` (and each run's per-iteration curve).
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
HW6 = REPO / "solutions" / "hw6_group_rl" / "hw6_group_rl.ipynb"
HW5 = REPO / "solutions" / "hw5_lm_alignment" / "hw5_lm_alignment.ipynb"
RESULTS = REPO / "bench" / "results"
sys.path.insert(0, str(REPO / "datasets" / "scripts"))
from make_hw6_models import fit_reward_model, train_dpo  # noqa: E402  (instructor tooling: the fits hw5's students write)
# hw6's full budgets (its parameters cell with FAST = False).
BUDGET = dict(N_PAIRS=3000, RM_STEPS=120, N_EVAL=64, RL_ITERS=30, RL_PROMPTS=8, RL_GROUP=8, OFFLINE_STEPS=90,
              OFFLINE_BETA=0.1, POOL_PROMPTS=8, POOL_SIZE=256, FIT_MAX_N=16, PPO_BATCH=64, KL_BETA=0.0)


def solution_namespace(path: Path) -> dict:
    """A solution notebook's setup and stub cells, executed in a fresh namespace."""
    import nbformat

    ns: dict = {"__name__": "__bench__"}
    for cell in nbformat.read(path, as_version=4).cells:
        meta = cell.metadata
        if cell.cell_type == "code" and ("setup" in meta.get("tags", []) or meta.get("nbgrader", {}).get("solution")):
            with contextlib.redirect_stdout(io.StringIO()):
                exec(compile(cell.source, f"<{meta.get('nbgrader', {}).get('grade_id')}>", "exec"), ns)
    return ns


def run_seed(seed: int, all_variants: bool = False) -> dict:
    """Every method's gold reward, proxy reward, KL, wall time and curve for one seed; best-of-n from one pool.

    Each method's row is written to the seed's file as soon as it is measured, and a rerun skips the rows
    already there (the reward model, deterministic given the seed, is fitted again).
    """
    import torch

    from rlcourse import group_rl as G
    from rlcourse import group_training as GT
    from rlcourse import lm_training as L
    from rlcourse import reviews as R
    from rlcourse.lm import generate, load_sft

    torch.set_num_threads(1)
    hw6, hw5 = solution_namespace(HW6), solution_namespace(HW5)
    hw6["seed_everything"](seed)
    sft, prefs = load_sft(), R.load_preferences()
    p = prefs["prompt_len"]
    tr = torch.as_tensor(np.flatnonzero(~prefs["test"])[: BUDGET["N_PAIRS"]])
    chosen, rejected = torch.as_tensor(prefs["chosen"]), torch.as_tensor(prefs["rejected"])
    prompts = chosen[tr, :p]
    eval_prompts = torch.as_tensor(prefs["eval_prompts"])[: BUDGET["N_EVAL"]]
    t0 = time.perf_counter()
    rm = fit_reward_model(sft, chosen[tr], rejected[tr], BUDGET["RM_STEPS"], seed=seed)
    rm_s = time.perf_counter() - t0
    gold_fn, proxy_fn = L.gold_fn, (lambda s: G.proxy_score(rm, s))
    variants = {"GRPO": (hw6["group_advantages"], True), "RLOO": (hw6["rloo_advantages"], True),
                "Dr. GRPO": (lambda r: hw6["group_advantages"](r, scale=False), False)}
    done = json.loads(seed_file(seed).read_text()) if seed_file(seed).exists() else {}
    out: dict = {"reward_model_s": done.get("reward_model_s", rm_s), "methods": done.get("methods", {})}
    if "best_of_n" in done:
        out["best_of_n"] = done["best_of_n"]

    def save():
        seed_file(seed).write_text(json.dumps(out) + "\n")

    def record(name, policy, seconds, log=None):
        e = L.evaluate(policy, sft, proxy_fn, eval_prompts, seed, log_prob_sums=G.completion_log_prob_sums)
        row = {"gold": e["gold"], "proxy": e["proxy"], "kl": e["kl"], "wall_s": seconds}
        if log is not None:
            row["curve"] = {k: [float(v) for v in log[k]] for k in ("gold", "proxy", "kl")}
        out["methods"][name] = row
        print(f"  seed {seed} {name:<20} {seconds:6.0f} s  KL {e['kl']:6.2f}  proxy {e['proxy']:+.2f}  gold {e['gold']:+.3f}",
              file=sys.stderr, flush=True)
        save()

    if "SFT" not in out["methods"]:
        record("SFT", sft, 0.0)
    it, n_p, grp = BUDGET["RL_ITERS"], BUDGET["RL_PROMPTS"], BUDGET["RL_GROUP"]
    for target, fn in (("gold", gold_fn), ("proxy", proxy_fn)):
        for variant in ("GRPO", "Dr. GRPO", "RLOO") if target == "gold" and all_variants else ("GRPO",):
            if f"{variant} ({target})" in out["methods"]:
                continue
            t0 = time.perf_counter()
            advantage_fn, length_norm = variants[variant]
            policy, log = GT.critic_free_train(sft, fn, prompts, advantage_fn, hw6["grpo_token_loss"], iters=it,
                                              n_prompts=n_p, group=grp, seed=seed, length_norm=length_norm,
                                              beta=BUDGET["KL_BETA"], proxy_fn=proxy_fn)
            record(f"{variant} ({target})", policy, time.perf_counter() - t0, log)
        # PPO with a value head (hw5's given loop), same number of sampled sequences, same KL coefficient (0).
        if f"PPO ({target})" in out["methods"] or (target == "proxy" and not all_variants):
            continue
        t0 = time.perf_counter()
        policy, log = L.ppo_train(sft, fn, prompts, hw5["token_log_probs"], hw5["kl_penalised_rewards"],
                                  hw5["ppo_token_loss"], beta=BUDGET["KL_BETA"], iters=it, batch=BUDGET["PPO_BATCH"],
                                  seed=seed)
        seconds = time.perf_counter() - t0
        # hw5's loop logs the reward it optimised: the proxy on the proxy, nothing of the proxy on the gold reward
        log = {"gold": log["gold"], "proxy": log["reward"] if target == "proxy" else np.full(len(log["gold"]), np.nan),
               "kl": log["kl"]}
        record(f"PPO ({target})", policy, seconds, log)

    b = BUDGET["OFFLINE_BETA"]
    half = len(tr) // 2
    kto_tokens = torch.cat([chosen[tr[:half]], rejected[tr[half:]]])
    kto_des = torch.cat([torch.ones(half, dtype=torch.bool), torch.zeros(len(tr) - half, dtype=torch.bool)])
    offline = {
        "DPO": lambda: train_dpo(sft, chosen[tr], rejected[tr], p, b, BUDGET["OFFLINE_STEPS"], seed=seed),
        "IPO": lambda: GT.pairwise_train(sft, chosen[tr], rejected[tr], p, lambda pc, pr, rc, rr:
                                        hw6["ipo_loss"](pc, pr, rc, rr, b), BUDGET["OFFLINE_STEPS"], seed=seed),
        "KTO": lambda: GT.kto_train(sft, kto_tokens, kto_des, p, hw6["kto_loss"], beta=b, steps=BUDGET["OFFLINE_STEPS"],
                                   seed=seed),
    }
    for name, train in offline.items():
        if f"{name} beta={b}" in out["methods"]:
            continue
        t0 = time.perf_counter()
        policy = train()
        record(f"{name} beta={b}", policy, time.perf_counter() - t0)

    if "best_of_n" in out:
        return out
    t0 = time.perf_counter()
    k, m = BUDGET["POOL_PROMPTS"], BUDGET["POOL_SIZE"]
    pool_prompts = torch.as_tensor(prefs["eval_prompts"])[-k:].repeat_interleave(m, dim=0)   # not the RL eval prompts
    gen = torch.Generator().manual_seed(10_000 + seed)
    pool = torch.cat([generate(sft, x, R.MAX_LEN - p, generator=gen) for x in pool_prompts.split(1024)])
    proxy = G.proxy_score(rm, pool).numpy().reshape(k, m)
    gold = R.gold_reward(pool.numpy()).reshape(k, m)
    ns = [int(n) for n in 2 ** np.arange(int(np.log2(m)) + 1)]
    out["best_of_n"] = {
        "n": ns, "pool_s": time.perf_counter() - t0,
        "gold": [float(G.best_of_n_from_pool(proxy, gold, n).mean()) for n in ns],
        "proxy": [float(G.best_of_n_from_pool(proxy, proxy, n).mean()) for n in ns],
        "gold_by_gold": [float(G.best_of_n_from_pool(gold, gold, n).mean()) for n in ns],
        "kl_formula": [float(G.bon_kl_formula(n)) for n in ns],
        "kl_exact_proxy": [float(np.mean([G.best_of_n_kl(s, n) for s in proxy])) for n in ns],
        "kl_exact_gold": [float(np.mean([G.best_of_n_kl(s, n) for s in gold])) for n in ns],
    }
    save()
    return out


def seed_file(seed: int) -> Path:
    return RESULTS / f"hw6_group_rl.seed{seed}.json"


def laws(seeds: dict[str, dict]) -> dict:
    """The laws fitted per seed: best-of-n on n <= FIT_MAX_N, RL on the first half of each run on the proxy."""
    from rlcourse import group_rl as G

    out: dict = {"best_of_n": {}, "rl": {}}
    for s, run in seeds.items():
        bon = run.get("best_of_n")
        if bon is None:       # a seed stopped before its pool: no best-of-n law for it
            continue
        n, kl, gold = np.array(bon["n"]), np.array(bon["kl_formula"]), np.array(bon["gold"])
        gain, d = gold - gold[0], np.sqrt(kl)
        fit = n <= BUDGET["FIT_MAX_N"]
        a, b = G.fit_bon_law(d[fit], gain[fit])
        d_star = G.bon_law_peak(a, b)
        out["best_of_n"][s] = {"alpha": a, "beta": b, "d_star": d_star, "kl_star": d_star ** 2,
                               "n_star": G.n_for_kl(d_star ** 2),
                               "predicted": {int(k): float(G.bon_law(dk, a, b)) for k, dk in zip(n[~fit], d[~fit])},
                               "measured": {int(k): float(g) for k, g in zip(n[~fit], gain[~fit])}}
    for s, run in seeds.items():
        sft_gold = run["methods"]["SFT"]["gold"]
        for method in [m for m in ("GRPO (proxy)", "PPO (proxy)", "GRPO (gold)", "PPO (gold)") if m in run["methods"]]:
            c = run["methods"][method]["curve"]
            d, gain = np.sqrt(np.maximum(c["kl"], 0.0)), np.array(c["gold"]) - sft_gold
            first = np.arange(len(d)) < len(d) // 2
            a, b = G.fit_rl_law(d[first], gain[first])
            pred = G.rl_law(d[~first], a, b)
            out["rl"].setdefault(method, {})[s] = {
                "alpha": a, "beta": b, "d_star": G.rl_law_peak(a, b),
                "rmse_second_half": float(np.sqrt(np.mean((pred - gain[~first]) ** 2))),
                "sd_second_half": float(np.std(gain[~first])),
                "predicted_last": float(pred[-1]), "measured_last": float(gain[-1]),
                "measured_peak_d": float(d[np.argmax(gain)]), "max_d": float(d.max())}
    return out


def ms(values, fmt="{:+.3f}") -> str:
    v = np.asarray(values, dtype=float)
    return (fmt + " ± " + fmt.replace("+", "")).format(v.mean(), v.std())


def print_tables(result: dict) -> None:
    seeds = result["seeds"]
    keys = sorted(seeds)
    methods = list(dict.fromkeys(m for s in keys for m in seeds[s]["methods"]))
    print(f"\n### Gold reward, proxy reward and KL from the SFT model ({len(keys)} seeds; mean ± sd over seeds; "
          f"{BUDGET['N_EVAL']} evaluation prompts; RL: {BUDGET['RL_ITERS']} iterations of "
          f"{BUDGET['RL_PROMPTS'] * BUDGET['RL_GROUP']} sampled sequences, no KL penalty)\n")
    print("| method | gold reward | proxy reward | KL (nats) | wall time (s) |")
    print("|---|---:|---:|---:|---:|")
    for m in methods:
        col = lambda k: [seeds[s]["methods"][m][k] for s in keys if m in seeds[s]["methods"]]  # noqa: E731
        print(f"| {m} | {ms(col('gold'))} | {ms(col('proxy'))} | {ms(col('kl'), '{:.2f}')} | {ms(col('wall_s'), '{:.0f}')} |")
    rm_s = np.mean([seeds[s]["reward_model_s"] for s in keys])
    print(f"\nThe reward model took {rm_s:.0f} s to fit (not included above); PPO's wall time includes its value head.")

    keys = [s for s in keys if "best_of_n" in seeds[s]]
    if not keys:
        return
    print("\n### Best-of-n from one pool (KL: formula and exact for the pool; gold gained over SFT)\n")
    bon0 = seeds[keys[0]]["best_of_n"]
    print("| n | KL formula | KL exact (proxy picks) | KL exact (gold picks) | gold (proxy picks) | gold (gold picks) |")
    print("|---:|---:|---:|---:|---:|---:|")
    for i, n in enumerate(bon0["n"]):
        col = lambda k: [seeds[s]["best_of_n"][k][i] for s in keys]  # noqa: E731
        print(f"| {n} | {bon0['kl_formula'][i]:.3f} | {ms(col('kl_exact_proxy'), '{:.3f}')} | "
              f"{ms(col('kl_exact_gold'), '{:.3f}')} | {ms(col('gold'))} | {ms(col('gold_by_gold'))} |")

    lw = result["laws"]
    bl = lw["best_of_n"]
    print(f"\n### The laws as predictions\n\nBest-of-n, fitted on n <= {BUDGET['FIT_MAX_N']} (d = sqrt(KL formula)): "
          f"alpha {ms([bl[s]['alpha'] for s in keys], '{:.3f}')}, beta {ms([bl[s]['beta'] for s in keys], '{:.3f}')}; "
          f"peak d* = alpha/(2 beta) = {ms([bl[s]['d_star'] for s in keys], '{:.2f}')}, "
          f"KL* = {ms([bl[s]['kl_star'] for s in keys], '{:.1f}')} nats, "
          f"n* = {', '.join(format(bl[s]['n_star'], '.3g') for s in keys)} (per seed).\n")
    print("| n | predicted gold gain | measured gold gain | within the seeds' spread (2 sd) |")
    print("|---:|---:|---:|---|")
    for n in bl[keys[0]]["predicted"]:
        pred = [bl[s]["predicted"][n] for s in keys]
        meas = [bl[s]["measured"][n] for s in keys]
        spread = 2 * max(np.std(meas), np.std(pred), 1e-9)
        ok = abs(np.mean(pred) - np.mean(meas)) <= spread
        print(f"| {n} | {ms(pred)} | {ms(meas)} | {'yes' if ok else 'no'} |")
    print("\nRL, fitted on the first half of each run's per-iteration batch (gold gained over SFT against "
          "d = sqrt(KL of the batch)), predicting the second half:\n")
    print("| run | alpha | beta | predicted peak d* | measured peak at d | largest d | RMSE, second half | sd of the second half | last: predicted / measured |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for method, per in lw["rl"].items():
        col = lambda k: [per[s][k] for s in sorted(per)]  # noqa: E731
        print(f"| {method} | {ms(col('alpha'), '{:.3f}')} | {ms(col('beta'), '{:.3f}')} | "
              f"{', '.join(format(v, '.3g') for v in col('d_star'))} | {ms(col('measured_peak_d'), '{:.2f}')} | "
              f"{ms(col('max_d'), '{:.2f}')} | {ms(col('rmse_second_half'), '{:.3f}')} | {ms(col('sd_second_half'), '{:.3f}')} | "
              f"{np.mean(col('predicted_last')):+.3f} / {np.mean(col('measured_last')):+.3f} |")


def merge() -> dict:
    seeds = {}
    for path in sorted(RESULTS.glob("hw6_group_rl.seed*.json")):
        seeds[path.stem.split("seed")[-1]] = json.loads(path.read_text())
    if not seeds:
        raise SystemExit("no per-seed results: run with --seed N first")
    result = {"budget": BUDGET, "command": "python bench/bench_hw6_group_rl.py", "seeds": seeds}
    result["laws"] = laws(seeds)
    names = dict.fromkeys(m for run in seeds.values() for m in run["methods"])
    result["methods"] = {m: {s: {k: run["methods"][m][k] for k in ("gold", "proxy", "kl", "wall_s")}
                             for s, run in seeds.items() if m in run["methods"]} for m in names}
    (RESULTS / "hw6_group_rl.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--seed", type=int, help="run this one seed and write its file")
    parser.add_argument("--merge", action="store_true", help="merge the per-seed files and print the tables")
    parser.add_argument("--all-variants", action="store_true",
                        help="also Dr. GRPO and RLOO on the program and PPO on the proxy (twice the time)")
    parser.add_argument("--smoke", action="store_true", help="tiny budgets, results to a scratch folder (checks the script)")
    args = parser.parse_args()
    if args.smoke:
        global RESULTS
        RESULTS = Path("/tmp/hw6_bench_smoke")
        BUDGET.update(N_PAIRS=128, RM_STEPS=2, N_EVAL=8, RL_ITERS=4, RL_PROMPTS=2, RL_GROUP=4, OFFLINE_STEPS=2,
                      POOL_PROMPTS=2, POOL_SIZE=32, FIT_MAX_N=8, PPO_BATCH=8)
    RESULTS.mkdir(parents=True, exist_ok=True)
    todo = [] if args.merge else ([args.seed] if args.seed is not None else list(range(args.seeds)))
    for seed in todo:
        t0 = time.perf_counter()
        run = run_seed(seed, args.all_variants)
        run["seconds"] = time.perf_counter() - t0
        seed_file(seed).write_text(json.dumps(run) + "\n")
        print(f"seed {seed}: {run['seconds']:.0f} s", file=sys.stderr, flush=True)
    if args.seed is None:
        print_tables(merge())


if __name__ == "__main__":
    main()
