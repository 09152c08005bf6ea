"""Make hw4_rlhf_dpo's reference ("SFT") policy: a small Hopper policy cloned from a mid-skill checkpoint.

    python datasets/scripts/make_reference_policy.py --teacher experts/Hopper-v5/level_2.pt --seed 0

The teacher (a ``rlcourse.nets.GaussianPolicy`` from the skill ladder) plays ``--episodes`` episodes
*stochastically*, sampling its own Gaussian actions, and a fresh ``GaussianPolicy`` with ``--hidden``
units is fitted to those (observation, sampled action) pairs by maximum likelihood: its mean and its
state-independent standard deviation are both learned, so the clone is a stochastic policy whose
spread matches the teacher's. This is the continuous-control analogue of supervised fine-tuning (SFT)
on demonstrations, and it is the starting point and the KL anchor of every method in hw4.

The clone's deterministic return is measured over 20 seeded episodes and written into the policy's
metadata and the MANIFEST entry; the file is ``datasets/hw4/reference_policy.pt``.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from rlcourse import data
from rlcourse.nets import GaussianPolicy, save_policy
from rlcourse.rollouts import evaluate, rollout
from rlcourse.seeding import seed_everything

ENV_ID = "Hopper-v5"
OUT = data.DATASETS / "hw4" / "reference_policy.pt"


def clone(obs: np.ndarray, act: np.ndarray, hidden: list[int], n_steps: int, batch_size: int, lr: float,
          seed: int) -> GaussianPolicy:
    """A GaussianPolicy fitted to ``(obs, act)`` pairs ``(n, 11)``, ``(n, 3)`` by maximum likelihood."""
    torch.manual_seed(seed)
    policy = GaussianPolicy(obs.shape[1], act.shape[1], hidden=hidden, activation="tanh")
    obs_t, act_t = torch.as_tensor(obs), torch.as_tensor(act)
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, n_steps)
    gen = torch.Generator().manual_seed(seed)
    for _ in range(n_steps):
        idx = torch.randint(len(obs_t), (batch_size,), generator=gen)
        loss = -policy.log_prob(obs_t[idx], act_t[idx]).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    return policy.eval()


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--teacher", default="experts/Hopper-v5/level_2.pt", help="a file under datasets/")
    p.add_argument("--episodes", type=int, default=60, help="stochastic teacher episodes to clone")
    p.add_argument("--hidden", type=int, nargs="+", default=[64, 64])
    p.add_argument("--steps", type=int, default=4000, help="Adam steps of the maximum-likelihood fit")
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-record", action="store_true")
    args = p.parse_args(argv)

    torch.set_num_threads(1)
    seed_everything(args.seed)
    teacher = data.load_policy(args.teacher)
    gen = torch.Generator().manual_seed(args.seed)
    demos = rollout(lambda o: teacher.act(o, deterministic=False, generator=gen), ENV_ID, args.episodes,
                    seed=10_000 + args.seed, progress=False)
    obs, act = demos.flat()
    print(f"teacher {args.teacher}: stochastic return {demos.returns.mean():.1f} ± {demos.returns.std():.1f}, "
          f"{len(obs)} state-action pairs")
    policy = clone(obs, act, args.hidden, args.steps, args.batch_size, args.lr, args.seed)
    mean, std = evaluate(policy.act, ENV_ID, n_episodes=20, seed=1000)
    s_mean, s_std = evaluate(lambda o: policy.act(o, deterministic=False, generator=gen), ENV_ID, 20, seed=1000)
    print(f"clone: deterministic return {mean:.1f} ± {std:.1f}, stochastic {s_mean:.1f} ± {s_std:.1f}, "
          f"std {policy.log_std.exp().detach().numpy().round(3)}")
    meta = dict(env_id=ENV_ID, teacher=args.teacher, return_mean=round(mean, 1), return_std=round(std, 1),
                stochastic_return_mean=round(s_mean, 1), stochastic_return_std=round(s_std, 1),
                eval_episodes=20, eval_seed=1000, demo_pairs=int(len(obs)))
    save_policy(policy, OUT, **meta)
    if not args.no_record:
        data.record(OUT, __file__, argv, seed=args.seed, info=meta)
    print(f"wrote {OUT.relative_to(data.DATASETS.parent)}")


if __name__ == "__main__":
    main()
