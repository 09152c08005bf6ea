"""Where DPO's pairs come from: hw3's pairs (other policies' behaviour) against pairs of the reference
policy's own continuations from a shared start state (the analogue of two answers to one prompt).

    python bench/bench_hw4_dpo_pairs.py                      # 3 seeds each, about 5 minutes on 2 idle cores
    python bench/bench_hw4_dpo_pairs.py --seeds 0 --pairs 500 --dpo-steps 100   # a quick smoke run

hw4's notebook claims that DPO works best when the preferred behaviour is close to the reference
policy, i.e. when the pairs are sampled from (something like) pi_ref. This script measures it. The
on-policy pairs are made here, not shipped: the reference plays stochastically; at random moments
the simulator's state is saved and the reference plays two independent stochastic 25-step
continuations from it; pairs in which a continuation falls are dropped; the same simulated annotator
as hw3's data labels each pair (temperature 2, Rao–Kupper ties with log theta 0.4, 10% flips). Both
data sets then train DPO with the solution notebook's ``dpo_loss`` and ``train_dpo`` at its ``BETA``
and ``DPO_STEPS``, from the same reference, and the policies are evaluated like bench_hw4_rlhf_dpo.py
(true return over 20 deterministic episodes, per-step KL on the visited states). Results go to
``bench/results/hw4_dpo_pairs.json``.
"""
from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import gymnasium as gym
import numpy as np

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results" / "hw4_dpo_pairs.json"
ANNOTATOR = dict(temperature=2.0, flip_rate=0.1, log_theta=0.4)  # hw3's data set (see its MANIFEST entry)
SEGMENT = 25
FINAL_EPISODES = 20


def shared_start_pairs(reference, n_pairs: int, seed: int) -> dict[str, np.ndarray]:
    """``n_pairs`` labelled pairs of the reference's own stochastic continuations from shared start states.

    Returns ``obs`` ``(2 n, L, 11)``, ``act`` ``(2 n, L, 3)``, ``returns`` ``(2 n,)``, ``pairs`` ``(n, 2)``
    (rows ``2i`` and ``2i + 1``) and ``mu`` ``(n,)``.
    """
    import torch

    from rlcourse.preferences import simulate_annotator

    rng, gen = np.random.default_rng(seed), torch.Generator().manual_seed(seed)
    env = gym.make("Hopper-v5").unwrapped  # the time limit is kept by hand: branches must not count towards it
    act = lambda o: reference.act(o[None], deterministic=False, generator=gen)[0]
    obs_out, act_out, ret_out = [], [], []
    obs, _ = env.reset(seed=seed)
    t = 0
    while len(ret_out) < 2 * n_pairs:
        for _ in range(rng.integers(5, 40)):  # walk on to the next branching point
            obs, _, terminated, _, _ = env.step(act(obs))
            t += 1
            if terminated or t >= 1000:
                obs, _ = env.reset(seed=int(rng.integers(2**31)))
                t = 0
        qpos, qvel, start = env.data.qpos.copy(), env.data.qvel.copy(), obs
        branches = []
        for _ in range(2):
            env.set_state(qpos, qvel)
            o, seg_o, seg_a, total, fell = start, [], [], 0.0, False
            for _ in range(SEGMENT):
                a = act(o)
                seg_o.append(o)
                seg_a.append(a)
                o, r, terminated, _, _ = env.step(a)
                total += r
                if terminated:
                    fell = True
                    break
            branches.append((seg_o, seg_a, total, fell))
        env.set_state(qpos, qvel)  # the main rollout goes on from the branching point
        if not any(b[3] for b in branches):
            for seg_o, seg_a, total, _ in branches:
                obs_out.append(np.array(seg_o, np.float32))
                act_out.append(np.array(seg_a, np.float32))
                ret_out.append(total)
    env.close()
    returns = np.array(ret_out)
    pairs = np.arange(2 * n_pairs).reshape(n_pairs, 2)
    mu = simulate_annotator(returns[pairs[:, 0]], returns[pairs[:, 1]], rng=rng, **ANNOTATOR)
    return {"obs": np.stack(obs_out), "act": np.stack(act_out), "returns": returns, "pairs": pairs, "mu": mu}


def run(source: str, seed: int, n_pairs: int, dpo_steps: int | None) -> dict:
    """Train DPO on ``source`` in {"hw3", "own"} with minibatch seed ``seed``; evaluate it."""
    import torch

    from autograder.core.grader import build_reference
    from rlcourse.preferences import expected_bayes_accuracy

    torch.set_num_threads(1)
    ns = build_reference("hw4_rlhf_dpo", {"FAST": False})
    reference, steps = ns["load_reference"](), dpo_steps or ns["DPO_STEPS"]
    t0 = time.perf_counter()
    if source == "hw3":
        prefs = ns["load_hopper_preferences"]()
        train = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.train_pairs, prefs.train_mu)
        val = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.test_pairs, prefs.test_mu)
        seg_obs, seg_act = prefs.obs, prefs.act
        gaps = np.abs(np.subtract(*prefs.returns[prefs.train_pairs].T))
        ceiling = expected_bayes_accuracy(*prefs.returns[prefs.test_pairs].T, **ANNOTATOR)
    else:
        d, v = shared_start_pairs(reference, n_pairs, seed=0), shared_start_pairs(reference, n_pairs // 4, seed=1)
        train = ns["oriented_pairs"](d["obs"], d["act"], d["pairs"], d["mu"])
        val = ns["oriented_pairs"](v["obs"], v["act"], v["pairs"], v["mu"])
        seg_obs, seg_act = d["obs"], d["act"]
        gaps = np.abs(np.subtract(*d["returns"][d["pairs"]].T))
        ceiling = expected_bayes_accuracy(*v["returns"][v["pairs"]].T, **ANNOTATOR)
    data_seconds = time.perf_counter() - t0
    with torch.no_grad():
        loglik = ns["sequence_log_prob"](reference, torch.as_tensor(seg_obs, dtype=torch.float32),
                                         torch.as_tensor(seg_act, dtype=torch.float32)).numpy()
    policy, log = ns["train_dpo"](reference, reference, ns["dpo_loss"], train, ns["BETA"], n_steps=steps, val=val,
                                  log_every=max(1, steps // 10), eval_every=steps, seed=seed, verbose=False)
    final = ns["evaluate_policy"](policy, reference, n_episodes=FINAL_EPISODES)
    return {"source": source, "seed": seed, "train_pairs": len(train), "data_seconds": data_seconds,
            "segment_loglik_median": float(np.median(loglik)), "val_accuracy": log.steps[-1]["val_accuracy"],
            "annotator_accuracy": ceiling, "return_gap_median": float(np.median(gaps)),
            "return": final["return"], "kl": final["kl"], "length": final["length"]}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--pairs", type=int, default=6000, help="on-policy training pairs (hw3's set has 6,000)")
    p.add_argument("--dpo-steps", type=int, default=None, help="default: the notebook's DPO_STEPS")
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args(argv)
    start = time.perf_counter()
    jobs = [(src, s, args.pairs, args.dpo_steps) for src in ("hw3", "own") for s in args.seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run, *zip(*jobs)))
    ref_return = json.loads((REPO / "datasets" / "MANIFEST.json").read_text())
    ref_return = next(v for k, v in (ref_return.get("files", ref_return)).items()
                      if k == "hw4/reference_policy.pt")["info"]["return_mean"]
    print(f"\n### DPO on whose pairs? (beta and steps as in the notebook; reference returns {ref_return:.0f})\n")
    print("| pairs | seeds | training pairs (no ties) | median return gap in a pair | median segment log-lik under "
          "pi_ref | held-out accuracy (annotator's own rule) | true return | KL (nats/step) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    summary = {}
    for src, name in (("hw3", "hw3's (16 other policies)"), ("own", "the reference's own, shared start")):
        rs = [r for r in results if r["source"] == src]
        ret = [r["return"] for r in rs]
        summary[src] = {"returns": ret, "return_mean": float(np.mean(ret)), "return_std": float(np.std(ret)),
                        "kl_mean": float(np.mean([r["kl"] for r in rs]))}
        print(f"| {name} | {len(rs)} | {rs[0]['train_pairs']} | {rs[0]['return_gap_median']:.1f} | "
              f"{rs[0]['segment_loglik_median']:.1f} | {np.mean([r['val_accuracy'] for r in rs]):.3f} "
              f"({rs[0]['annotator_accuracy']:.3f}) | {np.mean(ret):.0f} ± {np.std(ret):.0f} "
              f"({', '.join(f'{v:.0f}' for v in ret)}) | {summary[src]['kl_mean']:.3f} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({"args": vars(args), "reference_return": ref_return, "runs": results,
                                   "summary": summary, "total_wall": time.perf_counter() - start}, indent=1))
    print(f"\nwrote {RESULTS}; total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
