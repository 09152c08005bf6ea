"""Benchmark of hw1b_multimodal: who passes the obstacle, on which side, over 3 training seeds.

Prints the Markdown table that the README shows and records every number in
``bench/results/hw1b_multimodal.json`` (per policy: ``success`` and ``left_fraction``, one entry per seed,
beside the expert's; plus ``coverage`` and the training times):

    python bench/bench_hw1b_multimodal.py                 # 3 seeds (a few minutes on 2 quiet cores)
    python bench/bench_hw1b_multimodal.py --seeds 0 --episodes 50

Every stub is the reference solution (``solutions/hw1b_multimodal``, run through the grader's own
``build_reference``); the training recipes are the notebook's full budget: 1,500 Adam steps per L2
clone, 2,000 per mixture (5 components), 3,000 per flow-matching policy (lr 2e-3), all on the shipped
100 demonstrations. Seed ``s`` trains every learner with seed ``s`` and evaluates it on
``ObstacleTracks(episodes, 10_000 + 1_000 s)``; the expert drives the same episodes with its own fair
coin per episode (``default_rng(10_000 + 1_000 s)``). A success is an episode that runs its 100 steps.

**Averaging that bites** (``--averaging``; the ``"averaging"`` entry of the results file, the other entries are
kept). On the task above the L2 clone survives: acting in closed loop, its mean is unstable at the centre and
the steering noise picks a side. The protocol below, written down before any learner was trained on it, asks
whether the clone drives into the obstacle when it must commit to a manoeuvre at the state where the
demonstrators split:

- *Task*: ``mm.COMMIT_TASKS``. Every episode starts where the demonstrators begin to swerve, about 9 steps
  before the obstacle, so the first observation is the one where they split 50/50 (a fair coin each); 30
  steps per episode; the race track's own steering noise (0.02 rad). The swerve's offset (0.55) was set so that
  the expert's own chunks of 8, planned without noise and driven open loop, succeed in at least 98.7% of
  episodes (checked on the scripted expert alone; no learner was run before the protocol was fixed).
- *Settings* (three, all reported): how fast the demonstrators swerve out, the arc over which their offset
  rises: ``sharp`` 2.0, ``medium`` 3.0, ``gentle`` 4.0 units (4, 6 and 8 steps).
- *Data*: ``datasets/hw1b/commit_<setting>.npz``, 200 demonstrations each (one undecided state per
  demonstration, its first).
- *Learners, one chunking for all*: chunks of H = 8 actions executed whole (k = 8), so that the first chunk
  covers the approach and a mean chunk ends at the obstacle's edge: the L2 clone (1,500 Adam steps), the
  Gaussian mixture (5 components, 2,000 steps) and flow matching (3,000 steps, lr 2e-3, K = 10 Euler steps),
  the recipes of the main task. Contrast: the same L2 clone one step at a time (H = k = 1).
- *Seeds*: 0 to 4. Seed ``s`` trains with seed ``s`` and evaluates on ``ObstacleTracks(100, 20_000 + 1_000 s,
  task)``; the expert drives the same episodes with its own fair coin (``default_rng(20_000 + 1_000 s)``).
- *Measured per seed*: success (30 steps driven), and among the successful episodes the fraction that passed
  on the left (``flow_left`` for flow matching). Also the expert's own chunks driven open loop (the ceiling of
  any policy that executes 8 actions blind).
- *Targets* (issue 34): in every setting the chunked L2 clone reaches at most 0.6 of the expert's success,
  flow matching at least 0.9 with each side between 30 and 70% of its successes.

    python bench/bench_hw1b_multimodal.py --averaging       # 3 settings x 5 seeds: 4.4 min at load average 3 to 7

*Follow-up* (``--followup``, the ``"averaging_followup"`` entry), declared after the protocol above had been run
and had left flow matching at 0.65 to 0.78 (its failures: chunks sampled between the two modes at the first
state, crashing at the obstacle; 10, 20 or 50 Euler steps did not change that; one diagnostic run, medium swerve
seed 0, went from 0.70 to 0.81 with 12,000 steps): is the gap a matter of training or of data? The same
settings, seeds and evaluation; flow matching only, with 12,000 Adam steps (four times the recipe) on the 200
shipped demonstrations, and with 12,000 steps on 1,000 demonstrations (made by the dataset script's recorder with
seed 0, in memory; their first 200 are the shipped ones). Every cell is reported, whatever it shows.

    python bench/bench_hw1b_multimodal.py --followup        # 3 settings x 5 seeds x 2 cells: 33 min at load 15 to 20

Each (setting, seed) is written to ``bench/results/hw1b_multimodal.averaging.partial.json`` as it finishes and
skipped when the script is run again; the final file gets per-seed lists and a ``meta`` object.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from autograder.core.grader import build_reference
from rlcourse import data
from rlcourse import multimodal as mm

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402
RESULTS = REPO / "bench" / "results" / "hw1b_multimodal.json"
REG_STEPS, MIX_STEPS, FLOW_STEPS = 1500, 2000, 3000       # the notebook's full budget
CHUNK, EXECUTE, EULER_STEPS = 4, 2, 10
POLICIES = {  # name -> (kind, H, k, K)
    "l2_one_step": ("l2", 1, 1, None),
    "l2_chunk": ("l2", CHUNK, EXECUTE, None),
    "mixture_one_step": ("mixture", 1, 1, None),
    "mixture_chunk": ("mixture", CHUNK, EXECUTE, None),
    "flow": ("flow", CHUNK, EXECUTE, EULER_STEPS),
    "flow_K1": ("flow", CHUNK, EXECUTE, 1),
    "flow_H8_k8": ("flow", 8, 8, EULER_STEPS),
}
LABELS = {
    "expert": "expert (fair coin per episode)",
    "l2_one_step": "L2 clone, one step at a time",
    "l2_chunk": f"L2 clone, chunks H={CHUNK}, k={EXECUTE}",
    "mixture_one_step": "Gaussian mixture (5), one step at a time",
    "mixture_chunk": f"Gaussian mixture (5), chunks H={CHUNK}, k={EXECUTE}",
    "flow": f"flow matching, H={CHUNK}, k={EXECUTE}, K={EULER_STEPS}",
    "flow_K1": f"flow matching, H={CHUNK}, k={EXECUTE}, K=1",
    "flow_H8_k8": f"flow matching, H=8, k=8, K={EULER_STEPS}",
}


class Bench:
    def __init__(self, episodes: int) -> None:
        self.ns = build_reference("hw1b_multimodal")    # the solution notebook's setup and stub cells
        self.demos = data.load_npz("hw1b/demos.npz")
        self.stats = mm.obs_statistics(self.demos["obs"])
        self.episodes = episodes
        self.cache: dict = {}

    def chunks(self, horizon: int):
        obs, chunks = mm.make_chunks(self.demos["obs"], self.demos["actions"], self.demos["lengths"], horizon)
        return torch.as_tensor(obs), torch.as_tensor(chunks)

    def train(self, kind: str, horizon: int, seed: int, demos: dict | None = None, stats: dict | None = None,
              flow_steps: int = FLOW_STEPS):
        """A trained learner; on the shipped demonstrations (cached, with its training time) unless ``demos`` are
        given (then it returns the model alone)."""
        if demos is not None:
            obs, chunks = (torch.as_tensor(x) for x in mm.make_chunks(demos["obs"], demos["actions"], demos["lengths"],
                                                                      horizon))
            return self._fit(kind, horizon, seed, obs, chunks, stats, flow_steps)
        key = (kind, horizon, seed)
        if key in self.cache:
            return self.cache[key], 0.0
        obs, chunks = self.chunks(horizon)
        start = time.perf_counter()
        self.cache[key] = self._fit(kind, horizon, seed, obs, chunks, self.stats, flow_steps)
        return self.cache[key], time.perf_counter() - start

    def _fit(self, kind: str, horizon: int, seed: int, obs, chunks, stats, flow_steps: int):
        torch.manual_seed(seed)
        if kind == "l2":
            model = mm.ChunkRegressor(horizon=horizon, **stats)
            mm.fit(model, lambda i, g: ((model(obs[i]) - chunks[i]) ** 2).sum(dim=(1, 2)).mean(), len(obs), REG_STEPS,
                   seed=seed)
        elif kind == "mixture":
            model = mm.MixtureNet(horizon=horizon, **stats)
            nll = self.ns["mixture_nll"]
            mm.fit(model, lambda i, g: nll(*model(obs[i]), chunks[i].reshape(len(i), -1)), len(obs), MIX_STEPS, seed=seed)
        else:
            model = mm.VelocityNet(horizon=horizon, **stats)
            fm = self.ns["flow_matching_loss"]

            def loss(i, g):
                return fm(model, obs[i], chunks[i], torch.randn(chunks[i].shape, generator=g),
                          torch.rand(len(i), generator=g))

            mm.fit(model, loss, len(obs), flow_steps, lr=2e-3, seed=seed)
        return model.eval()

    def planner(self, kind: str, model, n_steps, seed: int):
        generator = torch.Generator().manual_seed(seed)
        if kind == "l2":
            return lambda obs: model(torch.as_tensor(obs)).detach().numpy()
        if kind == "mixture":
            return lambda obs: model.sample(torch.as_tensor(obs), generator).numpy()
        euler = self.ns["euler_sample"]
        return lambda obs: euler(model, torch.as_tensor(obs),
                                 torch.randn((len(obs), model.horizon, model.act_dim), generator=generator), n_steps).numpy()

    def measure(self, plan, execute: int, eval_seed: int, expert_sides) -> dict:
        episodes = self.ns["chunked_rollout"](plan, mm.ObstacleTracks(self.episodes, eval_seed), execute)
        sides = mm.passing_sides(episodes.obs, episodes.mask)
        cov = self.ns["mode_coverage"](sides, expert_sides)
        return {"success": float(np.mean(episodes.lengths == mm.HORIZON)), "left_fraction": cov["left"],
                "right_fraction": cov["right"], "coverage": cov["coverage"]}

    def run_seed(self, seed: int) -> dict:
        eval_seed = 10_000 + 1_000 * seed
        coin = np.random.default_rng(eval_seed).choice([mm.LEFT, mm.RIGHT], size=self.episodes)
        expert = mm.ObstacleExpert(coin)
        expert_eps = self.ns["chunked_rollout"](lambda o: expert.act(o)[:, None], mm.ObstacleTracks(self.episodes, eval_seed), 1)
        expert_sides = mm.passing_sides(expert_eps.obs, expert_eps.mask)
        out = {"expert": self.measure(lambda o: expert.act(o)[:, None], 1, eval_seed, expert_sides)}
        for name, (kind, horizon, execute, n_steps) in POLICIES.items():
            model, seconds = self.train(kind, horizon, seed)
            out[name] = self.measure(self.planner(kind, model, n_steps, seed), execute, eval_seed, expert_sides)
            out[name]["train_seconds"] = round(seconds, 1)
            print(f"seed {seed} {name:18s} success {out[name]['success']:.2f} left {out[name]['left_fraction']:.2f} "
                  f"right {out[name]['right_fraction']:.2f} coverage {out[name]['coverage']:.2f} "
                  f"({seconds:.0f} s training)", flush=True)
        return out


def table(per_seed: dict[int, dict]) -> str:
    seeds = sorted(per_seed)
    expert_success = np.mean([per_seed[s]["expert"]["success"] for s in seeds])
    lines = ["| policy | success | / expert's | passed left | passed right | coverage |", "|---|---:|---:|---:|---:|---:|"]
    for name in ["expert", *POLICIES]:
        cols = {k: np.array([per_seed[s][name][k] for s in seeds]) for k in ("success", "left_fraction",
                                                                            "right_fraction", "coverage")}
        ms = lambda x: f"{x.mean():.2f} ± {x.std():.2f}"  # noqa: E731
        lines.append(f"| {LABELS[name]} | {ms(cols['success'])} | {cols['success'].mean() / expert_success:.0%} | "
                     f"{ms(cols['left_fraction'])} | {ms(cols['right_fraction'])} | {ms(cols['coverage'])} |")
    return "\n".join(lines)


# ---------------------------------------------------------------- averaging that bites (the commit tasks)

COMMIT_CHUNK = 8                            # H = k for every chunked learner of the averaging protocol
AVERAGING_SEEDS = (0, 1, 2, 3, 4)
AVERAGING_EPISODES = 100
AVERAGING_PARTIAL = RESULTS.with_suffix(".averaging.partial.json")
AVERAGING_POLICIES = {  # name -> (kind, H, k)
    "l2": ("l2", COMMIT_CHUNK, COMMIT_CHUNK),
    "mixture": ("mixture", COMMIT_CHUNK, COMMIT_CHUNK),
    "flow": ("flow", COMMIT_CHUNK, COMMIT_CHUNK),
    "l2_one_step": ("l2", 1, 1),
}


def expert_chunk_planner(task: mm.ObstacleTask, sides: np.ndarray, horizon: int):
    """The expert's own chunks: from the current states, its next ``horizon`` actions on a noise-free track."""
    expert = mm.ObstacleExpert(sides, task=task)

    def plan(obs):
        state, actions = mm.state_of(obs), []
        for _ in range(horizon):
            action = expert.act(mm.observe(state))
            actions.append(action)
            state, _ = mm.rt.step_states(state, action[:, 0], np.zeros(len(state)))
        return np.stack(actions, axis=1)
    return plan


def averaging_run(bench: "Bench", name: str, seed: int, episodes: int) -> dict:
    """One setting, one seed: the expert, its open-loop chunks and every learner, on the same 100 episodes."""
    task = mm.COMMIT_TASKS[name]
    demos = data.load_npz(f"hw1b/commit_{name}.npz")
    stats = mm.obs_statistics(demos["obs"])
    eval_seed = 20_000 + 1_000 * seed
    coin = np.random.default_rng(eval_seed).choice([mm.LEFT, mm.RIGHT], size=episodes)
    rollout = bench.ns["chunked_rollout"]

    def measure(plan, execute):
        eps = rollout(plan, mm.ObstacleTracks(episodes, eval_seed, task), execute)
        ok = eps.lengths == task.horizon
        sides = mm.passing_sides(eps.obs, eps.mask)
        return {"success": float(ok.mean()), "left_of_successes": float(np.mean(sides[ok] == mm.LEFT)) if ok.any()
                else None, "left": float(np.mean(sides == mm.LEFT)), "right": float(np.mean(sides == mm.RIGHT))}

    expert = mm.ObstacleExpert(coin, task=task)
    out = {"expert": measure(lambda o: expert.act(o)[:, None], 1),
           "expert_chunks": measure(expert_chunk_planner(task, coin, COMMIT_CHUNK), COMMIT_CHUNK)}
    for policy, (kind, horizon, execute) in AVERAGING_POLICIES.items():
        start = time.perf_counter()
        model = bench.train(kind, horizon, seed, demos=demos, stats=stats)
        seconds = time.perf_counter() - start
        out[policy] = measure(bench.planner(kind, model, EULER_STEPS, seed), execute) | {"train_seconds": round(seconds, 1)}
    return out


def averaging(seeds: list[int], episodes: int) -> dict:
    """Run (or resume) the averaging protocol; returns the results file's ``"averaging"`` entry."""
    bench = Bench(episodes)
    done = json.loads(AVERAGING_PARTIAL.read_text()) if AVERAGING_PARTIAL.exists() else {}
    start = time.perf_counter()
    for name in mm.COMMIT_TASKS:
        for seed in seeds:
            key = f"{name}/{seed}"
            if key in done:
                continue
            run_start = time.perf_counter()
            done[key] = averaging_run(bench, name, seed, episodes)
            AVERAGING_PARTIAL.write_text(json.dumps(done, indent=1))
            r = done[key]
            print(f"{name:6s} seed {seed}: expert {r['expert']['success']:.2f}, its chunks {r['expert_chunks']['success']:.2f}"
                  f" | L2 H=k={COMMIT_CHUNK} {r['l2']['success']:.2f} | mixture {r['mixture']['success']:.2f}"
                  f" (left {r['mixture']['left_of_successes']:.2f}) | flow {r['flow']['success']:.2f} (left "
                  f"{r['flow']['left_of_successes']:.2f}) | L2 one step {r['l2_one_step']['success']:.2f} "
                  f"({time.perf_counter() - run_start:.0f} s)", flush=True)
    settings = []
    for name, task in mm.COMMIT_TASKS.items():
        runs = [done[f"{name}/{seed}"] for seed in seeds]
        col = lambda policy, key="success": [r[policy][key] for r in runs]  # noqa: E731
        settings.append({
            "name": name, "swerve_rise": task.swerve_rise,
            "expert": col("expert"), "expert_chunks": col("expert_chunks"),
            "l2": col("l2"), "l2_left": col("l2", "left_of_successes"),
            "mixture": col("mixture"), "mixture_left": col("mixture", "left_of_successes"),
            "flow": col("flow"), "flow_left": col("flow", "left_of_successes"),
            "l2_one_step": col("l2_one_step"), "l2_one_step_left": col("l2_one_step", "left_of_successes"),
            "train_seconds": {p: col(p, "train_seconds") for p in AVERAGING_POLICIES},
        })
    return {
        "command": "python bench/bench_hw1b_multimodal.py --averaging",
        "protocol": {"tasks": {name: {"swerve_rise": t.swerve_rise, "swerve_offset": t.swerve_offset,
                                      "steer_noise": t.steer_noise, "horizon": t.horizon,
                                      "start_window": list(t.start_window)} for name, t in mm.COMMIT_TASKS.items()},
                     "demonstrations": 200, "chunk": COMMIT_CHUNK, "execute": COMMIT_CHUNK, "euler_steps": EULER_STEPS,
                     "reg_steps": REG_STEPS, "mix_steps": MIX_STEPS, "flow_steps": FLOW_STEPS, "seeds": list(seeds),
                     "episodes": episodes, "eval_seeds": "20_000 + 1_000 * seed",
                     "targets": "l2 <= 0.6 x expert, flow >= 0.9, flow_left in [0.3, 0.7], every setting"},
        "settings": settings,
        "wall_seconds_this_call": round(time.perf_counter() - start, 1),
        "meta": meta(),
    }


FOLLOWUP_CELLS = {"flow_12k": (12_000, 200), "flow_12k_1000": (12_000, 1_000)}   # name -> (Adam steps, demos)
FOLLOWUP_PARTIAL = RESULTS.with_suffix(".followup.partial.json")


def commit_demonstrations(name: str, n: int) -> dict:
    """The shipped 200 demonstrations of a commit task, or ``n`` recorded the same way (seed 0) in memory."""
    if n == 200:
        return data.load_npz(f"hw1b/commit_{name}.npz")
    import sys
    sys.path.insert(0, str(REPO / "datasets" / "scripts"))
    from make_multimodal_demos import record_episodes
    sides = np.random.default_rng(0).choice([mm.LEFT, mm.RIGHT], size=n)
    return record_episodes(sides, 0, mm.COMMIT_TASKS[name])


def followup(seeds: list[int], episodes: int) -> dict:
    """Run (or resume) the follow-up: flow matching with a longer budget, on the shipped and on more demonstrations."""
    bench = Bench(episodes)
    done = json.loads(FOLLOWUP_PARTIAL.read_text()) if FOLLOWUP_PARTIAL.exists() else {}
    for name, task in mm.COMMIT_TASKS.items():
        for cell, (steps, n_demos) in FOLLOWUP_CELLS.items():
            demos = commit_demonstrations(name, n_demos)
            stats = mm.obs_statistics(demos["obs"])
            for seed in seeds:
                key = f"{name}/{cell}/{seed}"
                if key in done:
                    continue
                start = time.perf_counter()
                model = bench.train("flow", COMMIT_CHUNK, seed, demos=demos, stats=stats, flow_steps=steps)
                eval_seed = 20_000 + 1_000 * seed
                eps = bench.ns["chunked_rollout"](bench.planner("flow", model, EULER_STEPS, seed),
                                                  mm.ObstacleTracks(episodes, eval_seed, task), COMMIT_CHUNK)
                ok = eps.lengths == task.horizon
                sides = mm.passing_sides(eps.obs, eps.mask)
                done[key] = {"success": float(ok.mean()),
                             "left_of_successes": float(np.mean(sides[ok] == mm.LEFT)) if ok.any() else None,
                             "train_seconds": round(time.perf_counter() - start, 1)}
                FOLLOWUP_PARTIAL.write_text(json.dumps(done, indent=1))
                print(f"{name:6s} {cell:14s} seed {seed}: flow {done[key]['success']:.2f} "
                      f"(left {done[key]['left_of_successes']}) ({done[key]['train_seconds']:.0f} s)", flush=True)
    settings = [{"name": name} | {f"{cell}{suffix}": [done[f"{name}/{cell}/{seed}"][key] for seed in seeds]
                                  for cell in FOLLOWUP_CELLS for suffix, key in (("", "success"),
                                                                                  ("_left", "left_of_successes"))}
                for name in mm.COMMIT_TASKS]
    return {"command": "python bench/bench_hw1b_multimodal.py --followup",
            "question": "is flow matching's gap to the expert on the commit tasks a matter of training or of data?",
            "cells": {cell: {"flow_steps": st, "demonstrations": n} for cell, (st, n) in FOLLOWUP_CELLS.items()},
            "seeds": list(seeds), "episodes": episodes, "settings": settings, "meta": meta()}

def averaging_table(entry: dict) -> str:
    ms = lambda x: f"{np.mean(x):.2f} ± {np.std(x):.2f}"  # noqa: E731
    left = lambda x: np.nanmean([np.nan if v is None else v for v in x])  # noqa: E731 (None: no success)
    lines = ["| swerve | expert | expert's chunks, open loop | L2, H=k=8 | mixture, H=k=8 (left) | flow, H=k=8 (left) "
             "| L2, one step |", "|---|---:|---:|---:|---:|---:|---:|"]
    for s in entry["settings"]:
        lines.append(f"| {s['name']} ({s['swerve_rise']:g}) | {ms(s['expert'])} | {ms(s['expert_chunks'])} | {ms(s['l2'])} | "
                     f"{ms(s['mixture'])} ({left(s['mixture_left']):.2f}) | {ms(s['flow'])} "
                     f"({left(s['flow_left']):.2f}) | {ms(s['l2_one_step'])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=None)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--averaging", action="store_true", help="run only the averaging protocol (see above)")
    parser.add_argument("--followup", action="store_true", help="run only the averaging follow-up (see above)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.followup:
        entry = followup(args.seeds or list(AVERAGING_SEEDS), args.episodes)
        record = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        record["averaging_followup"] = entry
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        FOLLOWUP_PARTIAL.unlink(missing_ok=True)
        for row in entry["settings"]:
            print(row["name"], {cell: f"{np.mean(row[cell]):.2f} ± {np.std(row[cell]):.2f}" for cell in FOLLOWUP_CELLS})
        print(f"wrote the averaging_followup entry of {RESULTS.relative_to(REPO)}")
        return
    if args.averaging:
        entry = averaging(args.seeds or list(AVERAGING_SEEDS), args.episodes)
        record = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        record["averaging"] = entry
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        AVERAGING_PARTIAL.unlink(missing_ok=True)
        print(averaging_table(entry))
        print(f"wrote the averaging entry of {RESULTS.relative_to(REPO)}")
        return
    args.seeds = args.seeds or [0, 1, 2]
    bench = Bench(args.episodes)
    partial = RESULTS.with_suffix(".partial.json")
    per_seed = {}
    start = time.perf_counter()
    for seed in args.seeds:
        bench.cache.clear()
        per_seed[seed] = bench.run_seed(seed)
        partial.write_text(json.dumps({str(s): v for s, v in per_seed.items()}, indent=1))
    names = ["expert", *POLICIES]
    record = {
        "command": "python bench/bench_hw1b_multimodal.py " + " ".join(argv or []),
        "seeds": args.seeds, "episodes": args.episodes, "wall_seconds": round(time.perf_counter() - start, 1),
        "budgets": {"reg_steps": REG_STEPS, "mix_steps": MIX_STEPS, "flow_steps": FLOW_STEPS, "chunk": CHUNK,
                    "execute": EXECUTE, "euler_steps": EULER_STEPS},
        "policies": {name: {key: [per_seed[s][name][key] for s in args.seeds]
                            for key in per_seed[args.seeds[0]][name]} | {"label": LABELS[name]} for name in names},
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(record, indent=1) + "\n")
    partial.unlink(missing_ok=True)
    print(table(per_seed))
    print(f"wrote {RESULTS.relative_to(REPO)} ({record['wall_seconds']:.0f} s)")


if __name__ == "__main__":
    main()
