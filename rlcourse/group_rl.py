"""Given tools of ``hw6_group_rl``: critic-free RL, preference losses beyond DPO, over-optimisation laws.

hw6 reuses hw5's language, gold reward and SFT model (:mod:`rlcourse.reviews`, :mod:`rlcourse.lm`).
What students write there (the group advantages, the GRPO loss, IPO and KTO) lives in the notebook;
this module holds what the notebook gives them, built so that none of it is one of hw5's stubs
(hw5's students write the token log-probabilities, the Bradley-Terry loss and the DPO loss, and the
whole release is readable while hw5 is graded):

- :func:`completion_log_probs` and :func:`completion_log_prob_sums` (from :mod:`rlcourse.completions`): a
  language model's log-probabilities of the completion tokens of sequences, computed by running the model
  (they take a model and a prompt length, never logits and a mask);
- :func:`load_reward_model` and :func:`proxy_score`: the Bradley-Terry reward model on the shipped
  preference pairs, fitted by the instructors' script ``datasets/scripts/make_hw6_models.py`` and
  shipped as weights, standardised on those pairs; :func:`load_dpo_policy`: DPO's policy from the
  same script, for the frontier beside IPO and KTO;
- :func:`best_of_n_from_pool`: the expected gold and proxy reward of best-of-``n`` from one pool of
  samples per prompt, unbiased for every ``n`` up to the pool's size;
- :func:`best_of_n_kl`: the exact KL of best-of-``n`` from a discrete reference (ties grouped, broken
  at random), against the formula ``log n - (n - 1)/n``;
- :func:`fit_bon_law`, :func:`fit_rl_law` and their peaks: Gao et al. (2022)'s functional forms
  ``R(d) = d (alpha - beta d)`` and ``R(d) = d (alpha - beta log d)``, ``d = sqrt(KL)``, fitted by
  least squares (both are linear in ``(alpha, beta)``).
"""
from __future__ import annotations

import math

import numpy as np
import torch

from rlcourse.checkpoint import load_model
from rlcourse.completions import completion_log_prob_sums, completion_log_probs  # noqa: F401 - given to hw6 from here
from rlcourse.lm import LMConfig, ScalarHeadLM, TinyLM, load_lm


REWARD_MODEL_FILE = "hw6/reward_model.pt"
DPO_POLICY_FILE = "hw6/dpo_beta0.1.pt"


def load_reward_model() -> ScalarHeadLM:
    """The shipped proxy reward model (``datasets/hw6/reward_model.pt``), checksum-verified, in eval mode.

    A scalar-head copy of the SFT model fitted to the first 3,000 training pairs of
    ``datasets/lm/preferences.npz`` by ``datasets/scripts/make_hw6_models.py``; ``rm.shift`` and ``rm.scale``
    (the mean and standard deviation of its raw scores on those pairs) standardise :func:`proxy_score`, and
    ``rm.metadata`` records how it was fitted and its held-out accuracy.
    """
    from rlcourse import data

    rm = load_model(data.verify(REWARD_MODEL_FILE), lambda **config: ScalarHeadLM(TinyLM(LMConfig(**config))))
    rm.shift, rm.scale = float(rm.metadata["shift"]), float(rm.metadata["scale"])
    return rm


def load_dpo_policy() -> TinyLM:
    """DPO's policy (``datasets/hw6/dpo_beta0.1.pt``), checksum-verified, in eval mode; ``.metadata`` says how.

    Trained from the SFT model on the same pairs, at the same beta and budget as the notebook's IPO, by
    ``datasets/scripts/make_hw6_models.py`` (hw5's students write the DPO loss, so hw6 ships its result).
    """
    from rlcourse import data

    return load_lm(data.verify(DPO_POLICY_FILE))


@torch.no_grad()
def proxy_score(rm: ScalarHeadLM, tokens: torch.Tensor) -> torch.Tensor:
    """The reward model's standardised score of each sequence, ``(B,)``."""
    return (torch.cat([rm.score(x) for x in tokens.split(1024)]) - rm.shift) / rm.scale


def best_of_n_from_pool(select: np.ndarray, value: np.ndarray, n: int) -> np.ndarray:
    """Expected ``value`` of best-of-``n`` (by ``select``), per prompt, from one pool of ``M >= n`` samples.

    ``select`` and ``value`` are ``(B, M)``: the score that picks the best and the quantity measured (say the
    proxy and the gold reward of ``M`` samples of each of ``B`` prompts). Drawing ``n`` of the ``M`` without
    replacement, the ``k``-th lowest by ``select`` (``k = 1..M``) is the best with probability
    ``C(k - 1, n - 1) / C(M, n)``; the result, ``(B,)``, averages ``value`` with these weights. It is an unbiased
    estimate of best-of-``n`` from the model itself (the pool is an i.i.d. sample), for every ``n <= M`` at
    once. Ties in ``select`` are broken by position.
    """
    select, value = np.asarray(select, float), np.asarray(value, float)
    m = select.shape[1]
    if not 1 <= n <= m:
        raise ValueError(f"n = {n} must be between 1 and the pool size {m}")
    k = np.arange(1, m + 1)
    log_w = np.full(m, -np.inf)
    ok = k >= n
    log_w[ok] = (_log_comb(k[ok] - 1, n - 1) - _log_comb(np.array(m), n))
    w = np.exp(log_w)
    order = np.argsort(select, axis=1, kind="stable")
    return (np.take_along_axis(value, order, axis=1) * w).sum(axis=1) / w.sum()


def _log_comb(a: np.ndarray, b: int) -> np.ndarray:
    from scipy.special import gammaln

    return gammaln(a + 1.0) - gammaln(b + 1.0) - gammaln(a - b + 1.0)


def best_of_n_kl(scores: np.ndarray, n: int) -> float:
    """Exact ``KL(best-of-n || reference)`` when the reference is the empirical distribution of ``scores``.

    ``scores`` ``(M,)``: rewards of ``M`` equally likely responses. Responses with equal scores form one
    atom of the reward's distribution, with ties broken uniformly at random, so that with ``q`` the
    atoms' probabilities sorted by reward and ``C`` their cumulative sums, best-of-``n`` puts mass
    ``p_k = C_k^n - C_{k-1}^n`` on atom ``k`` and ``KL = sum_k p_k log(p_k / q_k)``. Without ties and as ``M``
    grows this tends to ``log n - (n - 1)/n``, its upper bound.
    """
    _, counts = np.unique(np.asarray(scores, float), return_counts=True)
    q = counts / counts.sum()
    c = np.cumsum(q)
    p = c ** n - np.concatenate([[0.0], c[:-1]]) ** n
    keep = p > 0
    return float(np.sum(p[keep] * np.log(p[keep] / q[keep])))


def bon_kl_formula(n: int | np.ndarray) -> np.ndarray | float:
    """``log n - (n - 1)/n``: the KL of best-of-``n`` for a reward without atoms."""
    n = np.asarray(n, float)
    out = np.log(n) - (n - 1) / n
    return float(out) if out.ndim == 0 else out


def fit_bon_law(d: np.ndarray, gain: np.ndarray) -> tuple[float, float]:
    """Least-squares ``(alpha, beta)`` of ``gain ~ d (alpha - beta d)``, with ``d = sqrt(KL)``.

    ``gain`` is the gold reward minus the starting policy's (the form has ``R(0) = 0``). Linear in the
    coefficients: the columns are ``d`` and ``-d^2``.
    """
    d, gain = np.asarray(d, float), np.asarray(gain, float)
    design = np.stack([d, -d ** 2], axis=1)
    (alpha, beta), *_ = np.linalg.lstsq(design, gain, rcond=None)
    return float(alpha), float(beta)


def fit_rl_law(d: np.ndarray, gain: np.ndarray) -> tuple[float, float]:
    """Least-squares ``(alpha, beta)`` of ``gain ~ d (alpha - beta log d)``; points with ``d <= 0`` are dropped."""
    d, gain = np.asarray(d, float), np.asarray(gain, float)
    keep = d > 0
    design = np.stack([d[keep], -d[keep] * np.log(d[keep])], axis=1)
    (alpha, beta), *_ = np.linalg.lstsq(design, gain[keep], rcond=None)
    return float(alpha), float(beta)


def bon_law(d: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """``d (alpha - beta d)``."""
    d = np.asarray(d, float)
    return d * (alpha - beta * d)


def rl_law(d: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """``d (alpha - beta log d)`` (0 at ``d = 0``)."""
    d = np.asarray(d, float)
    return np.where(d > 0, d * (alpha - beta * np.log(np.where(d > 0, d, 1.0))), 0.0)


def bon_law_peak(alpha: float, beta: float) -> float:
    """``d* = alpha / (2 beta)``, where ``d (alpha - beta d)`` peaks (``inf`` when ``beta <= 0``)."""
    return alpha / (2 * beta) if beta > 0 else math.inf


def rl_law_peak(alpha: float, beta: float) -> float:
    """``d* = exp(alpha / beta - 1)``, where ``d (alpha - beta log d)`` peaks (``inf`` when ``beta <= 0``)."""
    return math.exp(alpha / beta - 1) if beta > 0 else math.inf


def n_for_kl(kl: float) -> float:
    """The (real) ``n >= 1`` whose best-of-``n`` formula KL ``log n - (n - 1)/n`` equals ``kl``."""
    if kl <= 0:
        return 1.0
    lo, hi = 1.0, 2.0
    while bon_kl_formula(hi) < kl:
        lo, hi = hi, hi * 2
        if hi > 1e300:
            return math.inf
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if bon_kl_formula(mid) < kl else (lo, mid)
    return 0.5 * (lo + hi)
