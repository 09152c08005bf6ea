"""Make hw6_group_rl's shipped models: the proxy reward model and DPO's policy, both from hw5's SFT model.

    python datasets/scripts/make_hw6_models.py --seed 0          # a few minutes on one core

hw5 asks students to write the Bradley-Terry loss (``reward_model_loss``) and the DPO loss (``dpo_loss``);
hw6 needs a reward model and DPO's point on its frontier, and its release is readable while hw5 is graded.
So both fits live here, in instructor tooling the student release leaves out, and hw6 loads their results
with ``rlcourse.group_rl.load_reward_model`` and ``load_dpo_policy``.

- ``datasets/hw6/reward_model.pt``: a scalar-head copy of the SFT model fitted to the first ``--pairs``
  training pairs of ``datasets/lm/preferences.npz`` by the Bradley-Terry negative log-likelihood (AdamW,
  ``--rm-steps`` batches of 64 pairs), with the mean and standard deviation of its raw scores on those
  pairs' sequences (``shift``, ``scale``) and its accuracy on the held-out pairs in the metadata.
- ``datasets/hw6/dpo_beta0.1.pt``: DPO from the SFT model on the same pairs, at beta ``--beta``,
  ``--dpo-steps`` batches of 64, with hw6's given ``rlcourse.group_training.pairwise_train``, so that
  it is trained exactly as the notebook trains IPO.

With the defaults (hw6's full budget) and seed 0 both equal seed 0 of ``bench/bench_hw6_group_rl.py``,
which imports :func:`fit_reward_model` and :func:`train_dpo` from here for its other seeds.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import asdict

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import data
from rlcourse import group_rl as G
from rlcourse import reviews as R
from rlcourse.checkpoint import save_model
from rlcourse.lm import ScalarHeadLM, TinyLM, load_sft, save_lm
from rlcourse import lm_training
from rlcourse.group_training import pairwise_train


def fit_reward_model(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, steps: int, seed: int,
                     batch: int = 64, lr: float = 3e-4) -> ScalarHeadLM:
    """A scalar-head copy of ``sft`` fitted to pairs (row ``i`` of ``chosen`` beats row ``i`` of ``rejected``):
    ``rlcourse.lm_training.fit_reward_model`` with the Bradley-Terry loss written here (the script may not use
    a student's stub). In eval mode, ``rm.shift`` and ``rm.scale`` standardise ``rlcourse.group_rl.proxy_score``."""
    return lm_training.fit_reward_model(sft, chosen, rejected, _bradley_terry_loss, steps, seed, batch=batch, lr=lr)


def _bradley_terry_loss(chosen_scores: torch.Tensor, rejected_scores: torch.Tensor) -> torch.Tensor:
    return -F.logsigmoid(chosen_scores - rejected_scores).mean()


def train_dpo(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, prompt_len: int, beta: float, steps: int,
              seed: int) -> TinyLM:
    """DPO from ``sft`` with hw6's given ``pairwise_train``: the mean over pairs of ``-log sigmoid(beta * margin)``."""

    def dpo(pi_c, pi_r, ref_c, ref_r):
        return -F.logsigmoid(beta * ((pi_c - ref_c) - (pi_r - ref_r))).mean()

    return pairwise_train(sft, chosen, rejected, prompt_len, dpo, steps, seed=seed)


def training_pairs(n_pairs: int) -> tuple[torch.Tensor, torch.Tensor, int, dict]:
    """The first ``n_pairs`` training pairs (chosen, rejected), the prompt length, and the preference file."""
    prefs = R.load_preferences()
    tr = torch.as_tensor(np.flatnonzero(~prefs["test"])[:n_pairs])
    chosen, rejected = torch.as_tensor(prefs["chosen"]), torch.as_tensor(prefs["rejected"])
    return chosen[tr], rejected[tr], int(prefs["prompt_len"]), prefs


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pairs", type=int, default=3000, help="training pairs (hw6's N_PAIRS)")
    parser.add_argument("--rm-steps", type=int, default=120, help="reward-model updates of 64 pairs")
    parser.add_argument("--dpo-steps", type=int, default=90, help="DPO updates of 64 pairs (hw6's OFFLINE_STEPS)")
    parser.add_argument("--beta", type=float, default=0.1, help="DPO's beta (hw6's OFFLINE_BETA)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)                    # as the notebook and the benchmark run
    sft = load_sft()
    chosen, rejected, p, prefs = training_pairs(args.pairs)

    t0 = time.perf_counter()
    rm = fit_reward_model(sft, chosen, rejected, args.rm_steps, seed=args.seed)
    fit_s = time.perf_counter() - t0
    test = torch.as_tensor(np.flatnonzero(prefs["test"]))
    all_c, all_r = torch.as_tensor(prefs["chosen"]), torch.as_tensor(prefs["rejected"])
    accuracy = float((G.proxy_score(rm, all_c[test]) > G.proxy_score(rm, all_r[test])).float().mean())
    rm_info = dict(shift=rm.shift, scale=rm.scale, steps=args.rm_steps, batch=64, lr=3e-4, seed=args.seed,
                   pairs=args.pairs, test_accuracy=round(accuracy, 4), fit_seconds=round(fit_s, 1))
    out = data.DATASETS / G.REWARD_MODEL_FILE
    save_model(rm, out, asdict(sft.cfg), **rm_info)
    data.record(out, __file__, argv, seed=args.seed, info=rm_info)
    print(f"reward model: held-out accuracy {accuracy:.3f}, {fit_s:.0f} s -> {out}")

    t0 = time.perf_counter()
    dpo = train_dpo(sft, chosen, rejected, p, args.beta, args.dpo_steps, seed=args.seed)
    dpo_info = dict(beta=args.beta, steps=args.dpo_steps, batch=64, lr=2e-4, seed=args.seed, pairs=args.pairs,
                    train_seconds=round(time.perf_counter() - t0, 1))
    out = data.DATASETS / G.DPO_POLICY_FILE
    save_lm(dpo, out, **dpo_info)
    data.record(out, __file__, argv, seed=args.seed, info=dpo_info)
    print(f"DPO beta={args.beta}: {dpo_info['train_seconds']:.0f} s -> {out}")


if __name__ == "__main__":
    main()
