"""Shared pieces of hw4_rlhf_dpo that are not the students' stubs.

* :func:`load_reference` — the reference ("SFT") policy, cloned from a mid-skill checkpoint
  (``datasets/hw4/reference_policy.pt``, made by ``datasets/scripts/make_reference_policy.py``).
* :func:`load_reward_model` — the Bradley–Terry reward ensemble fitted to hw3's pairs
  (``datasets/hw4/reward_model.pt``, made by ``datasets/scripts/make_hw4_reward_model.py``: hw3 asks
  students to write that fit, so it is not in this library), and :func:`reward_function`, its
  batched numpy form for an environment wrapper.
* :func:`oriented_pairs` — labelled pairs turned into (chosen, rejected) segment tensors, ties left out.
* :func:`evaluate_policy` — deterministic true return, the KL to the reference on the visited states,
  and optionally the learned return, of one policy.
* :func:`train_dpo` — the DPO training loop, which calls the student's ``dpo_loss``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch
from torch.distributions import kl_divergence

from rlcourse import data as _data
from rlcourse.checkpoint import load_model, save_model
from rlcourse.envs import HOPPER
from rlcourse.nets import GaussianPolicy
from rlcourse.preferences import RewardEnsemble
from rlcourse.rollouts import rollout
from rlcourse.training import EvaluationHook, TrainingLog, due, fine_tuning_copies

ENV_ID = HOPPER
REFERENCE_FILE = "hw4/reference_policy.pt"
REWARD_MODEL_FILE = "hw4/reward_model.pt"
EVAL_SEED = 1000


def load_reference() -> GaussianPolicy:
    """The frozen reference policy (its ``metadata`` holds the measured return over 20 episodes)."""
    return _data.load_policy(REFERENCE_FILE).requires_grad_(False)


# --------------------------------------------------------------------------- the learned reward
def save_reward_model(ensemble: RewardEnsemble, path: str | Path, **metadata: float | int | str) -> None:
    """Save a reward ensemble as a checkpoint (config, ``state_dict``, metadata), atomically."""
    config = {"obs_dim": ensemble.obs_dim, "act_dim": ensemble.act_dim, "n_members": ensemble.n_members,
              "hidden": ensemble.hidden, **({"absorbing": True} if ensemble.has_absorbing else {})}
    save_model(ensemble, path, config, **metadata)


def load_reward_model(name: str = REWARD_MODEL_FILE) -> RewardEnsemble:
    """The shipped reward ensemble (made by ``datasets/scripts/make_hw4_reward_model.py`` from hw3's pairs),
    in eval mode; ``.metadata`` holds its held-out accuracy, the mean and standard deviation of its
    per-step reward on the real steps of the preference data (``step_mean``, ``step_std``), its fit time,
    and, for a model with an absorbing-state reward, that reward (``absorbing_reward``, in the units of
    :func:`reward_function`) and the offset that puts it at zero once normalised (``data_offset``)."""
    return load_model(_data.verify(name), RewardEnsemble).requires_grad_(False)


def reward_function(ensemble: RewardEnsemble) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``r(obs, act)``: the ensemble's mean per-step reward for a batch, ``(n, 11), (n, 3) -> (n,)`` float32."""
    def r(obs: np.ndarray, act: np.ndarray) -> np.ndarray:
        return ensemble.predict(np.asarray(obs, np.float32), np.asarray(act, np.float32)).mean(0).astype(np.float32)
    return r


# --------------------------------------------------------------------------- preference pairs
@dataclass
class SegmentPairs:
    """Segment pairs oriented by their label: ``chosen_obs`` ``(B, L, 11)``, ``chosen_act`` ``(B, L, 3)``,
    and the same for ``rejected``; all float32 tensors. Ties are not included."""

    chosen_obs: torch.Tensor
    chosen_act: torch.Tensor
    rejected_obs: torch.Tensor
    rejected_act: torch.Tensor

    def __len__(self) -> int:
        return len(self.chosen_obs)

    def batch(self, idx) -> tuple[tuple[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
        """``(chosen, rejected)`` for rows ``idx``, each an ``(obs, act)`` tuple."""
        return (self.chosen_obs[idx], self.chosen_act[idx]), (self.rejected_obs[idx], self.rejected_act[idx])


def oriented_pairs(obs: np.ndarray, act: np.ndarray, pairs: np.ndarray, mu: np.ndarray) -> SegmentPairs:
    """Labelled pairs ``(M, 2)`` with labels ``mu`` ``(M,)`` as chosen/rejected segments; ties (0.5) dropped."""
    pairs, mu = np.asarray(pairs), np.asarray(mu)
    strict = mu != 0.5
    first_wins = mu[strict] == 1.0
    chosen = np.where(first_wins, pairs[strict, 0], pairs[strict, 1])
    rejected = np.where(first_wins, pairs[strict, 1], pairs[strict, 0])
    t = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32)
    return SegmentPairs(t(obs[chosen]), t(act[chosen]), t(obs[rejected]), t(act[rejected]))


# --------------------------------------------------------------------------- evaluation
def mean_kl(policy: GaussianPolicy, reference: GaussianPolicy, obs: np.ndarray | torch.Tensor) -> float:
    """Average over the given states of ``KL(pi(.|s) || pi_ref(.|s))`` (exact, diagonal Gaussians), in nats."""
    obs = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
    with torch.no_grad():
        return float(kl_divergence(policy.distribution(obs), reference.distribution(obs)).mean())


def evaluate_policy(policy: GaussianPolicy, reference: Optional[GaussianPolicy] = None,
                    reward_fn: Optional[Callable] = None, n_episodes: int = 10, seed: int = EVAL_SEED,
                    max_steps: Optional[int] = None) -> dict[str, float]:
    """Deterministic episodes of ``policy``: ``return`` (mean true return), ``return_std``, ``length``,
    and, when given, ``kl`` (per-step KL to ``reference`` on the visited states) and ``learned_return``
    (the return under ``reward_fn``)."""
    eps = rollout(policy.act, ENV_ID, n_episodes, seed=seed, max_steps=max_steps, progress=False)
    out = {"return": float(eps.returns.mean()), "return_std": float(eps.returns.std()),
           "length": float(eps.lengths.mean())}
    obs, act = eps.flat()
    if reference is not None:
        out["kl"] = mean_kl(policy, reference, obs)
    if reward_fn is not None:
        learned = np.zeros(eps.mask.shape, dtype=np.float32)
        learned[eps.mask] = reward_fn(obs, act)
        out["learned_return"] = float(learned.sum(1).mean())
    return out


# --------------------------------------------------------------------------- DPO
@dataclass
class DPOLog(TrainingLog):
    """What :func:`train_dpo` records: besides ``evals``, one dict per logged step in ``steps`` (``step``,
    ``time``, ``loss``, ``margin``, ``accuracy``, and the held-out ``val_margin``, ``val_accuracy``)."""

    steps: list[dict] = field(default_factory=list)


def train_dpo(policy: GaussianPolicy, reference: GaussianPolicy, dpo_loss: Callable, train: SegmentPairs,
              beta: float, n_steps: int = 1000, batch_size: int = 64, lr: float = 3e-4,
              val: Optional[SegmentPairs] = None, evaluate: Optional[Callable[[GaussianPolicy], dict]] = None,
              eval_every: int = 250, log_every: int = 25, seed: int = 0, verbose: bool = True,
              ) -> tuple[GaussianPolicy, DPOLog]:
    """Fine-tune a copy of ``policy`` on preference pairs with ``dpo_loss(policy, reference, chosen,
    rejected, beta) -> (loss, info)`` (``info`` holds ``margin`` and ``accuracy``), Adam, minibatches
    of ``batch_size`` pairs drawn with replacement. Returns the trained copy and the log."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    actor, reference = fine_tuning_copies(policy, reference)
    opt = torch.optim.Adam(actor.parameters(), lr=lr)
    log = DPOLog(config=dict(beta=beta, n_steps=n_steps, batch_size=batch_size, lr=lr, seed=seed))
    run_evaluation = EvaluationHook(log, evaluate, verbose)

    run_evaluation(actor, 0)
    for step in range(1, n_steps + 1):
        chosen, rejected = train.batch(rng.integers(len(train), size=batch_size))
        loss, info = dpo_loss(actor, reference, chosen, rejected, beta)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if due(step, log_every, n_steps):
            row = {"step": step, "time": run_evaluation.elapsed(), "loss": float(loss.detach()),
                   **{k: float(torch.as_tensor(v).detach()) for k, v in info.items()}}
            if val is not None:
                with torch.no_grad():
                    idx = np.arange(min(len(val), 512))
                    val_loss, val_info = dpo_loss(actor, reference, *val.batch(idx), beta)
                row.update(val_loss=float(val_loss), **{f"val_{k}": float(v) for k, v in val_info.items()})
            log.steps.append(row)
        if due(step, eval_every, n_steps):
            run_evaluation(actor, step)
    return actor.eval(), log


# --------------------------------------------------------------------------- choosing settings without the true reward
def reward_disagreement(ensemble: RewardEnsemble, obs: np.ndarray, act: np.ndarray) -> np.ndarray:
    """Per-step standard deviation over the ensemble's members of the normalised reward, ``obs.shape[:-1]``:
    large where the members were not pinned down by comparisons (away from the preference data)."""
    return ensemble.predict(np.asarray(obs, np.float32), np.asarray(act, np.float32)).std(0)


def disagreement_threshold(ensemble: RewardEnsemble, obs: np.ndarray, act: np.ndarray, real: np.ndarray,
                           quantile: float = 0.9) -> float:
    """The ``quantile`` of the per-segment mean disagreement over the given segments ``(N, L, .)``, real steps
    only (``real`` ``(N, L)`` bool): how much the members disagree on states that comparisons covered."""
    d = reward_disagreement(ensemble, obs, act)
    return float(np.quantile((d * real).sum(1) / real.sum(1), quantile))


def preference_only_check(policy: GaussianPolicy, reference: GaussianPolicy, ensemble: RewardEnsemble, offset: float,
                          n_episodes: int = 10, seed: int = EVAL_SEED, max_steps: Optional[int] = None
                          ) -> dict[str, float]:
    """What may be known about a trained policy without the true reward: over deterministic episodes, its
    ``learned_return`` (the normalised learned reward plus ``offset`` per step, as RLHF optimised it),
    ``disagreement`` (mean per-step ensemble disagreement on the states it visits), ``kl`` to the
    reference and episode ``length``. The true return is deliberately not returned."""
    eps = rollout(policy.act, ENV_ID, n_episodes, seed=seed, max_steps=max_steps, progress=False)
    obs, act = eps.flat()
    meta = ensemble.metadata
    r = (reward_function(ensemble)(obs, act) - meta["step_mean"]) / meta["step_std"] + offset
    return {"learned_return": float(r.sum() / n_episodes), "disagreement": float(reward_disagreement(ensemble, obs, act).mean()),
            "kl": mean_kl(policy, reference, obs), "length": float(eps.lengths.mean())}


def choose_kl_coef(checks: dict[float, dict[str, float]], threshold: float) -> float:
    """The KL coefficient whose policy has the highest learned return among those whose states the reward
    model still covers (mean disagreement at most ``threshold``); the largest coefficient if none does."""
    covered = {c: ch for c, ch in checks.items() if ch["disagreement"] <= threshold}
    if not covered:
        return max(checks)
    return max(covered, key=lambda c: covered[c]["learned_return"])


def choose_beta(val_accuracy: dict[float, float], tolerance: float = 0.005) -> float:
    """The DPO beta whose implicit reward ranks the held-out pairs best; within ``tolerance`` of the best,
    the largest beta (the policy closest to the reference)."""
    best = max(val_accuracy.values())
    return max(b for b, acc in val_accuracy.items() if acc >= best - tolerance)


# --------------------------------------------------------------------------- comparing methods over seeds
def bootstrap_ratio(numerator: "np.ndarray | list[float]", denominator: "np.ndarray | list[float]",
                    n_resamples: int = 10_000, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """A percentile bootstrap interval for ``mean(numerator) / mean(denominator)`` over seeds: each resample
    draws both methods' seeds again, with replacement and independently (the two methods' seed numbers are
    not paired), and the interval holds the central ``level`` of the resampled ratios. With three to five
    seeds it is wide, as it should be: it says how little a handful of runs pins down."""
    num, den = np.asarray(numerator, dtype=np.float64), np.asarray(denominator, dtype=np.float64)
    rng = np.random.default_rng(seed)
    n = num[rng.integers(len(num), size=(n_resamples, len(num)))].mean(1)
    d = den[rng.integers(len(den), size=(n_resamples, len(den)))].mean(1)
    lo, hi = np.quantile(n / d, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)
