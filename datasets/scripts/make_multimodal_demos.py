"""Record the obstacle track's two-sided demonstrations for hw1b as ``datasets/hw1b/demos.npz``.

Each episode's demonstrator passes the obstacle on a side drawn by a fair coin
(``numpy.random.default_rng(seed)``), which the observations do not show; the
episodes themselves are :class:`rlcourse.multimodal.ObstacleTracks` seeded
``seed, seed + 1, ...``. The file is listed in the MANIFEST with this command.

    python datasets/scripts/make_multimodal_demos.py --episodes 100 --seed 0

``--task sharp|medium|gentle`` records the same kind of file for one of the versions of the track where the
demonstrators split at the first step (``rlcourse.multimodal.COMMIT_TASKS``), as
``datasets/hw1b/commit_<task>.npz``:

    python datasets/scripts/make_multimodal_demos.py --task sharp --episodes 200 --seed 0

Arrays: ``obs`` ``(N, 5)``, ``actions`` ``(N, 1)``, ``rewards`` ``(N,)`` (float32), stored episode after
episode; ``lengths`` ``(n_episodes,)`` int64 with ``N = lengths.sum()``; ``terminated`` ``(n_episodes,)``
bool; ``sides`` ``(n_episodes,)`` int64, +1 for the left (inside) and -1 for the right.
"""
from __future__ import annotations

import argparse

import numpy as np

from rlcourse import data, multimodal


def record_episodes(sides: np.ndarray, seed: int, task: multimodal.ObstacleTask = multimodal.CLOSED_LOOP
                    ) -> dict[str, np.ndarray]:
    """The expert's episodes on ``task``, one per entry of ``sides``, stored flat."""
    env = multimodal.ObstacleTracks(len(sides), seed, task)
    expert = multimodal.ObstacleExpert(sides, task=task)
    obs, steps = env.reset(), []
    running = np.ones(len(sides), dtype=bool)
    while running.any():
        actions = expert.act(obs)
        next_obs, rewards, _, _ = env.step(actions)
        steps.append((obs, actions, rewards, running.copy()))
        running = ~env.done
        obs = next_obs
    o, a, r, m = (np.stack(x, axis=1) for x in zip(*steps))
    return {"obs": o[m].astype(np.float32), "actions": a[m].astype(np.float32), "rewards": r[m].astype(np.float32),
            "lengths": m.sum(axis=1).astype(np.int64), "terminated": env.terminated.copy(),
            "sides": np.asarray(sides, dtype=np.int64)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--task", choices=sorted(multimodal.COMMIT_TASKS), default=None,
                        help="a version where the demonstrators split at the first step (default: the main task)")
    args = parser.parse_args(argv)
    task = multimodal.COMMIT_TASKS[args.task] if args.task else multimodal.CLOSED_LOOP
    sides = np.random.default_rng(args.seed).choice([multimodal.LEFT, multimodal.RIGHT], size=args.episodes)
    arrays = record_episodes(sides, args.seed, task)
    target = data.DATASETS / "hw1b" / (f"commit_{args.task}.npz" if args.task else "demos.npz")
    target.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(target, **arrays)
    info = {"episodes": args.episodes, "steps": int(arrays["lengths"].sum()),
            "left_fraction": round(float(np.mean(sides == multimodal.LEFT)), 3),
            "success": round(float(np.mean(arrays["lengths"] == task.horizon)), 3),
            "terminated": int(arrays["terminated"].sum())}
    data.record(target, __file__, argv, seed=args.seed, info=info)
    print(f"{target.relative_to(data.DATASETS.parent)}: {args.episodes} episodes, {info['steps']} steps, "
          f"left {info['left_fraction']:.2f}, success {info['success']:.2f}, {target.stat().st_size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
