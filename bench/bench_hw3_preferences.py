"""Benchmark of hw3_preferences: utility recovery, reward-model accuracy, query selection, dueling-bandit
regret and notebook run times. Prints the Markdown tables that the README shows.

    python bench/bench_hw3_preferences.py                  # everything (about 15 minutes on 2 cores)
    python bench/bench_hw3_preferences.py --skip-notebook  # without timing the notebook runs
    python bench/bench_hw3_preferences.py --hopper-only    # only the reward models on the Hopper pairs

The Hopper pairs are the set with falls (``hopper_prefs/hopper_prefs_falls.npz``: a quarter of the pairs
contain a segment that ends in a fall); held-out accuracy is also split into pairs with a fall and
upright pairs, each against its own Bayes ceiling.

Every number comes from the reference solutions in ``solutions/hw3_preferences`` run on the shipped
data (``datasets/items``, ``datasets/hopper_prefs``), with the same budgets as the notebook.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
from scipy.stats import pearsonr, spearmanr

from autograder.core.grader import build_reference
from rlcourse.preferences import (DuelingBandit, dueling_regret, load_hopper_preferences, load_items,
                                  preference_accuracy, random_pairs, uniform_pairs)

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK = REPO / "solutions" / "hw3_preferences" / "hw3_preferences.ipynb"


def solution_namespace() -> dict:
    """The solution notebook's parameters, setup and stub cells, run in a fresh namespace."""
    return build_reference("hw3_preferences", {"FAST": False})


def mean_sd(x) -> str:
    x = np.asarray(x, dtype=float)
    return f"{x.mean():.3f} ± {x.std():.3f}"


def bench_recovery(ns: dict, repeats: int = 5) -> None:
    d = load_items()
    n, truth = d["n_items"], d["utilities"]
    print(f"\n### Utility recovery ({n} items, Rao–Kupper ties, eta = {d['info']['log_theta']}; "
          f"times: median of {repeats} runs)\n")
    print("| comparisons | Spearman (GD) | Spearman (MM) | RMSE (GD) | RMSE (MM) | max |GD − MM| | time GD | time MM |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for m in (250, 500, 1000, 2000, 4000, len(d["mu"])):
        args = (n, d["i"][:m], d["j"][:m], d["mu"][:m])
        out, times = {}, {}
        for name, fit in (("gd", ns["fit_bradley_terry"]), ("mm", ns["fit_bradley_terry_mm"])):
            ts = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                out[name] = fit(*args)
                ts.append(time.perf_counter() - t0)
            times[name] = np.median(ts)
        rho = {k: spearmanr(v, truth).statistic for k, v in out.items()}
        rmse = {k: np.sqrt(np.mean((v - truth) ** 2)) for k, v in out.items()}
        print(f"| {m} | {rho['gd']:.3f} | {rho['mm']:.3f} | {rmse['gd']:.3f} | {rmse['mm']:.3f} | "
              f"{np.abs(out['gd'] - out['mm']).max():.1e} | {1e3 * times['gd']:.1f} ms | {1e3 * times['mm']:.1f} ms |")


def bench_reward_models(ns: dict, seeds: int, n_steps: int, counts: list[int], active_counts: list[int],
                        queries: bool = True) -> None:
    p = load_hopper_preferences()
    obs, act = torch.as_tensor(p.obs), torch.as_tensor(p.act)
    ceiling, test_seg, true_ret = p.info["bayes_ceiling_test"], np.flatnonzero(p.test_segment), p.returns
    train, select = ns["train_reward_model"], ns["select_queries"]

    fall_pair = p.terminated[p.test_pairs].any(1)

    def evaluate(ens, split: bool = False) -> tuple[float, ...]:
        with torch.no_grad():
            ret = ens(obs, act).sum(-1).mean(0).numpy()
        acc = lambda m: preference_accuracy(ret[p.test_pairs[m, 0]], ret[p.test_pairs[m, 1]], p.test_mu[m])
        out = (acc(np.ones_like(fall_pair)), pearsonr(ret[test_seg], true_ret[test_seg]).statistic)
        return out + (acc(fall_pair), acc(~fall_pair)) if split else out

    info = p.info
    print(f"\n### Reward model on Hopper preferences ({info['n_train_pairs']} training / {info['n_test_pairs']} held-out "
          f"pairs, segments of {info['segment_length']} steps; annotator temperature {info['temperature']}, "
          f"flip rate {info['flip_rate']}, eta {info['log_theta']}; Bayes ceiling {ceiling:.3f}; "
          f"3-member ensembles, {n_steps} steps per member; mean ± sd over {seeds} seeds; pairs with a fall: "
          f"{fall_pair.mean():.0%} of the held-out pairs, ceiling {info['bayes_ceiling_test_fall_pairs']:.3f}; upright "
          f"pairs: ceiling {info['bayes_ceiling_test_upright_pairs']:.3f})\n")
    print("| labels | held-out accuracy | fraction of Bayes ceiling | correlation with true return | "
          "accuracy, pairs with a fall | accuracy, upright pairs | train time |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in counts:
        accs, cors, secs, falls, uprights = [], [], [], [], []
        for s in range(seeds):
            order = np.random.default_rng(100 + s).permutation(len(p.train_mu))[:n]
            t0 = time.perf_counter()
            ens = train(obs, act, p.train_pairs[order], p.train_mu[order], n_steps=n_steps, seed=s)
            secs.append(time.perf_counter() - t0)
            acc, cor, fall, upright = evaluate(ens, split=True)
            accs.append(acc)
            cors.append(cor)
            falls.append(fall)
            uprights.append(upright)
        print(f"| {n} | {mean_sd(accs)} | {mean_sd(np.array(accs) / ceiling)} | {mean_sd(cors)} | {mean_sd(falls)} | "
              f"{mean_sd(uprights)} | {np.mean(secs):.1f} s |")

    if not queries:
        return
    pool = random_pairs(np.flatnonzero(~p.test_segment), 4000, np.random.default_rng(7))
    res = {k: np.zeros((seeds, len(active_counts), 2)) for k in ("random", "disagreement")}
    for s in range(seeds):
        pool_mu = p.annotate(pool, np.random.default_rng(1000 + s))
        order = np.random.default_rng(2000 + s).permutation(len(pool))
        for c, n in enumerate(active_counts):
            res["random"][s, c] = evaluate(train(obs, act, pool[order[:n]], pool_mu[order[:n]], n_steps=n_steps, seed=s))
        asked = order[:active_counts[0]]
        for c, n in enumerate(active_counts):
            if c > 0:
                rest = np.setdiff1d(np.arange(len(pool)), asked)
                asked = np.concatenate([asked, rest[select(ens, obs, act, pool[rest], n - len(asked))]])
            ens = train(obs, act, pool[asked], pool_mu[asked], n_steps=n_steps, seed=s)
            res["disagreement"][s, c] = evaluate(ens)
    print(f"\n### Query selection (pool of {len(pool)} candidate pairs, fresh labels from the simulated annotator; "
          f"both start from the same 50 random labels; mean ± sd over {seeds} seeds)\n")
    print("| labels | accuracy, random | accuracy, disagreement | fraction of ceiling, random | fraction of ceiling, "
          "disagreement | correlation, random | correlation, disagreement |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for c, n in enumerate(active_counts):
        r, a = res["random"][:, c], res["disagreement"][:, c]
        print(f"| {n} | {mean_sd(r[:, 0])} | {mean_sd(a[:, 0])} | {mean_sd(r[:, 0] / ceiling)} | "
              f"{mean_sd(a[:, 0] / ceiling)} | {mean_sd(r[:, 1])} | {mean_sd(a[:, 1])} |")


def bench_bandit(ns: dict, horizon: int, seeds: int) -> None:
    utilities = np.array([0.8, 0.5, 0.4, 0.2, 0.0, -0.2, -0.5, -1.0])
    P = ns["bt_probability"](utilities[:, None], utilities[None, :])
    rows = {}
    for name in ("RUCB", "uniform pairs"):
        totals, secs = [], []
        for s in range(seeds):
            t0 = time.perf_counter()
            if name == "RUCB":
                pairs = ns["rucb"](DuelingBandit(P, s), horizon, rng=np.random.default_rng(s))
            else:
                pairs = uniform_pairs(DuelingBandit(P, s), horizon, np.random.default_rng(s))
            secs.append(time.perf_counter() - t0)
            reg = np.cumsum(dueling_regret(P, pairs, winner=int(np.argmax(utilities))))
            totals.append(reg[[horizon // 10 - 1, horizon // 2 - 1, horizon - 1]])
        rows[name] = (np.array(totals), np.mean(secs))
    print(f"\n### Dueling bandit (8 Bradley–Terry arms, alpha = 0.51; cumulative regret, mean ± sd over {seeds} seeds)\n")
    print(f"| algorithm | after {horizon // 10} duels | after {horizon // 2} | after {horizon} | time per run |")
    print("|---|---:|---:|---:|---:|")
    for name, (tot, sec) in rows.items():
        print(f"| {name} | " + " | ".join(f"{tot[:, k].mean():.1f} ± {tot[:, k].std():.1f}" for k in range(3))
              + f" | {sec:.2f} s |")


def bench_notebook() -> None:
    print("\n### Notebook run time (solution notebook, `python -m autograder run`)\n")
    print("| mode | wall time | status |")
    print("|---|---:|---|")
    for mode in ("True", "False"):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "autograder", "run", str(NOTEBOOK), "-p", f"FAST={mode}"],
                              cwd=REPO, capture_output=True, text=True)
        status = "ok" if proc.returncode == 0 else f"failed: {(proc.stdout + proc.stderr).strip()[-200:]}"
        print(f"| FAST = {mode} | {time.perf_counter() - t0:.0f} s | {status} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3, help="seeds of the reward-model experiments")
    parser.add_argument("--rm-steps", type=int, default=500, help="gradient steps per ensemble member (notebook: 500)")
    parser.add_argument("--bandit-horizon", type=int, default=4000)
    parser.add_argument("--bandit-seeds", type=int, default=5)
    parser.add_argument("--skip-notebook", action="store_true")
    parser.add_argument("--hopper-only", action="store_true", help="only the reward models on the Hopper pairs")
    parser.add_argument("--no-queries", action="store_true", help="without the query-selection experiment")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    ns = solution_namespace()
    print(f"## hw3_preferences benchmark (torch threads: 1; {time.strftime('%Y-%m-%d')})")
    if not args.hopper_only:
        bench_recovery(ns)
        bench_bandit(ns, args.bandit_horizon, args.bandit_seeds)
    n_train = len(load_hopper_preferences().train_mu)
    bench_reward_models(ns, args.seeds, args.rm_steps, [50, 200, 800, n_train], [50, 100, 200, 400, 800],
                        queries=not args.no_queries)
    if not (args.skip_notebook or args.hopper_only):
        bench_notebook()


if __name__ == "__main__":
    main()
