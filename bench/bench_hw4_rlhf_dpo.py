"""Benchmark of hw4_rlhf_dpo: true-reward PPO, RLHF and DPO from the same reference policy, over seeds,
plus the KL-coefficient and beta sweeps that the notebook plots as precomputed. Prints Markdown tables.

    python bench/bench_hw4_rlhf_dpo.py                 # 3 seeds + sweeps (about 10 minutes on 2 idle cores)
    python bench/bench_hw4_rlhf_dpo.py --seeds 0 --no-sweep --steps 20000   # a quick smoke run
    python bench/bench_hw4_rlhf_dpo.py --record        # also refresh datasets/hw4/precomputed.json + MANIFEST
    python bench/bench_hw4_rlhf_dpo.py --preference-only   # every setting chosen from preference data (key preference_only)

The first table (the default) was measured on the upright pairs (``hopper_prefs/hopper_prefs.npz``) with
their reward model (``datasets/hw4/reward_model_upright.pt``) and the offset b = 5 chosen on the true
return; it stays for comparison. ``--preference-only`` measures the course's protocol on the pairs with
falls: the offset from the reward model's absorbing state, the KL coefficient and beta from sweeps on
seed 0 judged by preference data and the policies alone, then every seed at the choices, and the true
return read once, at the end.

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
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from autograder.core.grader import build_reference

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench import run_record  # noqa: E402
RESULTS = REPO / "bench" / "results" / "hw4_rlhf_dpo.json"
PRECOMPUTED = REPO / "datasets" / "hw4" / "precomputed.json"
FINAL_EPISODES = 20
UPRIGHT_PREFS = "hopper_prefs/hopper_prefs.npz"  # the first table: the upright pairs, their reward model, b = 5
UPRIGHT_REWARD_MODEL = "hw4/reward_model_upright.pt"
UPRIGHT_OFFSET = 5.0


def solution_namespace() -> dict:
    """The solution notebook's parameters, setup and stub cells, run in a fresh namespace."""
    return build_reference("hw4_rlhf_dpo", {"FAST": os.environ.get("HW4_BENCH_FAST") == "1"})


def _final(ns: dict, policy, reference, reward_fn=None) -> dict:
    return ns["evaluate_policy"](policy, reference, reward_fn, n_episodes=FINAL_EPISODES)


def job(kind: str, seed: int, value: float, steps: int | None, offset: float | None = None) -> dict:
    """One run of the first table in a fresh worker (the upright pairs and their reward model, as first
    measured): ``kind`` in {reward_model, ppo, rlhf, dpo}; ``value`` is the KL coefficient (rlhf) or beta
    (dpo); ``offset`` is the learned reward's per-step offset b (rlhf; default 5, tuned on the true return)."""
    import torch

    ns = solution_namespace()
    torch.set_num_threads(1)
    ns["seed_everything"](seed)
    reference, prefs = ns["load_reference"](), ns["load_hopper_preferences"](UPRIGHT_PREFS)
    ppo_steps = steps or ns["PPO_STEPS"]
    out: dict = {"kind": kind, "seed": seed, "value": value, "steps": ppo_steps}
    cpu0 = time.process_time()
    reward_model = ns["load_reward_model"](UPRIGHT_REWARD_MODEL)
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
        offset = UPRIGHT_OFFSET if offset is None else offset
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


# --------------------------------------------------------------------------- every setting from preference data
# 0.0 (no penalty) is a candidate so that the coverage rule is seen to bind or not: it was added, before its run,
# to the three coefficients first swept (issue 34); the rule, not the true return, says whether it is taken.
KL_CANDIDATES = (0.0, 0.01, 0.03, 0.1)
BETA_CANDIDATES = (0.03, 0.1, 0.3, 1.0)
PREF_PARTIAL = RESULTS.with_suffix(".preference_only.partial.json")


def pref_job(kind: str, seed: int, value: float, steps: int | None, data: str = "falls") -> dict:
    """One run of the preference-only protocol in a fresh worker. ``pref_rlhf``: PPO on the reward model
    with an absorbing state (``datasets/hw4/reward_model.pt``), offset ``data_offset`` from its metadata,
    KL coefficient ``value``. ``pref_dpo``: DPO with beta ``value`` on the pairs with falls (``data="falls"``)
    or on the upright pairs (``"upright"``). Each records what the protocol may look at (``check``:
    learned return, disagreement, KL; ``val_accuracy`` for DPO) and, apart, the true ``final`` evaluation."""
    import torch

    from rlcourse.preferences import HOPPER_PREFS_FILE, HOPPER_PREFS_UPRIGHT_FILE
    from rlcourse.rlhf import preference_only_check

    ns = solution_namespace()
    torch.set_num_threads(1)
    ns["seed_everything"](seed)
    reference = ns["load_reference"]()
    prefs = ns["load_hopper_preferences"](HOPPER_PREFS_UPRIGHT_FILE if data == "upright" else HOPPER_PREFS_FILE)
    reward_model = ns["load_reward_model"]()
    meta, rf = reward_model.metadata, ns["reward_function"](reward_model)
    offset = meta["data_offset"]
    ppo_steps = steps or ns["PPO_STEPS"]
    out: dict = {"kind": kind, "seed": seed, "value": value, "steps": ppo_steps, "data": data}
    cpu0, t0 = time.process_time(), time.perf_counter()
    if kind == "pref_rlhf":
        cfg = ns["PPOConfig"](total_steps=ppo_steps, n_steps=ns["PPO_ENV_STEPS_PER_ROLLOUT"], seed=seed,
                              eval_every=10**9, kl_coef=value)
        wrap = lambda envs: ns["LearnedRewardWrapper"](envs, rf, meta["step_mean"], meta["step_std"], offset)
        policy, _ = ns["ppo"](reference, reference, ns["compute_gae"], ns["ppo_loss"], cfg, wrap=wrap, verbose=False)
        out.update(offset=offset, rm_wall=meta["fit_seconds"])
    elif kind == "pref_dpo":
        pairs = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.train_pairs, prefs.train_mu)
        val = ns["oriented_pairs"](prefs.obs, prefs.act, prefs.test_pairs, prefs.test_mu)
        n = ns["DPO_STEPS"]
        policy, log = ns["train_dpo"](reference, reference, ns["dpo_loss"], pairs, value, n_steps=n, val=val,
                                      log_every=max(1, n // 10), seed=seed, verbose=False)
        out["val_accuracy"] = log.steps[-1].get("val_accuracy")
    else:
        raise ValueError(kind)
    out["wall"] = time.perf_counter() - t0 + out.get("rm_wall", 0.0)
    out["cpu"] = time.process_time() - cpu0 + out.get("rm_wall", 0.0)
    out["check"] = preference_only_check(policy, reference, reward_model, offset, n_episodes=5)
    out["final"] = _final(ns, policy, reference)  # the evaluation: never read by the choices below
    return out


def survival_bonus(ensemble, prefs, offset: float) -> float:
    """The learned reward's survival bonus per upright step, in the environment's units: regress the learned
    reward (normalised, plus ``offset``) on the environment's reward minus its healthy bonus 1 over the upright
    steps of the data; intercept / slope is what it pays for one more upright step with no progress and no
    control cost (the environment pays exactly 1). An evaluation: it reads the true reward."""
    meta = ensemble.metadata
    real = ~prefs.absorbing
    last = np.zeros_like(real)
    last[np.flatnonzero(prefs.terminated), prefs.length[prefs.terminated] - 1] = True  # the fall's own step
    upright = real & ~last
    learned = (ensemble.predict(prefs.obs[upright], prefs.act[upright]).mean(0) - meta["step_mean"]) / meta["step_std"]
    slope, intercept = np.polyfit(prefs.rewards[upright] - 1.0, learned + offset, 1)
    return float(intercept / slope)


def _protocol_job(kind: str, seed: int, value: float, steps: int | None, data: str) -> dict:
    """A run of the protocol's table: true-reward PPO (``kind="ppo"``, the first table's job) or a preference-only run."""
    if kind == "ppo":
        return {**job("ppo", seed, value, steps), "data": data}
    return pref_job(kind, seed, value, steps, data)


def preference_only(args, workers: int) -> dict:
    """Run the protocol: sweep on seed 0, choose the KL coefficient and beta from preference data and the
    policies alone, run the other seeds at the choices, then read the true returns once for the table."""
    from rlcourse.preferences import HOPPER_PREFS_UPRIGHT_FILE, load_hopper_preferences
    from rlcourse.rlhf import bootstrap_ratio, choose_beta, choose_kl_coef, disagreement_threshold, load_reward_model

    steps = args.steps
    done = json.loads(PREF_PARTIAL.read_text()) if PREF_PARTIAL.exists() and not args.fresh else []
    if not args.fresh and RESULTS.exists():  # runs of the last complete invocation, same code and budget: reused
        recorded = json.loads(RESULTS.read_text()).get("preference_only", {}).get("runs", [])
        done = [r for r in recorded if r["steps"] == (steps or 200_000)] + done
    key = lambda kind, seed, value, data: (kind, seed, value, data)
    have = {key(r["kind"], r["seed"], r["value"], r["data"]): r for r in done}

    def run(jobs: list[tuple]) -> list[dict]:
        todo = [j for j in jobs if key(*j[:3], j[4]) not in have]
        print(f"{len(jobs)} runs ({len(jobs) - len(todo)} reused)", flush=True)
        if todo:
            with ProcessPoolExecutor(workers) as pool:
                futures = {pool.submit(_protocol_job, *j): j for j in todo}
                for f in as_completed(futures):
                    r = f.result()
                    print(f"  done {r['kind']} {r['data']} seed {r['seed']} value {r['value']:g} wall {r['wall']:.0f} s",
                          flush=True)
                    have[key(r["kind"], r["seed"], r["value"], r["data"])] = r
                    PREF_PARTIAL.write_text(json.dumps(list(have.values()), indent=1))
        return [have[key(*j[:3], j[4])] for j in jobs]

    prefs = load_hopper_preferences()
    rm = load_reward_model()
    real = ~prefs.absorbing
    test = prefs.test_segment
    threshold = disagreement_threshold(rm, prefs.obs[test], prefs.act[test], real[test])
    # 1. sweeps on seed 0: what the protocol may look at
    sweep = run([("pref_rlhf", 0, c, steps, "falls") for c in KL_CANDIDATES]
                + [("pref_dpo", 0, b, steps, d) for d in ("falls", "upright") for b in BETA_CANDIDATES])
    kl_checks = {r["value"]: r["check"] for r in sweep if r["kind"] == "pref_rlhf"}
    kl = choose_kl_coef(kl_checks, threshold)
    betas = {d: choose_beta({r["value"]: r["val_accuracy"] for r in sweep if r["kind"] == "pref_dpo" and r["data"] == d})
             for d in ("falls", "upright")}
    print(f"chosen from preference data: KL coefficient {kl:g} (disagreement threshold {threshold:.3f}), "
          f"beta {betas['falls']:g} (pairs with falls), {betas['upright']:g} (upright pairs)", flush=True)
    # 2. the other seeds at the choices
    final = run([("pref_rlhf", s, kl, steps, "falls") for s in args.seeds]
                + [("pref_dpo", s, betas[d], steps, d) for d in ("falls", "upright") for s in args.seeds])
    # 3. true-reward PPO at the same budget on every seed: the first table's runs (same code), the seeds it lacks
    # run here
    saved = json.loads(RESULTS.read_text())
    for r in saved["runs"]:
        if r["kind"] == "ppo" and r["steps"] == (steps or 200_000):
            have.setdefault(key("ppo", r["seed"], 0.0, "true reward"), {**r, "data": "true reward"})
    ppo = run([("ppo", s, 0.0, steps, "true reward") for s in args.seeds])
    # 4. the evaluation, once
    ppo_returns = [r["final"]["return"] for r in ppo]
    ppo_mean = float(np.mean(ppo_returns))
    methods = {}
    for name, kind, data in (("RLHF", "pref_rlhf", "falls"), ("DPO, pairs with falls", "pref_dpo", "falls"),
                             ("DPO, upright pairs", "pref_dpo", "upright")):
        rs = [r for r in final if r["kind"] == kind and r["data"] == data]
        rets = [r["final"]["return"] for r in rs]
        methods[name] = {"value": rs[0]["value"], "seeds": [r["seed"] for r in rs], "returns": rets,
                         "return_mean": float(np.mean(rets)), "return_std": float(np.std(rets)),
                         "fraction_of_true_reward_ppo": float(np.mean(rets)) / ppo_mean,
                         "fraction_interval": bootstrap_ratio(rets, ppo_returns),
                         "checks": [r["check"] for r in rs],
                         "kls": [r["final"]["kl"] for r in rs], "lengths": [r["final"]["length"] for r in rs],
                         "walls": [r["wall"] for r in rs], "cpus": [r["cpu"] for r in rs],
                         "val_accuracy": [r.get("val_accuracy") for r in rs]}
    old_rm = load_reward_model("hw4/reward_model_upright.pt")
    upright_prefs = load_hopper_preferences(HOPPER_PREFS_UPRIGHT_FILE)
    meta = rm.metadata
    covered = {str(c): ch["disagreement"] <= threshold for c, ch in kl_checks.items()}
    out = {
        "meta": run_record.meta(),
        "protocol": "offset b = the reward model's data_offset (its absorbing state pays 0); KL coefficient: among "
                    f"{list(KL_CANDIDATES)} (seed 0), the highest learned return among policies whose mean ensemble "
                    "disagreement is at most the 90% quantile of held-out segments'; beta: among "
                    f"{list(BETA_CANDIDATES)} (seed 0), the best held-out preference accuracy (ties within 0.005: "
                    "the largest beta); then every seed at the choices; true returns read once, after",
        "kl_coef": kl, "beta": betas["falls"], "beta_upright": betas["upright"], "offset": meta["data_offset"],
        "disagreement_threshold": threshold, "kl_checks": {str(c): ch for c, ch in kl_checks.items()},
        "kl_candidates": list(KL_CANDIDATES), "kl_covered": covered, "rule_binds": not all(covered.values()),
        "beta_val_accuracy": {d: {str(r["value"]): r["val_accuracy"] for r in sweep
                                  if r["kind"] == "pref_dpo" and r["data"] == d} for d in ("falls", "upright")},
        "sweep_true_returns": {f"{r['kind']} {r['data']} {r['value']:g}": r["final"]["return"] for r in sweep},
        "reward_model": {k: meta[k] for k in ("test_accuracy", "bayes_ceiling_test", "return_correlation",
                                              "absorbing_reward", "data_offset", "fit_seconds")},
        "survival_bonus": {"learned, data offset": survival_bonus(rm, prefs, meta["data_offset"]),
                           "upright model, b = 5": survival_bonus(old_rm, upright_prefs, 5.0),
                           "upright model, b = 0": survival_bonus(old_rm, upright_prefs, 0.0),
                           "environment": 1.0},
        "ppo_true_reward": {"seeds": list(args.seeds), "returns": ppo_returns, "return_mean": ppo_mean,
                            "return_std": float(np.std(ppo_returns)), "kls": [r["final"]["kl"] for r in ppo],
                            "cpus": [r["cpu"] for r in ppo],
                            "role": "the yardstick at equal budget (one optimiser, 200,000 steps), not a ceiling: "
                                    "the ceiling is the optimum of the true return, which no run here knows"},
        "methods": methods,
        "fraction_of_true_reward_ppo": methods["RLHF"]["fraction_of_true_reward_ppo"],
        "returns": methods["RLHF"]["returns"],
        "runs": sweep + [r for r in final if r not in sweep] + [r for r in ppo if r["seed"] not in
                                                                 {q["seed"] for q in saved["runs"] if q["kind"] == "ppo"}],
    }
    saved["preference_only"] = out
    RESULTS.write_text(json.dumps(saved, indent=1))
    PREF_PARTIAL.unlink(missing_ok=True)
    print_preference_only(out)
    return out


GUARD_STEPS_FACTOR = 4
GUARD_DECLARATION = (
    "Declared on 2026-12-04, before its runs, after the KL sweep had shown every candidate covered (disagreement "
    "0.266 to 0.354 against the threshold 0.417): the coverage rule is tested on a policy that optimises the learned "
    "reward harder than any candidate, no KL penalty and 4 x the PPO budget (800,000 steps), seeds 0, 1 and 2. "
    "Prediction: its mean ensemble disagreement exceeds the threshold, so the rule would reject it. Reported "
    "whichever way it comes out; its true return is recorded and, like the sweep's, read by no choice.")


def guard_check(args, workers: int) -> dict:
    """The coverage rule on a policy pushed past every candidate (``GUARD_DECLARATION``): RLHF without a KL penalty
    for ``GUARD_STEPS_FACTOR`` times the budget. Merged into the results file under ``preference_only.guard_check``."""
    from rlcourse.preferences import load_hopper_preferences
    from rlcourse.rlhf import disagreement_threshold, load_reward_model

    steps = GUARD_STEPS_FACTOR * (args.steps or 200_000)
    prefs, rm = load_hopper_preferences(), load_reward_model()
    test = prefs.test_segment
    threshold = disagreement_threshold(rm, prefs.obs[test], prefs.act[test], ~prefs.absorbing[test])
    with ProcessPoolExecutor(workers) as pool:
        runs = list(pool.map(pref_job, ["pref_rlhf"] * len(args.seeds), args.seeds, [0.0] * len(args.seeds),
                             [steps] * len(args.seeds)))
    out = {"declared": GUARD_DECLARATION, "meta": run_record.meta(), "kl_coef": 0.0, "steps": steps,
           "disagreement_threshold": threshold,
           "runs": [{"seed": r["seed"], "check": r["check"], "covered": r["check"]["disagreement"] <= threshold,
                     "final": r["final"], "wall": r["wall"], "cpu": r["cpu"]} for r in runs]}
    out["rejected_seeds"] = [r["seed"] for r in out["runs"] if not r["covered"]]
    saved = json.loads(RESULTS.read_text())
    saved["preference_only"]["guard_check"] = out
    RESULTS.write_text(json.dumps(saved, indent=1))
    print(f"guard check ({steps:,} steps, no KL penalty, threshold {threshold:.3f}): " + "; ".join(
        f"seed {r['seed']}: disagreement {r['check']['disagreement']:.3f} "
        f"({'covered' if r['covered'] else 'REJECTED'}), learned return {r['check']['learned_return']:.0f}, "
        f"KL {r['check']['kl']:.2f}, true return {r['final']['return']:.0f}" for r in out["runs"]))
    return out


def print_preference_only(out: dict) -> None:
    print(f"\n### hw4_rlhf_dpo, every setting from preference data ({out['protocol']})\n")
    print(f"offset b = {out['offset']:.2f} (data), KL coefficient {out['kl_coef']:g}, beta {out['beta']:g} "
          f"(upright pairs: {out['beta_upright']:g}); reward model held-out accuracy "
          f"{out['reward_model']['test_accuracy']:.3f} (ceiling {out['reward_model']['bayes_ceiling_test']:.3f})\n")
    ppo = out["ppo_true_reward"]
    print("| method | setting | seeds | true return | per seed | % of true-reward PPO (95% bootstrap interval) "
          "| KL (nats/step) | CPU s |")
    print("|---|---|---:|---:|---|---:|---:|---:|")
    print(f"| PPO, true reward (yardstick at equal budget) | – | {len(ppo['returns'])} | {ppo['return_mean']:.0f} ± "
          f"{np.std(ppo['returns']):.0f} | " + ", ".join(f"{v:.0f}" for v in ppo["returns"]) + " | 100% | "
          + (f"{np.mean(ppo['kls']):.3f} | {np.mean(ppo['cpus']):.0f} |" if "kls" in ppo else "– | – |"))
    for name, m in out["methods"].items():
        setting = (f"b = {out['offset']:.2f}, KL {m['value']:g}" if name == "RLHF" else f"β = {m['value']:g}")
        lo, hi = m.get("fraction_interval", (np.nan, np.nan))
        print(f"| {name} | {setting} | {len(m['returns'])} | {m['return_mean']:.0f} ± {m['return_std']:.0f} | "
              + ", ".join(f"{v:.0f}" for v in m["returns"])
              + f" | {100 * m['fraction_of_true_reward_ppo']:.0f}% ({100 * lo:.0f}–{100 * hi:.0f}%) | "
              f"{np.mean(m['kls']):.3f} | {np.mean(m['cpus']):.0f} |")
    print("\nKL sweep, seed 0 (what the choice saw): " + "; ".join(
        f"{c}: learned return {ch['learned_return']:.0f}, disagreement {ch['disagreement']:.3f}, KL {ch['kl']:.3f}"
        for c, ch in out["kl_checks"].items()) + f" (threshold {out['disagreement_threshold']:.3f})")
    if "kl_covered" in out:
        print("Coverage: " + "; ".join(f"{c} {'covered' if v else 'NOT covered'}" for c, v in out["kl_covered"].items())
              + (" (the rule binds: it rejects a candidate)" if out["rule_binds"] else
                 " (the rule does not bind: every candidate is covered)"))
        print("Checks of the runs at the chosen KL coefficient, per seed: " + "; ".join(
            f"seed {s}: disagreement {ch['disagreement']:.3f}, learned return {ch['learned_return']:.0f}"
            for s, ch in zip(out["methods"]["RLHF"]["seeds"], out["methods"]["RLHF"]["checks"])))
    if "guard_check" in out:
        g = out["guard_check"]
        print(f"Guard check (declared before its runs; no penalty, {g['steps']:,} steps): " + "; ".join(
            f"seed {r['seed']}: disagreement {r['check']['disagreement']:.3f} "
            f"({'covered' if r['covered'] else 'REJECTED'}), learned return {r['check']['learned_return']:.0f}, "
            f"true return {r['final']['return']:.0f}" for r in g["runs"]))
    print("Beta sweep, seed 0, held-out accuracy: " + "; ".join(
        f"{d}: " + ", ".join(f"{b} → {a:.3f}" for b, a in accs.items()) for d, accs in out["beta_val_accuracy"].items()))
    print("Sweep true returns (read after the choice): " + "; ".join(f"{k}: {v:.0f}" for k, v in out["sweep_true_returns"].items()))
    print("Survival bonus per upright step (environment: 1): " + "; ".join(
        f"{k} {v:.2f}" for k, v in out["survival_bonus"].items()))


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
    p.add_argument("--preference-only", action="store_true",
                   help="only the runs whose every setting is chosen from preference data (key preference_only)")
    p.add_argument("--guard-check", action="store_true", help="only the coverage rule's test on a policy pushed "
                   "past every candidate (GUARD_DECLARATION), merged into the results file")
    p.add_argument("--tables-only", action="store_true", help="reprint (and with --record, re-record) the tables "
                   "from bench/results/hw4_rlhf_dpo.json without running anything")
    args = p.parse_args(argv)
    if args.smoke:
        os.environ["HW4_BENCH_FAST"] = "1"
        global RESULTS, FINAL_EPISODES
        RESULTS, FINAL_EPISODES = Path(os.environ.get("TMPDIR", "/tmp")) / "hw4_bench_smoke.json", 2

    if args.guard_check:
        guard_check(args, args.workers)
        return
    if args.preference_only:
        out = (json.loads(RESULTS.read_text())["preference_only"] if args.tables_only
               else preference_only(args, args.workers))
        if args.tables_only:
            print_preference_only(out)
        if args.record:
            _record_preference_only(out, args)
        return
    ns = solution_namespace()
    steps, dpo_steps = args.steps or ns["PPO_STEPS"], ns["DPO_STEPS"]
    args.kl = ns["KL_COEF"] if args.kl is None else args.kl
    args.beta = ns["BETA"] if args.beta is None else args.beta
    offset = UPRIGHT_OFFSET
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


def _record_preference_only(out: dict, args) -> None:
    """Add the protocol's results (without the per-run curves) to the notebook's precomputed file, re-record it."""
    from rlcourse import data

    pre = json.loads(PRECOMPUTED.read_text())
    pre["preference_only"] = {k: v for k, v in out.items() if k != "runs"}
    PRECOMPUTED.write_text(json.dumps(pre, indent=1) + "\n")
    entry = data.read_manifest()["hw4/precomputed.json"]
    first = entry["command"].split("; python bench/bench_hw4_rlhf_dpo.py --preference-only")[0]  # the table's command
    data.add(PRECOMPUTED, first + "; python bench/bench_hw4_rlhf_dpo.py --preference-only --record "
             f"--seeds {' '.join(map(str, args.seeds))} --workers {args.workers}", entry["seed"],
             {**entry["info"], "preference_only": "every setting chosen from preference data (bench --preference-only)"})
    print(f"recorded {PRECOMPUTED.relative_to(REPO)} (key preference_only)")


def _record(summary: dict, args: dict) -> None:
    """Write the notebook's precomputed file and record it in the MANIFEST."""
    from rlcourse import data

    kept = json.loads(PRECOMPUTED.read_text()) if PRECOMPUTED.exists() else {}
    if "preference_only" in kept:  # written by --preference-only --record: keep it
        summary = {**summary, "preference_only": kept["preference_only"]}
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
