"""Extend the Hopper preference set with segments that contain a fall (hw3_preferences, hw4_rlhf_dpo).

    python datasets/scripts/make_hopper_falls.py --seed 1          # about 1 minute on one core

Why: every segment of ``hopper_prefs/hopper_prefs.npz`` shows a robot still upright, so comparisons of
its equal-length segments cannot identify a per-step constant in the reward, and the constant is what
decides whether a learned reward pays for staying alive (lecture 6, "The constant the comparisons
cannot see"). A segment that contains the fall can: after the fall the episode is over, which we
write as an *absorbing state* that pays nothing for the rest of the segment's 25 steps.

The new file holds every segment and pair of the upright set (unchanged, first) followed by the new
segments and pairs. New segments come from the shipped Hopper snapshots
(``datasets/experts/Hopper-v5/level_*.pt``, which fall within 1,000 steps) acting deterministically or
with Gaussian action noise, plus uniform random actions. Each source plays ``--episodes`` seeded
episodes (the last ``--test-fraction`` held out); from every episode that *terminated* (fell, not cut
by the time limit) ``--cuts-per-episode`` segments are cut that end in the fall: ``k`` real steps,
``k`` uniform in ``[--min-steps, L - 1]`` (at most the episode's length), then ``L - k`` absorbing
steps with reward 0, action 0 and the last real observation repeated (a placeholder: a reward model
must not read them as states; ``length`` says where the real steps end).

New pairs join a fall segment with a segment drawn uniformly from the whole pool of the same split
(upright or fallen), so a pair holds one or two falls; they are labelled by the same annotator as the
upright set (``rlcourse.preferences.simulate_annotator`` on the true return of the padded segment,
the same temperature, tie parameter and flip rate, read from the upright file's MANIFEST entry).
``--fall-pair-fraction`` sets the share of all pairs, training and held-out alike, that contain a fall.

Stored (one compressed .npz): every array of the upright file (``obs``, ``act``, ``rewards``,
``source``, ``test_segment``, ``episode``, ``start``, ``train_pairs``, ``test_pairs``, ``train_mu``,
``test_mu``, ``source_names``, ``rollout_*``) extended with the new rows, plus ``terminated`` bool
(N,) (the segment contains a fall) and ``length`` int16 (N,) (real steps; L for upright segments).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rlcourse import data
from rlcourse.nets import load_policy
from rlcourse.preferences import (HOPPER_PREFS_UPRIGHT_FILE, expected_bayes_accuracy, preference_accuracy,
                                  random_pairs, simulate_annotator)
from rlcourse.rollouts import rollout

ENV_ID = "Hopper-v5"
OUT = data.DATASETS / "hopper_prefs" / "hopper_prefs_falls.npz"
LEVELS = [f"experts/Hopper-v5/level_{k}.pt" for k in range(4)]


def fall_sources(noise_stds: list[float], rng: np.random.Generator) -> tuple[list[str], list]:
    """Names and batch policies: every shipped snapshot with each action noise, and uniform random actions."""
    names, policies = [], []
    for path in LEVELS:
        policy = load_policy(data.DATASETS / path)
        for std in noise_stds:
            def act(obs, policy=policy, std=std):
                a = policy.act(obs)
                return np.clip(a + std * rng.standard_normal(a.shape), -1, 1).astype(np.float32) if std > 0 else a
            names.append(f"{Path(path).stem}+noise{std:g}" if std > 0 else Path(path).stem)
            policies.append(act)
    names.append("random (falls)")
    policies.append(lambda obs: rng.uniform(-1, 1, size=(obs.shape[0], 3)).astype(np.float32))
    return names, policies


def cut_falls(lengths: np.ndarray, terminated: np.ndarray, cuts: int, seg_len: int, min_steps: int,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``(episode, k)``: ``cuts`` segments per terminated episode, each ending in its fall after ``k`` real steps."""
    episode = np.repeat(np.flatnonzero(terminated), cuts)
    high = np.minimum(lengths[episode], seg_len - 1)
    k = rng.integers(np.minimum(min_steps, high), high + 1)
    return episode, k


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--noise-stds", nargs="+", type=float, default=[0.0, 0.3, 0.8])
    p.add_argument("--episodes", type=int, default=24, help="episodes per source")
    p.add_argument("--max-steps", type=int, default=1000)
    p.add_argument("--test-fraction", type=float, default=0.25)
    p.add_argument("--cuts-per-episode", type=int, default=3)
    p.add_argument("--min-steps", type=int, default=3, help="fewest real steps before the fall in a segment")
    p.add_argument("--fall-pair-fraction", type=float, default=0.25,
                   help="share of all pairs (training and held-out) that contain a fall")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=str(OUT))
    p.add_argument("--no-record", action="store_true")
    args = p.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    old = dict(data.load_npz(HOPPER_PREFS_UPRIGHT_FILE))
    old_info = data.info(HOPPER_PREFS_UPRIGHT_FILE)["info"]
    n_old, L = old["obs"].shape[:2]
    names, policies = fall_sources(args.noise_stds, rng)
    n_test_ep = max(1, round(args.episodes * args.test_fraction))
    new = {key: [] for key in ("obs", "act", "rewards", "source", "episode", "start", "test_segment", "length")}
    stats = {}
    for s, (name, policy) in enumerate(zip(names, policies)):
        eps = rollout(policy, ENV_ID, args.episodes, seed=args.seed * 100_000 + 1000 * s, max_steps=args.max_steps,
                      progress=False)
        ep, k = cut_falls(eps.lengths, eps.terminated, args.cuts_per_episode, L, args.min_steps, rng)
        start = eps.lengths[ep] - k
        window = np.minimum(start[:, None] + np.arange(L), eps.lengths[ep, None] - 1)  # repeat the last real step
        real = np.arange(L) < k[:, None]
        new["obs"].append(eps.obs[ep[:, None], window])
        new["act"].append(eps.actions[ep[:, None], window] * real[..., None])
        new["rewards"].append(eps.rewards[ep[:, None], window] * real)
        new["source"].append(np.full(len(ep), len(old["source_names"]) + s))
        new["episode"].append(ep)
        new["start"].append(start)
        new["test_segment"].append(ep >= args.episodes - n_test_ep)
        new["length"].append(k)
        seg_ret = new["rewards"][-1].sum(1)
        stats[name] = {"episode_return": round(float(eps.returns.mean()), 1),
                       "episode_length": round(float(eps.lengths.mean()), 1),
                       "terminated_episodes": int(eps.terminated.sum()), "fall_segments": int(len(ep)),
                       "fall_segment_return_mean": round(float(seg_ret.mean()), 2) if len(ep) else None}
        print(f"{name:20s} episode return {eps.returns.mean():7.1f}  length {eps.lengths.mean():6.1f}  "
              f"falls {eps.terminated.sum():3d}/{args.episodes}", flush=True)
    new = {key: np.concatenate(v) for key, v in new.items()}
    n_new = len(new["obs"])

    obs = np.concatenate([old["obs"].astype(np.float32), new["obs"]])
    act = np.concatenate([old["act"], new["act"]])
    rew = np.concatenate([old["rewards"], new["rewards"]])
    test = np.concatenate([old["test_segment"], new["test_segment"]])
    terminated = np.arange(n_old + n_new) >= n_old
    length = np.concatenate([np.full(n_old, L), new["length"]])
    returns = rew.astype(float).sum(1)

    def fall_pairs(split: np.ndarray, n_old_pairs: int) -> np.ndarray:
        """Pairs of (a fall of this split, any segment of this split), in random order within the pair."""
        n = round(n_old_pairs * args.fall_pair_fraction / (1 - args.fall_pair_fraction))
        falls, pool = np.flatnonzero(terminated & split), np.flatnonzero(split)
        first = falls[rng.integers(len(falls), size=n)]
        second = pool[rng.integers(len(pool), size=n)]
        clash = first == second
        second[clash] = pool[(np.searchsorted(pool, second[clash]) + 1) % len(pool)]
        swap = rng.random(n) < 0.5
        return np.where(swap[:, None], np.stack([second, first], 1), np.stack([first, second], 1)).astype(np.int64)

    label = lambda pairs: simulate_annotator(returns[pairs[:, 0]], returns[pairs[:, 1]], old_info["temperature"],
                                             old_info["flip_rate"], old_info["log_theta"], rng)
    new_train, new_test = fall_pairs(~test, len(old["train_pairs"])), fall_pairs(test, len(old["test_pairs"]))
    new_train_mu, new_test_mu = label(new_train), label(new_test)
    train_pairs = np.concatenate([old["train_pairs"], new_train])
    test_pairs = np.concatenate([old["test_pairs"], new_test])
    train_mu, test_mu = np.concatenate([old["train_mu"], new_train_mu]), np.concatenate([old["test_mu"], new_test_mu])

    out = Path(args.out)
    np.savez_compressed(
        out, obs=obs.astype(np.float16), act=act.astype(np.float32), rewards=rew.astype(np.float32),
        source=np.concatenate([old["source"], new["source"]]).astype(np.int16), test_segment=test,
        episode=np.concatenate([old["episode"], new["episode"]]).astype(np.int32),
        start=np.concatenate([old["start"], new["start"]]).astype(np.int16),
        terminated=terminated, length=length.astype(np.int16),
        train_pairs=train_pairs.astype(np.int32), test_pairs=test_pairs.astype(np.int32), train_mu=train_mu,
        test_mu=test_mu, source_names=np.concatenate([old["source_names"], np.array(names)]),
        rollout_obs=old["rollout_obs"], rollout_act=old["rollout_act"], rollout_rewards=old["rollout_rewards"],
        rollout_length=old["rollout_length"])

    has_fall = lambda pairs: terminated[pairs].any(1)
    ta, tb = returns[test_pairs[:, 0]], returns[test_pairs[:, 1]]
    falls_test = has_fall(test_pairs)
    temperature, flip, log_theta = old_info["temperature"], old_info["flip_rate"], old_info["log_theta"]
    all_pairs, all_mu = np.concatenate([train_pairs, test_pairs]), np.concatenate([train_mu, test_mu])
    info = {
        **{k: old_info[k] for k in ("env_id", "segment_length", "temperature", "flip_rate", "log_theta", "tie_model",
                                    "accuracy_definition", "obs_dtype")},
        "upright_file": HOPPER_PREFS_UPRIGHT_FILE, "n_segments": int(len(obs)), "n_fall_segments": int(n_new),
        "n_train_segments": int((~test).sum()), "n_test_segments": int(test.sum()),
        "n_train_pairs": int(len(train_pairs)), "n_test_pairs": int(len(test_pairs)),
        "fall_pair_fraction_train": round(float(has_fall(train_pairs).mean()), 4),
        "fall_pair_fraction_test": round(float(falls_test.mean()), 4),
        "absorbing_state": "after the fall: reward 0, action 0, the last real observation repeated; "
                           "length = real steps",
        "tie_fraction": round(float((all_mu == 0.5).mean()), 4),
        "label_agreement_with_true_return": round(preference_accuracy(returns[all_pairs[:, 0]],
                                                                      returns[all_pairs[:, 1]], all_mu), 4),
        "bayes_ceiling_test": round(preference_accuracy(ta, tb, test_mu), 4),
        "bayes_ceiling_test_expected": round(expected_bayes_accuracy(ta, tb, temperature, flip, log_theta), 4),
        "bayes_ceiling_test_fall_pairs": round(preference_accuracy(ta[falls_test], tb[falls_test],
                                                                   test_mu[falls_test]), 4),
        "bayes_ceiling_test_upright_pairs": round(preference_accuracy(ta[~falls_test], tb[~falls_test],
                                                                      test_mu[~falls_test]), 4),
        "fall_segment_real_steps_mean": round(float(new["length"].mean()), 2),
        "fall_sources": names, "fall_source_stats": stats, "fall_checkpoints": LEVELS,
        "noise_stds": args.noise_stds, "episodes_per_source": args.episodes, "max_steps": args.max_steps,
        "sources": [str(s) for s in old["source_names"]] + names,
    }
    print(f"{len(obs)} segments ({n_new} with a fall), {len(train_pairs)} + {len(test_pairs)} pairs "
          f"({info['fall_pair_fraction_train']:.1%} / {info['fall_pair_fraction_test']:.1%} with a fall), Bayes "
          f"ceiling {info['bayes_ceiling_test']:.3f} (fall pairs {info['bayes_ceiling_test_fall_pairs']:.3f}, "
          f"upright {info['bayes_ceiling_test_upright_pairs']:.3f}), {out.stat().st_size / 1e6:.1f} MB")
    if not args.no_record:
        data.record(out, __file__, argv, seed=args.seed, info=info)


if __name__ == "__main__":
    main()
