"""Benchmark of hw1_imitation: behaviour cloning and DAgger against the expert, and notebook run times.

Prints the Markdown tables that the README shows:

    python bench/bench_hw1_imitation.py                  # everything (about 15 minutes on 2 shared cores)
    python bench/bench_hw1_imitation.py --skip-notebook  # without timing the notebook runs
    python bench/bench_hw1_imitation.py --expert HalfCheetah-v5=experts/HalfCheetah-v5/sac/ckpt_0125000.pt

Every number comes from the reference solutions in ``solutions/hw1_imitation`` (run through the
grader's own ``build_reference``) on the shipped experts and demonstrations, with the notebook's
full budgets: learners are two-layer tanh networks with input standardisation, ``BC_STEPS``
gradient steps of Adam per clone, evaluation on ``EPISODES`` episodes seeded from 1000 (the
expert is measured on the same episodes), and 3 training seeds. Returns are reported as a
fraction of the expert's return, mean ± standard deviation over the seeds.
"""
from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from autograder.grader import build_reference
from rlcourse import data, racetrack
from rlcourse.imitation import Demonstrations, NormalisedPolicy
from rlcourse.nets import GaussianPolicy, load_policy
from rlcourse.rollouts import rollout

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK = REPO / "solutions" / "hw1_imitation" / "hw1_imitation.ipynb"
ENVS = ("Hopper-v5", "HalfCheetah-v5")
SEEDS = (0, 1, 2)
N_DEMOS = (1, 5, 25)
BC_STEPS, HIDDEN, BATCH, LR = 5000, (64, 64), 256, 1e-3      # as in the notebook's full budget
DAGGER_ITERS, DAGGER_EPISODES, DAGGER_EPOCHS = 10, 2, 4
RACE_ITERS, RACE_TRAIN = 6, dict(batch_size=64, lr=3e-3)
EVAL_SEED = 1000


def frac(values, reference: float) -> str:
    x = np.asarray(values, dtype=float) / reference
    return f"{x.mean():.2f} ± {x.std():.2f}"


class Bench:
    def __init__(self, experts: dict[str, str], episodes: int) -> None:
        self.ns = build_reference("hw1_imitation")  # the solution notebook's setup and stub cells
        self.episodes = episodes
        self.experts = {env: data.load_policy(f) if f in data.read_manifest() else load_policy(data.DATASETS / f)
                        for env, f in experts.items()}
        self.expert_files = experts
        self.demos = {env: Demonstrations.load(f"demos/{env}.npz") for env in experts}

    def returns(self, policy, env: str, n: int | None = None) -> np.ndarray:
        return rollout(policy.act, env, n or self.episodes, EVAL_SEED).returns

    def clone(self, demos: Demonstrations, seed: int) -> NormalisedPolicy:
        torch.manual_seed(seed)
        policy = NormalisedPolicy.for_data(demos.obs, demos.actions.shape[1], hidden=HIDDEN)
        n_epochs = int(np.ceil(BC_STEPS * BATCH / (0.9 * len(demos.obs))))
        self.ns["train_bc"](policy, demos.obs, demos.actions, n_epochs=n_epochs, batch_size=BATCH, lr=LR, seed=seed)
        return policy

    def mujoco(self) -> None:
        print("| environment | expert (file) | expert return | demos (return) |")
        print("|---|---|---|---|")
        expert_return = {}
        for env, expert in self.experts.items():
            expert_return[env] = float(self.returns(expert, env).mean())
            d = self.demos[env]
            print(f"| {env} | `{self.expert_files[env]}` | {expert_return[env]:.0f} | "
                  f"{d.n_episodes} × {d.lengths.mean():.0f} steps ({d.returns.mean():.0f} ± {d.returns.std():.0f}) |")
        print()
        rows = []
        for env in self.experts:
            bc1 = {}
            for k in N_DEMOS:
                t = time.time()
                runs = []
                for seed in SEEDS:
                    policy = self.clone(self.demos[env].first(k), seed)
                    if k == 1:
                        bc1[seed] = policy
                    runs.append(self.returns(policy, env).mean())
                rows.append((env, f"BC, {k} demo{'s' * (k > 1)}", int(self.demos[env].lengths[:k].sum()),
                             frac(runs, expert_return[env]), time.time() - t))
            t = time.time()
            finals, curves, labels = [], [], []
            for seed in SEEDS:
                first = self.demos[env].first(1)
                learner, hist = self.ns["dagger"](env, self.experts[env], copy.deepcopy(bc1[seed]), DAGGER_ITERS,
                                                  [0.0] * DAGGER_ITERS, first.obs, first.actions,
                                                  episodes_per_iter=DAGGER_EPISODES, seed=seed,
                                                  n_epochs=DAGGER_EPOCHS, batch_size=BATCH, lr=LR)
                finals.append(self.returns(learner, env).mean())
                curves.append(np.r_[hist["returns"][1:], finals[-1]] / expert_return[env])  # after iteration 1..N
                labels.append(hist["dataset_sizes"][-1])
            curve = np.mean(curves, axis=0)
            reached = np.flatnonzero(curve >= 0.9)
            rows.append((env, f"DAgger, 1 demo + {DAGGER_ITERS} iterations", int(np.mean(labels)),
                         frac(finals, expert_return[env]), time.time() - t))
            print(f"{env}: DAgger mean fraction of expert after iterations 1..{DAGGER_ITERS}: "
                  + " ".join(f"{c:.2f}" for c in curve)
                  + f"; first reaches 90% after iteration {reached[0] + 1 if len(reached) else 'never'}")
        print()
        print("| environment | learner | expert labels | return / expert (3 seeds) | wall time |")
        print("|---|---|---|---|---|")
        for env, name, n, f, sec in rows:
            print(f"| {env} | {name} | {n} | {f} | {sec:.0f} s |")
        print()

    def race_clone(self, demos: Demonstrations, seed: int) -> GaussianPolicy:
        torch.manual_seed(seed)
        policy = GaussianPolicy(racetrack.OBS_DIM, racetrack.ACT_DIM, hidden=(64, 64))
        n_epochs = max(20, int(np.ceil(500 * 64 / len(demos.obs))))
        self.ns["train_bc"](policy, demos.obs, demos.actions, n_epochs=n_epochs, seed=seed, **RACE_TRAIN)
        return policy

    def race(self) -> None:
        """As in the notebook: DAgger one iteration at a time from a one-demonstration clone."""
        expert = racetrack.Expert()
        expert_return = float(self.returns(expert, racetrack.ENV_ID, 10).mean())
        demos = Demonstrations.from_episodes(rollout(expert.act, racetrack.ENV_ID, 16, seed=100))
        first = demos.first(1)
        rows = {name: [] for name in ("bc1", "dagger", "first_ok", "bc_matched", "bc16")}
        for seed in SEEDS:
            learner = self.race_clone(first, seed)
            rows["bc1"].append(self.returns(learner, racetrack.ENV_ID, 10).mean())
            obs, actions, ok_at = first.obs, first.actions, None
            for i in range(RACE_ITERS):
                if ok_at is None and self.returns(learner, racetrack.ENV_ID, 10).mean() >= 0.9 * expert_return:
                    ok_at = len(obs)
                learner, hist = self.ns["dagger"](racetrack.ENV_ID, expert, learner, 1, [0.0], obs, actions,
                                                  episodes_per_iter=4, seed=seed + 4 * i, n_epochs=50, **RACE_TRAIN)
                obs, actions = hist["obs"], hist["actions"]
            final = self.returns(learner, racetrack.ENV_ID, 10).mean()
            ok_at = ok_at or (len(obs) if final >= 0.9 * expert_return else None)
            rows["dagger"].append(final)
            rows["first_ok"].append(ok_at or np.nan)
            n_demos = int(np.ceil((ok_at or len(obs)) / len(first.obs)))
            rows["bc_matched"].append(self.returns(self.race_clone(demos.first(min(n_demos, 16)), seed),
                                                   racetrack.ENV_ID, 10).mean())
            rows["bc16"].append(self.returns(self.race_clone(demos, seed), racetrack.ENV_ID, 10).mean())
        print(f"Race track (expert return {expert_return:.0f} over 10 episodes of {racetrack.HORIZON} steps; "
              f"DAgger: {RACE_ITERS} iterations of 4 episodes; labels when DAgger first drove like the expert "
              f"(>= 90%): {rows['first_ok']}):")
        print()
        print("| learner | expert labels | return / expert (3 seeds) |")
        print("|---|---|---|")
        print(f"| BC, 1 demo | {len(first.obs)} | {frac(rows['bc1'], expert_return)} |")
        print(f"| BC, as many labels as DAgger needed | {np.nanmean(rows['first_ok']):.0f} (rounded up to whole demos) | "
              f"{frac(rows['bc_matched'], expert_return)} |")
        print(f"| BC, 16 demos | {len(demos.obs)} | {frac(rows['bc16'], expert_return)} |")
        print(f"| DAgger, 1 demo + {RACE_ITERS} iterations | {len(obs)} (seed {SEEDS[-1]}) | "
              f"{frac(rows['dagger'], expert_return)} |")
        print()


def time_notebook(fast: bool) -> tuple[float, str]:
    start = time.time()
    proc = subprocess.run([sys.executable, "-m", "autograder", "run", str(NOTEBOOK), "-p", f"FAST={fast}",
                           "--timeout", "1200"], capture_output=True, text=True, cwd=REPO)
    status = "ok" if proc.returncode == 0 else "FAILED: " + (proc.stdout + proc.stderr).strip().splitlines()[-1]
    return time.time() - start, status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--skip-notebook", action="store_true", help="do not time the notebook runs")
    parser.add_argument("--skip-learners", action="store_true", help="only time the notebook runs")
    parser.add_argument("--episodes", type=int, default=5, help="evaluation episodes per learner (the notebook's 5)")
    parser.add_argument("--expert", nargs="*", default=[], metavar="ENV=FILE",
                        help="use another expert file (relative to datasets/) for an environment")
    args = parser.parse_args()
    torch.set_num_threads(1)
    experts = {env: f"experts/{env}/expert.pt" for env in ENVS}
    experts.update(dict(item.split("=", 1) for item in args.expert))
    if not args.skip_learners:
        bench = Bench(experts, args.episodes)
        bench.mujoco()
        bench.race()
    if not args.skip_notebook:
        print("| notebook run | wall time | status |")
        print("|---|---|---|")
        for fast in (True, False):
            seconds, status = time_notebook(fast)
            print(f"| `FAST = {fast}` | {seconds:.0f} s | {status} |", flush=True)


if __name__ == "__main__":
    main()
