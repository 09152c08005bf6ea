"""Make hw4_rlhf_dpo's learned reward: a Bradley–Terry reward ensemble fitted to hw3's Hopper pairs.

    python datasets/scripts/make_hw4_reward_model.py --seed 0          # about 30 s on one core

hw3 asks students to write this fit (``preference_loss``, ``train_reward_model``); hw4 takes the
result as given, so the fit lives here, in instructor tooling that the student release leaves out,
and hw4 loads the file with ``rlcourse.rlhf.load_reward_model``.

The model is a ``rlcourse.preferences.RewardEnsemble`` of ``--members`` MLPs. Each member is trained
with Adam on its own bootstrap of the training pairs, by the segment Bradley–Terry loss
``-mu log sigma(R_a - R_b) - (1 - mu) log sigma(R_b - R_a)`` with ``R`` the member's reward summed
over a segment's steps (ties, ``mu = 0.5``, count half a win for each side). Inputs are standardised
and each member's per-step output normalised to mean 0 and standard deviation 1 on the real steps
of the segments of the training pairs. Written to ``datasets/hw4/reward_model.pt`` with the held-out
accuracy, the correlation with the true segment returns, the mean and standard deviation of the
ensemble's per-step reward on the real steps of all segments, and the fit time, and recorded in the MANIFEST.

Termination is handled as the data describes it: the steps after a fall are the absorbing state,
whose reward is one more number each member learns (``RewardEnsemble(absorbing=True)``), fitted by
the same loss. Comparisons of a segment that falls after ``k`` steps with one that stays up see
``L - k`` times the gap between an upright step's reward and the absorbing state's, so the per-step
constant that upright pairs cannot see is now fitted. The metadata records the absorbing reward and
``data_offset``, the offset ``b`` that makes the absorbing state pay 0 once the reward is normalised
as hw4's wrapper does (``(r - step_mean) / step_std + b``): the offset chosen by the data alone.
``--data hopper_prefs/hopper_prefs.npz --no-absorbing`` fits the earlier model on the upright set.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import data
from rlcourse.preferences import HOPPER_PREFS_FILE, RewardEnsemble, load_hopper_preferences, preference_accuracy
from rlcourse.rlhf import REWARD_MODEL_FILE, save_reward_model
from rlcourse.seeding import seed_everything

OUT = data.DATASETS / REWARD_MODEL_FILE


def segment_bt_loss(member, obs_a, act_a, obs_b, act_b, mu, absorbing_a=None, absorbing_b=None) -> torch.Tensor:
    """Mean Bradley–Terry negative log-likelihood of labels ``mu`` for segment pairs ``(a, b)``; the
    ``absorbing`` masks (or None) mark steps after a fall."""
    score = lambda obs, act, absorbing: (member(obs, act) if absorbing is None else member(obs, act, absorbing)).sum(-1)
    d = score(obs_a, act_a, absorbing_a) - score(obs_b, act_b, absorbing_b)
    return -(mu * F.logsigmoid(d) + (1 - mu) * F.logsigmoid(-d)).mean()


def fit(obs: np.ndarray, act: np.ndarray, pairs: np.ndarray, mu: np.ndarray, n_members: int, hidden: list[int],
        n_steps: int, batch_size: int, lr: float, weight_decay: float, seed: int,
        absorbing: np.ndarray | None = None) -> RewardEnsemble:
    """A reward ensemble fitted to labelled segment pairs, each member on a bootstrap of the pairs; with an
    ``absorbing`` mask ``(N, L)``, also each member's absorbing-state reward (not weight-decayed)."""
    obs_t, act_t = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)
    mu_t = torch.as_tensor(mu, dtype=torch.float32)
    absorbing_t = None if absorbing is None else torch.as_tensor(absorbing)
    mask = lambda idx: None if absorbing_t is None else absorbing_t[idx]
    used = np.unique(pairs)
    real = np.ones(obs.shape[:2], bool) if absorbing is None else ~absorbing
    real_obs, real_act = obs_t[used][torch.as_tensor(real[used])], act_t[used][torch.as_tensor(real[used])]
    ensemble = RewardEnsemble(obs_t.shape[-1], act_t.shape[-1], n_members, hidden, seed=seed,
                              absorbing=absorbing is not None)
    ensemble.set_input_scaling(real_obs, real_act)
    rng = np.random.default_rng(seed)
    for k in range(n_members):
        member, boot = ensemble.member(k), rng.integers(len(pairs), size=len(pairs))
        groups = [{"params": list(member.parameters())}]
        if absorbing is not None:  # a fresh Adam per member: the other members' entries get no update
            groups.append({"params": [ensemble.absorbing_reward], "weight_decay": 0.0})
        opt = torch.optim.Adam(groups, lr=lr, weight_decay=weight_decay)
        for _ in range(n_steps):
            batch = boot[rng.integers(len(boot), size=batch_size)]
            a, b = pairs[batch, 0], pairs[batch, 1]
            loss = segment_bt_loss(member, obs_t[a], act_t[a], obs_t[b], act_t[b], mu_t[batch], mask(a), mask(b))
            opt.zero_grad()
            loss.backward()
            opt.step()
        print(f"member {k}: final batch loss {loss.item():.3f}", flush=True)
    return ensemble.normalise_(real_obs, real_act).eval()


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--members", type=int, default=3)
    p.add_argument("--hidden", type=int, nargs="+", default=[64, 64])
    p.add_argument("--steps", type=int, default=1500, help="Adam steps per member")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--weight-decay", type=float, default=1e-4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--data", default=HOPPER_PREFS_FILE, help="the preference file (under datasets/)")
    p.add_argument("--no-absorbing", action="store_true", help="no absorbing-state reward (the upright set's model)")
    p.add_argument("--out", default=str(OUT))
    p.add_argument("--no-record", action="store_true", help="write the file but leave the MANIFEST alone")
    args = p.parse_args(argv)

    torch.set_num_threads(1)
    seed_everything(args.seed)
    prefs = load_hopper_preferences(args.data)
    absorbing = None if args.no_absorbing else prefs.absorbing
    t0 = time.perf_counter()
    ensemble = fit(prefs.obs, prefs.act, prefs.train_pairs, prefs.train_mu, args.members, args.hidden, args.steps,
                   args.batch_size, args.lr, args.weight_decay, args.seed, absorbing)
    fit_seconds = time.perf_counter() - t0

    steps = ensemble.predict(prefs.obs, prefs.act, absorbing).mean(0)  # (N, L): the ensemble's per-step reward
    seg, real = steps.sum(1), ~prefs.absorbing
    i, j = prefs.test_pairs.T
    meta = dict(test_accuracy=round(preference_accuracy(seg[i], seg[j], prefs.test_mu), 4),
                bayes_ceiling_test=round(float(prefs.info["bayes_ceiling_test"]), 4),
                return_correlation=round(float(np.corrcoef(seg, prefs.returns)[0, 1]), 4),
                step_mean=float(steps[real].mean()), step_std=float(steps[real].std()),
                fit_seconds=round(fit_seconds, 1), n_members=args.members, steps=args.steps, seed=args.seed,
                data=args.data)
    if absorbing is not None:
        meta["absorbing_reward"] = float(ensemble.absorbing_value().mean())
        meta["data_offset"] = (meta["step_mean"] - meta["absorbing_reward"]) / meta["step_std"]
    out = Path(args.out)
    save_reward_model(ensemble, out, **meta)
    print({k: v for k, v in meta.items() if k != "data"})
    if not args.no_record:
        data.record(out, __file__, argv, seed=args.seed, info=meta)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
