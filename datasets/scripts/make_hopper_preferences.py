"""Make the Hopper preference data set (hw3_preferences, hw4_rlhf_dpo): a pool of short segments
cut from rollouts of policies of several skill levels, and pairs of them labelled by a simulated
annotator that prefers the higher true return.

    python datasets/scripts/make_hopper_preferences.py \
        --checkpoints datasets/experts/Hopper-v5/ckpt_0050000.pt datasets/experts/Hopper-v5/ckpt_0200000.pt ... \
        --noise-stds 0 0.3 0.8 --random-policy --seed 0

Sources: every checkpoint (``rlcourse.nets.load_policy``) acting deterministically, plus, for each
non-zero entry of ``--noise-stds``, the same checkpoint with Gaussian noise of that standard
deviation added to its actions (clipped to [-1, 1]); plus, with ``--random-policy``, uniform random
actions. Every source plays ``--episodes`` seeded episodes; the last ``--test-fraction`` of each
source's episodes are held out. The same number of segments of ``--segment-length`` steps is cut
from each source at uniformly random valid starts (episodes shorter than a segment give none).

Labels (``rlcourse.preferences.simulate_annotator``): d = (R_a - R_b) / temperature through the
Rao–Kupper tie model (ties labelled 0.5), then each strict label flipped with probability
``--flip-rate``. Training pairs join training segments, held-out pairs join held-out segments.

Stored (one compressed .npz): ``obs`` float16 (N, L, 11) (float16 keeps the file small: about 3
significant digits), ``act`` float32 (N, L, 3), ``rewards`` float32 (N, L), ``source`` int16 (N,),
``test_segment`` bool (N,), ``episode`` int32 (N,) and ``start`` int16 (N,) (where each segment
was cut), ``train_pairs``/``test_pairs`` int32 (M, 2), ``train_mu``/``test_mu`` float32 (M,),
``source_names`` (str), and, per source, the first ``--rollout-steps`` steps of its first held-out
episode (``rollout_obs`` float16 (S, T, 11), ``rollout_act``, ``rollout_rewards``, zero-padded after
``rollout_length`` (S,)) for plotting a learned reward along a rollout. The checkpoints themselves are not shipped; the MANIFEST names them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rlcourse import data
from rlcourse.nets import load_policy
from rlcourse.preferences import expected_bayes_accuracy, preference_accuracy, random_pairs, simulate_annotator
from rlcourse.rollouts import rollout

ENV_ID = "Hopper-v5"
REPO = Path(__file__).resolve().parents[2]


def make_sources(checkpoints: list[str], noise_stds: list[float], random_policy: bool, act_dim: int,
                 rng: np.random.Generator) -> tuple[list[str], list, dict[str, float]]:
    """Names, batch policy functions and recorded eval returns of every source policy."""
    names, policies, returns = [], [], {}
    for path in checkpoints:
        policy = load_policy(path)
        stem = f"{Path(path).parent.name}/{Path(path).stem}"  # e.g. ppo/ckpt_0500000
        returns[stem] = float(policy.metadata.get("eval_return", float("nan")))
        for std in noise_stds:
            def act(obs, policy=policy, std=std):
                a = policy.act(obs)
                return np.clip(a + std * rng.standard_normal(a.shape), -1, 1).astype(np.float32) if std > 0 else a
            names.append(f"{stem}+noise{std:g}" if std > 0 else stem)
            policies.append(act)
    if random_policy:
        names.append("random")
        policies.append(lambda obs: rng.uniform(-1, 1, size=(obs.shape[0], act_dim)).astype(np.float32))
    return names, policies, returns


def cut_segments(lengths: np.ndarray, n: int, seg_len: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` (episode, start) pairs drawn uniformly among all valid starts (without replacement when possible)."""
    valid = np.clip(lengths - seg_len + 1, 0, None)
    if valid.sum() == 0:
        raise RuntimeError(f"no episode is {seg_len} steps long; run more episodes")
    flat = rng.choice(valid.sum(), size=n, replace=valid.sum() < n)
    episode = np.searchsorted(np.cumsum(valid), flat, side="right")
    start = flat - np.concatenate([[0], np.cumsum(valid)])[episode]
    return episode, start


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoints", nargs="+", required=True, help="policy files (rlcourse.nets.save_policy format)")
    p.add_argument("--noise-stds", nargs="+", type=float, default=[0.0, 0.3, 0.8])
    p.add_argument("--random-policy", action="store_true")
    p.add_argument("--episodes", type=int, default=20, help="episodes per source")
    p.add_argument("--max-steps", type=int, default=1000)
    p.add_argument("--test-fraction", type=float, default=0.2, help="fraction of each source's episodes held out")
    p.add_argument("--segment-length", type=int, default=25)
    p.add_argument("--segments-per-source", type=int, default=250)
    p.add_argument("--n-train-pairs", type=int, default=6000)
    p.add_argument("--n-test-pairs", type=int, default=1500)
    p.add_argument("--temperature", type=float, default=2.0, help="return units per unit of logit")
    p.add_argument("--flip-rate", type=float, default=0.1)
    p.add_argument("--log-theta", type=float, default=0.4, help="Rao–Kupper tie parameter eta = log(theta)")
    p.add_argument("--rollout-steps", type=int, default=300,
                   help="steps kept of one held-out episode per source (rollout_* arrays), for plots")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(data.DATASETS / "hopper_prefs" / "hopper_prefs.npz"))
    p.add_argument("--no-record", action="store_true", help="do not record the file in the MANIFEST")
    args = p.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    names, policies, ckpt_returns = make_sources(args.checkpoints, args.noise_stds, args.random_policy, 3, rng)
    L, n_test_ep = args.segment_length, max(1, round(args.episodes * args.test_fraction))
    obs, act, rew, source, episode, start, test = [], [], [], [], [], [], []
    demo = {"obs": [], "act": [], "rewards": [], "length": []}
    source_stats = {}
    for s, (name, policy) in enumerate(zip(names, policies)):
        eps = rollout(policy, ENV_ID, args.episodes, seed=args.seed * 100_000 + 1000 * s, max_steps=args.max_steps,
                      progress=False)
        first_test, T = args.episodes - n_test_ep, args.rollout_steps
        demo["length"].append(min(int(eps.lengths[first_test]), T))
        for key, arr in (("obs", eps.obs), ("act", eps.actions), ("rewards", eps.rewards)):
            clip = arr[first_test, :T]
            demo[key].append(np.concatenate([clip, np.zeros((T - len(clip),) + clip.shape[1:], clip.dtype)]))
        ep, st = cut_segments(eps.lengths, args.segments_per_source, L, rng)
        window = st[:, None] + np.arange(L)
        obs.append(eps.obs[ep[:, None], window])
        act.append(eps.actions[ep[:, None], window])
        rew.append(eps.rewards[ep[:, None], window])
        source.append(np.full(len(ep), s))
        episode.append(ep)
        start.append(st)
        test.append(ep >= args.episodes - n_test_ep)
        seg_ret = rew[-1].sum(1)
        source_stats[name] = {"episode_return": round(float(eps.returns.mean()), 1),
                              "episode_length": round(float(eps.lengths.mean()), 1),
                              "segment_return_mean": round(float(seg_ret.mean()), 2),
                              "segment_return_std": round(float(seg_ret.std()), 2)}
        print(f"{name:28s} episode return {eps.returns.mean():8.1f}  length {eps.lengths.mean():6.1f}  "
              f"segment return {seg_ret.mean():6.2f} ± {seg_ret.std():5.2f}", flush=True)
    obs, act, rew = np.concatenate(obs), np.concatenate(act), np.concatenate(rew)
    source, episode, start, test = map(np.concatenate, (source, episode, start, test))

    returns = rew.astype(float).sum(1)
    train_pairs = random_pairs(np.flatnonzero(~test), args.n_train_pairs, rng)
    test_pairs = random_pairs(np.flatnonzero(test), args.n_test_pairs, rng)
    label = lambda pairs: simulate_annotator(returns[pairs[:, 0]], returns[pairs[:, 1]], args.temperature,
                                             args.flip_rate, args.log_theta, rng)
    train_mu, test_mu = label(train_pairs), label(test_pairs)

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, obs=obs.astype(np.float16), act=act.astype(np.float32), rewards=rew.astype(np.float32),
                        source=source.astype(np.int16), test_segment=test, episode=episode.astype(np.int32),
                        start=start.astype(np.int16), train_pairs=train_pairs.astype(np.int32),
                        test_pairs=test_pairs.astype(np.int32), train_mu=train_mu, test_mu=test_mu,
                        source_names=np.array(names), rollout_obs=np.stack(demo["obs"]).astype(np.float16),
                        rollout_act=np.stack(demo["act"]), rollout_rewards=np.stack(demo["rewards"]),
                        rollout_length=np.array(demo["length"], dtype=np.int16))

    all_pairs, all_mu = np.concatenate([train_pairs, test_pairs]), np.concatenate([train_mu, test_mu])
    ret_a, ret_b = returns[all_pairs[:, 0]], returns[all_pairs[:, 1]]
    tr_a, tr_b = returns[test_pairs[:, 0]], returns[test_pairs[:, 1]]
    ckpt_paths = [Path(c).resolve() for c in args.checkpoints]
    info = {
        "env_id": ENV_ID, "segment_length": L, "n_segments": int(len(obs)),
        "n_train_segments": int((~test).sum()), "n_test_segments": int(test.sum()),
        "n_train_pairs": int(len(train_pairs)), "n_test_pairs": int(len(test_pairs)),
        "temperature": args.temperature, "flip_rate": args.flip_rate, "log_theta": args.log_theta,
        "tie_model": "Rao-Kupper on d=(R_a-R_b)/temperature: P(a)=sigmoid(d-eta), P(b)=sigmoid(-d-eta), "
                     "P(tie)=rest (label 0.5); then strict labels flipped with prob flip_rate",
        "tie_fraction": round(float((all_mu == 0.5).mean()), 4),
        "label_agreement_with_true_return": round(preference_accuracy(ret_a, ret_b, all_mu), 4),
        "bayes_ceiling_test": round(preference_accuracy(tr_a, tr_b, test_mu), 4),
        "bayes_ceiling_test_expected": round(expected_bayes_accuracy(tr_a, tr_b, args.temperature, args.flip_rate,
                                                                     args.log_theta), 4),
        "accuracy_definition": "fraction of strict labels (mu 0 or 1) whose preferred segment scores higher",
        "obs_dtype": "float16", "sources": names, "source_stats": source_stats,
        "checkpoints": [str(c.relative_to(REPO)) if c.is_relative_to(REPO) else str(c) for c in ckpt_paths],
        "checkpoint_eval_returns": ckpt_returns, "noise_stds": args.noise_stds,
        "random_policy": args.random_policy, "episodes_per_source": args.episodes, "max_steps": args.max_steps,
        "segments_per_source": args.segments_per_source, "test_split": "last episodes of each source",
    }
    size_mb = out.stat().st_size / 1e6
    print(f"{len(obs)} segments, {len(train_pairs)} + {len(test_pairs)} pairs, {info['tie_fraction']:.1%} ties, "
          f"label agreement {info['label_agreement_with_true_return']:.3f}, Bayes ceiling "
          f"{info['bayes_ceiling_test']:.3f} (expected {info['bayes_ceiling_test_expected']:.3f}), {size_mb:.1f} MB")
    if not args.no_record:
        data.record(out, __file__, argv, seed=args.seed, info=info)


if __name__ == "__main__":
    main()
