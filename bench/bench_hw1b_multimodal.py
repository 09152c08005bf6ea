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
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from autograder.grader import build_reference
from rlcourse import data
from rlcourse import multimodal as mm

REPO = Path(__file__).resolve().parents[1]
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

    def train(self, kind: str, horizon: int, seed: int):
        key = (kind, horizon, seed)
        if key in self.cache:
            return self.cache[key], 0.0
        obs, chunks = self.chunks(horizon)
        torch.manual_seed(seed)
        start = time.perf_counter()
        if kind == "l2":
            model = mm.ChunkRegressor(horizon=horizon, **self.stats)
            mm.fit(model, lambda i, g: ((model(obs[i]) - chunks[i]) ** 2).sum(dim=(1, 2)).mean(), len(obs), REG_STEPS,
                   seed=seed)
        elif kind == "mixture":
            model = mm.MixtureNet(horizon=horizon, **self.stats)
            nll = self.ns["mixture_nll"]
            mm.fit(model, lambda i, g: nll(*model(obs[i]), chunks[i].reshape(len(i), -1)), len(obs), MIX_STEPS, seed=seed)
        else:
            model = mm.VelocityNet(horizon=horizon, **self.stats)
            fm = self.ns["flow_matching_loss"]

            def loss(i, g):
                return fm(model, obs[i], chunks[i], torch.randn(chunks[i].shape, generator=g),
                          torch.rand(len(i), generator=g))

            mm.fit(model, loss, len(obs), FLOW_STEPS, lr=2e-3, seed=seed)
        self.cache[key] = model.eval()
        return self.cache[key], time.perf_counter() - start

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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
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
