"""Train a MuJoCo expert with Stable-Baselines3 SAC, resumably, and export it.

Instructor-only (needs the ``experts`` extra). The trainer state (model and
replay buffer) lives in a cache folder outside the repository and is saved
every ``--checkpoint-every`` steps, so a run that is cut off resumes where it
stopped when started again with the same arguments. At every checkpoint the
actor is exported to the ``rlcourse`` policy format under
``datasets/experts/<env>/`` (a few hundred kB), with its measured return:
these snapshots of increasing skill feed the preference data sets later.

    python datasets/scripts/train_expert.py --env Hopper-v5 --steps 1000000
"""
from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

import torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback

from rlcourse.nets import GaussianPolicy, save_policy
from rlcourse.rollouts import evaluate

REPO = Path(__file__).resolve().parents[2]
CACHE = Path(os.environ.get("RLCOURSE_TRAIN_DIR", Path.home() / ".cache" / "rlcourse" / "train"))


def export_actor(model: SAC) -> GaussianPolicy:
    """Copy SAC's actor mean into a ``GaussianPolicy(hidden=(256, 256), squash=True)``."""
    actor = model.actor
    obs_dim = model.observation_space.shape[0]
    act_dim = model.action_space.shape[0]
    assert (model.action_space.low == -1).all() and (model.action_space.high == 1).all(), "expects actions in [-1, 1]"
    policy = GaussianPolicy(obs_dim, act_dim, hidden=(256, 256), activation="relu", squash=True, log_std_init=-1.0)
    policy.body[0].load_state_dict(actor.latent_pi[0].state_dict())
    policy.body[2].load_state_dict(actor.latent_pi[2].state_dict())
    policy.mean.load_state_dict(actor.mu.state_dict())
    return policy.eval()


class Checkpoint(BaseCallback):
    """Every ``every`` steps: save trainer state atomically, export and evaluate the actor, log a CSV row."""

    def __init__(self, env_id: str, every: int, state_dir: Path, export_dir: Path, eval_episodes: int, t0: float):
        super().__init__()
        self.env_id, self.every, self.state_dir, self.export_dir = env_id, every, state_dir, export_dir
        self.eval_episodes, self.t0 = eval_episodes, t0

    def _on_step(self) -> bool:
        if self.num_timesteps % self.every == 0:
            save_state(self.model, self.state_dir)
            policy = export_actor(self.model)
            mean, std = evaluate(policy.act, self.env_id, self.eval_episodes, seed=10_000)
            hours = (time.time() - self.t0) / 3600
            save_policy(policy, self.export_dir / f"ckpt_{self.num_timesteps:07d}.pt", env_id=self.env_id,
                        steps=self.num_timesteps, eval_return=mean, eval_return_std=std,
                        eval_episodes=self.eval_episodes)
            log = self.state_dir / "progress.csv"
            new = not log.exists()
            with log.open("a", newline="") as f:
                w = csv.writer(f)
                if new:
                    w.writerow(["steps", "eval_return", "eval_std", "session_hours"])
                w.writerow([self.num_timesteps, f"{mean:.1f}", f"{std:.1f}", f"{hours:.3f}"])
            print(f"[{self.env_id}] {self.num_timesteps} steps: return {mean:.0f} ± {std:.0f}", flush=True)
        return True


def save_state(model: SAC, state_dir: Path) -> None:
    """Write model and replay buffer, then rename both into place (a kill never leaves half a checkpoint)."""
    model.save(state_dir / "model.tmp.zip")
    model.save_replay_buffer(state_dir / "buffer.tmp.pkl")
    (state_dir / "model.tmp.zip").replace(state_dir / "model.zip")
    (state_dir / "buffer.tmp.pkl").replace(state_dir / "buffer.pkl")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", required=True, help="gymnasium id, e.g. Hopper-v5")
    parser.add_argument("--steps", type=int, default=1_000_000, help="total environment steps")
    parser.add_argument("--checkpoint-every", type=int, default=25_000)
    parser.add_argument("--eval-episodes", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (two runs side by side: 1 each)")
    args = parser.parse_args()

    torch.set_num_threads(args.threads)
    state_dir = CACHE / args.env
    state_dir.mkdir(parents=True, exist_ok=True)
    export_dir = REPO / "datasets" / "experts" / args.env
    if (state_dir / "model.zip").exists():
        model = SAC.load(state_dir / "model.zip", device="cpu")
        from stable_baselines3.common.env_util import make_vec_env

        model.set_env(make_vec_env(args.env, n_envs=1, seed=args.seed + model.num_timesteps))
        model.load_replay_buffer(state_dir / "buffer.pkl")
        print(f"resuming {args.env} at {model.num_timesteps} steps", flush=True)
    else:
        model = SAC("MlpPolicy", args.env, seed=args.seed, device="cpu", verbose=0,
                    learning_starts=10_000, policy_kwargs=dict(net_arch=[256, 256]))
    remaining = args.steps - model.num_timesteps
    if remaining > 0:
        model.learn(remaining, reset_num_timesteps=False,
                    callback=Checkpoint(args.env, args.checkpoint_every, state_dir, export_dir,
                                        args.eval_episodes, time.time()))
    print(f"{args.env}: done at {model.num_timesteps} steps", flush=True)


if __name__ == "__main__":
    main()
