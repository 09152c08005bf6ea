"""Train a MuJoCo expert with Stable-Baselines3 (SAC or PPO), resumably, and export it.

Instructor-only (needs the ``experts`` extra). The trainer state (model, and
SAC's replay buffer or PPO's observation normaliser) lives in a cache folder
outside the repository and is saved every ``--checkpoint-every`` steps, so a
run that is cut off resumes where it stopped when started again with the same
arguments. At every checkpoint the actor is exported to the ``rlcourse``
policy format under ``datasets/experts/<env>/`` (a few hundred kB), with its
measured return and the command of the session that wrote it: these snapshots
of increasing skill feed the preference data sets later.

SAC is sample-efficient but slow per step here (about 100 steps/s on a core);
PPO with vectorised environments runs about 30 times more steps per second,
so on this machine PPO reaches a given return sooner in wall-clock time for
Hopper and Walker2d, while SAC wins on HalfCheetah.

    python datasets/scripts/train_expert.py --env HalfCheetah-v5 --algo sac --steps 1000000
    python datasets/scripts/train_expert.py --env Hopper-v5 --algo ppo --steps 10000000 --n-envs 8
"""
from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

from rlcourse.data import script_command
from rlcourse.nets import GaussianPolicy, save_policy
from rlcourse.rollouts import evaluate

REPO = Path(__file__).resolve().parents[2]
CACHE = Path(os.environ.get("RLCOURSE_TRAIN_DIR", Path.home() / ".cache" / "rlcourse" / "train"))


def export_actor(model: SAC | PPO) -> GaussianPolicy:
    """The trained actor's mean as a plain ``GaussianPolicy``.

    SAC: ``tanh`` of its mean head (``squash=True``). PPO: the unsquashed Gaussian mean (MuJoCo clips
    controls to [-1, 1]), with the observation normaliser folded into the first layer:
    ``W (o - m) / s + b = (W / s) o + (b - W m / s)``.
    """
    obs_dim = model.observation_space.shape[0]
    act_dim = model.action_space.shape[0]
    assert (model.action_space.low == -1).all() and (model.action_space.high == 1).all(), "expects actions in [-1, 1]"
    if isinstance(model, SAC):
        layers, head, squash, log_std = model.actor.latent_pi, model.actor.mu, True, -1.0
        activation = "relu"
    else:
        layers, head, squash = model.policy.mlp_extractor.policy_net, model.policy.action_net, False
        log_std, activation = float(model.policy.log_std.detach().mean()), "tanh"
    linears = [m for m in layers if isinstance(m, torch.nn.Linear)]
    policy = GaussianPolicy(obs_dim, act_dim, hidden=[m.out_features for m in linears], activation=activation,
                            squash=squash, log_std_init=log_std)
    body_linears = [m for m in policy.body if isinstance(m, torch.nn.Linear)]
    for mine, theirs in zip(body_linears, linears):
        mine.load_state_dict(theirs.state_dict())
    policy.mean.load_state_dict(head.state_dict())
    if isinstance(model, PPO):
        policy.log_std.data.copy_(model.policy.log_std.detach())
        norm = model.get_vec_normalize_env()
        if norm is not None:
            mean = torch.as_tensor(norm.obs_rms.mean, dtype=torch.float32)
            scale = torch.as_tensor(np.sqrt(norm.obs_rms.var + norm.epsilon), dtype=torch.float32)
            first = body_linears[0]
            with torch.no_grad():
                first.weight.div_(scale)
                first.bias.sub_(first.weight @ mean)
    return policy.eval()


class Checkpoint(BaseCallback):
    """Every ``every`` steps: save trainer state atomically, export and evaluate the actor, log a CSV row."""

    def __init__(self, env_id: str, every: int, state_dir: Path, export_dir: Path, eval_episodes: int, t0: float,
                 command: str):
        super().__init__()
        self.env_id, self.every, self.state_dir, self.export_dir = env_id, every, state_dir, export_dir
        self.eval_episodes, self.t0, self.command = eval_episodes, t0, command
        self.last = None

    def _on_step(self) -> bool:
        if self.last is None:
            self.last = self.num_timesteps // self.every
        if self.num_timesteps // self.every > self.last:  # crossed a multiple of `every` (vector envs step by n)
            self.last = self.num_timesteps // self.every
            save_state(self.model, self.state_dir)
            policy = export_actor(self.model)
            mean, std = evaluate(policy.act, self.env_id, self.eval_episodes, seed=10_000)
            hours = (time.time() - self.t0) / 3600
            save_policy(policy, self.export_dir / f"ckpt_{self.num_timesteps:07d}.pt", env_id=self.env_id,
                        steps=self.num_timesteps, eval_return=mean, eval_return_std=std,
                        eval_episodes=self.eval_episodes, command=self.command)
            log = self.state_dir / "progress.csv"
            new = not log.exists()
            with log.open("a", newline="") as f:
                w = csv.writer(f)
                if new:
                    w.writerow(["steps", "eval_return", "eval_std", "session_hours"])
                w.writerow([self.num_timesteps, f"{mean:.1f}", f"{std:.1f}", f"{hours:.3f}"])
            print(f"[{self.env_id}] {self.num_timesteps} steps: return {mean:.0f} ± {std:.0f}", flush=True)
        return True


def save_state(model: SAC | PPO, state_dir: Path) -> None:
    """Write the model and its companion (SAC: replay buffer; PPO: normaliser), then rename into place."""
    model.save(state_dir / "model.tmp.zip")
    if isinstance(model, SAC):
        model.save_replay_buffer(state_dir / "buffer.tmp.pkl")
        (state_dir / "buffer.tmp.pkl").replace(state_dir / "buffer.pkl")
    else:
        model.get_vec_normalize_env().save(str(state_dir / "vecnormalize.tmp.pkl"))
        (state_dir / "vecnormalize.tmp.pkl").replace(state_dir / "vecnormalize.pkl")
    (state_dir / "model.tmp.zip").replace(state_dir / "model.zip")


def load_or_create(args: argparse.Namespace, state_dir: Path) -> SAC | PPO:
    """Resume from ``state_dir`` when it holds a checkpoint, else start a new run."""
    resume = (state_dir / "model.zip").exists()
    if args.algo == "sac":
        env = make_vec_env(args.env, n_envs=1, seed=args.seed)
        if resume:
            model = SAC.load(state_dir / "model.zip", env=env, device="cpu")
            model.load_replay_buffer(state_dir / "buffer.pkl")
        else:
            model = SAC("MlpPolicy", env, seed=args.seed, device="cpu", learning_starts=10_000,
                        policy_kwargs=dict(net_arch=[256, 256]))
    else:
        venv = make_vec_env(args.env, n_envs=args.n_envs, seed=args.seed,
                            vec_env_cls=SubprocVecEnv if args.subproc else None)
        if resume:
            venv = VecNormalize.load(str(state_dir / "vecnormalize.pkl"), venv)
            model = PPO.load(state_dir / "model.zip", env=venv, device="cpu")
        else:
            venv = VecNormalize(venv, gamma=0.99)
            model = PPO("MlpPolicy", venv, seed=args.seed, device="cpu", n_steps=512, batch_size=512, n_epochs=10,
                        learning_rate=3e-4, gamma=0.99, gae_lambda=0.95, clip_range=0.2, max_grad_norm=0.5,
                        policy_kwargs=dict(net_arch=dict(pi=[256, 256], vf=[256, 256]), log_std_init=-0.5))
    if resume:
        print(f"resuming {args.env} ({args.algo}) at {model.num_timesteps} steps", flush=True)
    return model


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", required=True, help="gymnasium id, e.g. Hopper-v5")
    parser.add_argument("--steps", type=int, default=1_000_000, help="total environment steps")
    parser.add_argument("--checkpoint-every", type=int, default=25_000)
    parser.add_argument("--eval-episodes", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--algo", choices=["sac", "ppo"], default="sac")
    parser.add_argument("--n-envs", type=int, default=8, help="PPO: environments per rollout")
    parser.add_argument("--subproc", action="store_true", help="PPO: step the environments in parallel processes "
                        "(faster on many cores; slower than in-process stepping on two)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (two runs side by side: 1 each)")
    args = parser.parse_args(argv)

    torch.set_num_threads(args.threads)
    run = args.algo if args.seed == 0 else f"{args.algo}-seed{args.seed}"
    state_dir = CACHE / f"{args.env}-{run}"
    state_dir.mkdir(parents=True, exist_ok=True)
    export_dir = REPO / "datasets" / "experts" / args.env / run
    model = load_or_create(args, state_dir)
    remaining = args.steps - model.num_timesteps
    if remaining > 0:
        model.learn(remaining, reset_num_timesteps=False,
                    callback=Checkpoint(args.env, args.checkpoint_every, state_dir, export_dir,
                                        args.eval_episodes, time.time(), script_command(__file__, argv)))
    print(f"{args.env}: done at {model.num_timesteps} steps", flush=True)


if __name__ == "__main__":
    main()
