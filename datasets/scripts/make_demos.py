"""Record expert demonstrations for hw1 as ``datasets/demos/<env>.npz`` and list them in the MANIFEST.

The expert acts with its deterministic mean action (the same labels DAgger
asks it for later). Episodes are seeded ``seed, seed + 1, ...`` and stored flat
(every step of every episode, one after the other) with their lengths as
boundaries; :class:`rlcourse.imitation.Demonstrations` loads them.

    python datasets/scripts/make_demos.py --env Hopper-v5 --expert experts/Hopper-v5/expert.pt
    python datasets/scripts/make_demos.py --env HalfCheetah-v5 --expert experts/HalfCheetah-v5/expert.pt

Arrays: ``obs`` ``(N, obs_dim)``, ``actions`` ``(N, act_dim)``, ``rewards`` ``(N,)`` (float32);
``lengths`` ``(n_episodes,)`` int64 with ``N = lengths.sum()``; ``terminated`` ``(n_episodes,)`` bool.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rlcourse import data
from rlcourse.imitation import Demonstrations
from rlcourse.nets import load_policy
from rlcourse.rollouts import rollout


def record(env_id: str, expert_file: str, n_episodes: int, seed: int) -> Demonstrations:
    """``n_episodes`` seeded episodes of the expert in ``expert_file`` (see ``--expert``)."""
    if expert_file in data.read_manifest():
        expert = data.load_policy(expert_file)  # checksum verified
    else:  # an unlisted training snapshot, while the final expert is not there yet
        path = data.DATASETS / expert_file
        expert = load_policy(path if path.exists() else Path(expert_file))
    return Demonstrations.from_episodes(rollout(expert.act, env_id, n_episodes, seed, progress=False))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", required=True, help="gymnasium id, e.g. Hopper-v5")
    parser.add_argument("--expert", required=True,
                        help="the expert policy file, relative to datasets/ (checked against the MANIFEST) or a path")
    parser.add_argument("--episodes", type=int, default=25)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    demos = record(args.env, args.expert, args.episodes, args.seed)
    target = data.DATASETS / "demos" / f"{args.env}.npz"
    target.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(target, obs=demos.obs.astype(np.float32), actions=demos.actions.astype(np.float32),
                        rewards=demos.rewards.astype(np.float32), lengths=demos.lengths.astype(np.int64),
                        terminated=demos.terminated.astype(bool))
    returns = demos.returns
    info = {"env": args.env, "expert": args.expert, "episodes": args.episodes, "steps": int(demos.lengths.sum()),
            "return_mean": round(float(returns.mean()), 1), "return_std": round(float(returns.std()), 1),
            "terminated": int(demos.terminated.sum())}
    expert_entry = data.read_manifest().get(args.expert)
    if expert_entry is not None:
        info["expert_sha256"] = expert_entry["sha256"]
    data.record(target, __file__, argv, seed=args.seed, info=info)
    print(f"{target.relative_to(data.DATASETS.parent)}: {args.episodes} episodes, {info['steps']} steps, "
          f"return {info['return_mean']:.0f} ± {info['return_std']:.0f}, {target.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
