"""Choose which training snapshots ship: the expert, and a ladder of skill levels.

Training (``train_expert.py``) exports a snapshot every checkpoint under
``datasets/experts/<env>/<run>/`` (not committed). This script measures the
chosen snapshots over 20 seeded episodes and writes them as
``datasets/experts/<env>/expert.pt`` and ``level_<k>.pt`` (weakest first), with
their measured returns in the MANIFEST. The levels feed the preference data of
later assignments, so they should spread from poor to expert.

Every file of one environment is recorded with this script's own command (it
writes them all, and deletes the old levels first); the training command that
made a snapshot, which ``train_expert.py`` keeps in the snapshot's metadata, is
recorded beside it as ``info["training_command"]``.

    python datasets/scripts/select_experts.py --env Hopper-v5 --run ppo --expert 1250000 \
        --levels sac:50000 ppo:250000 ppo:500000 ppo-seed1:500000 --note "how it was trained"
"""
from __future__ import annotations

import argparse

from rlcourse import data
from rlcourse.nets import load_policy, save_policy
from rlcourse.rollouts import evaluate

EXPERTS = data.DATASETS / "experts"
EVAL_SEED, EVAL_EPISODES = 1000, 20
TARGETS = {"Hopper-v5": 3000, "HalfCheetah-v5": 6000, "Walker2d-v5": 3500}


def ship(env: str, run: str, steps: int, name: str, note: str, argv: list[str] | None) -> dict:
    """Evaluate snapshot ``steps`` of ``run`` and write it as ``<env>/<name>.pt`` with a MANIFEST entry
    (``argv``: the arguments this script was run with, recorded as its command)."""
    source = EXPERTS / env / run / f"ckpt_{steps:07d}.pt"
    if not source.exists():
        raise SystemExit(f"{source} does not exist: train further or pick one of "
                         + ", ".join(p.stem for p in sorted(source.parent.glob('ckpt_*.pt'))))
    policy = load_policy(source)
    mean, std = evaluate(policy.act, env, EVAL_EPISODES, seed=EVAL_SEED)
    target = EXPERTS / env / f"{name}.pt"
    save_policy(policy, target, env_id=env, run=run, steps=steps, return_mean=mean, return_std=std,
                eval_episodes=EVAL_EPISODES, eval_seed=EVAL_SEED)
    algo = run.split("-")[0]
    seed = int(run.split("seed")[1]) if "seed" in run else 0
    info = {"env": env, "algo": algo, "training_steps": steps, "return_mean": round(mean, 1),
            "return_std": round(std, 1), "eval_episodes": EVAL_EPISODES, "eval_seed": EVAL_SEED, "note": note}
    if name == "expert":
        info["return_target"] = TARGETS.get(env)
    if "command" in policy.metadata:
        info["training_command"] = policy.metadata["command"]
    data.record(target, __file__, argv, seed=seed, info=info)
    print(f"{env} {name}: {run} at {steps} steps, return {mean:.0f} ± {std:.0f} over {EVAL_EPISODES} episodes")
    return info


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", required=True)
    parser.add_argument("--run", required=True, help="training run folder, e.g. ppo, sac, ppo-seed1")
    parser.add_argument("--expert", type=int, required=True, help="training steps of the expert snapshot")
    parser.add_argument("--levels", nargs="*", default=[], metavar="RUN:STEPS",
                        help="lower levels as run:steps (any run of this environment), weakest first")
    parser.add_argument("--note", default="", help="how and where it was trained (recorded in the MANIFEST)")
    args = parser.parse_args(argv)
    for old in (EXPERTS / args.env).glob("level_*.pt"):
        old.unlink()
        data.remove(old.relative_to(data.DATASETS).as_posix())
    for i, level in enumerate(args.levels):
        run, steps = level.split(":")
        ship(args.env, run, int(steps), f"level_{i}", args.note, argv)
    ship(args.env, args.run, args.expert, "expert", args.note, argv)


if __name__ == "__main__":
    main()
