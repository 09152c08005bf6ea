"""Given tools of ``hw6_group_rl``: critic-free RL, preference losses beyond DPO, over-optimisation laws.

hw6 reuses hw5's language, gold reward and SFT model (:mod:`rlcourse.reviews`, :mod:`rlcourse.lm`).
What students write there (the group advantages, the GRPO loss, IPO and KTO) lives in the notebook;
this module holds what the notebook gives them:

- :func:`completion_log_probs`: per-token log-probabilities of a completion (hw5 has students write
  it; hw6 takes it as given);
- :func:`fit_reward_model` and :func:`proxy_score`: a Bradley-Terry reward model on the shipped
  preference pairs, standardised on them;
- :func:`best_of_n_from_pool`: the expected gold and proxy reward of best-of-``n`` from one pool of
  samples per prompt, unbiased for every ``n`` up to the pool's size;
- :func:`best_of_n_kl`: the exact KL of best-of-``n`` from a discrete reference (ties grouped, broken
  at random), against the formula ``log n - (n - 1)/n``;
- :func:`fit_bon_law`, :func:`fit_rl_law` and their peaks: Gao et al. (2022)'s functional forms
  ``R(d) = d (alpha - beta d)`` and ``R(d) = d (alpha - beta log d)``, ``d = sqrt(KL)``, fitted by
  least squares (both are linear in ``(alpha, beta)``).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse.lm import ScalarHeadLM, TinyLM


def completion_log_probs(logits: torch.Tensor, tokens: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``(B, T)`` log-probabilities of ``tokens`` under next-token ``logits`` ``(B, T, V)``, zero outside ``mask``.

    Entry ``[b, t]`` is ``log softmax(logits[b, t - 1])[tokens[b, t]]`` where ``mask[b, t]`` is set (column 0
    is always 0). Differentiable in ``logits``.
    """
    logp = F.log_softmax(logits[:, :-1], dim=-1).gather(-1, tokens[:, 1:, None]).squeeze(-1)
    logp = F.pad(logp, (1, 0))
    keep = mask.bool().clone()
    keep[:, 0] = False
    return torch.where(keep, logp, torch.zeros_like(logp))


def fit_reward_model(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, steps: int, seed: int,
                     batch: int = 64, lr: float = 3e-4) -> ScalarHeadLM:
    """A scalar-head copy of ``sft`` fitted to pairs (row ``i`` of ``chosen`` beats row ``i`` of ``rejected``).

    Bradley-Terry negative log-likelihood, AdamW, ``steps`` batches of ``batch`` pairs. The result is in eval
    mode, with ``rm.shift`` and ``rm.scale`` the mean and standard deviation of its raw scores on all the
    pairs' sequences, so that :func:`proxy_score` is standardised.
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    rm = ScalarHeadLM(copy.deepcopy(sft)).train()
    opt = torch.optim.AdamW(rm.parameters(), lr=lr, weight_decay=0.01)
    for _ in range(steps):
        idx = torch.randint(len(chosen), (batch,), generator=gen)
        loss = -F.logsigmoid(rm.score(chosen[idx]) - rm.score(rejected[idx])).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    rm.eval()
    with torch.no_grad():
        raw = torch.cat([rm.score(x) for x in torch.cat([chosen, rejected]).split(512)])
    rm.shift, rm.scale = float(raw.mean()), float(raw.std())
    return rm


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
