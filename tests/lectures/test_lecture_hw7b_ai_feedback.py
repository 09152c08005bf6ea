"""Numerical checks of chapter 9b (`lectures/09b_ai_feedback.md`): DPO's gradient on a pair, the loss over a sampler
and what it leaves free, the rule vote, the inherited bias and the position swap.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lecture_links.py``) and checks the
lecture's statement against an independent computation: autograd on a tabular policy, a generic optimiser on the
population loss, enumeration of orders.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from scipy.optimize import minimize
from scipy.special import expit, log_expit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_links import checks  # noqa: E402


def population_loss(theta, log_ref, mu, pref, beta):
    """Eq. (eq-online-dpo) for a tabular softmax policy: sum over ordered pairs of mu mu p log sigma(beta h)."""
    logp = theta - np.logaddexp.reduce(theta)
    ratio = logp - log_ref
    h = ratio[:, None] - ratio[None, :]
    return -float((mu[:, None] * mu[None, :] * pref * log_expit(beta * h)).sum())


@pytest.mark.parametrize("seed", [0, 1, 2])
@checks("eq-dpo-pair-grad", "8db03e1b")
def test_dpo_gradient_on_a_pair_by_autograd(seed):
    """The gradient of -log sigma(beta h) equals -beta sigma(-beta h) (grad log pi_w - grad log pi_l)."""
    rng = np.random.default_rng(seed)
    theta = torch.tensor(rng.normal(size=5), requires_grad=True)
    log_ref = torch.log_softmax(torch.tensor(rng.normal(size=5)), 0)
    beta, w, l = float(rng.uniform(0.1, 2)), 1, 3
    logp = torch.log_softmax(theta, 0)
    h = (logp[w] - log_ref[w]) - (logp[l] - log_ref[l])
    (g,) = torch.autograd.grad(-F.logsigmoid(beta * h), theta)
    p = torch.softmax(theta, 0).detach()
    grad_logp = lambda y: torch.eye(5, dtype=p.dtype)[y] - p      # noqa: E731  (d log softmax_y / d theta)
    want = -beta * torch.sigmoid(-beta * h.detach()) * (grad_logp(w) - grad_logp(l))
    assert torch.allclose(g, want, atol=1e-12)
    assert abs(float(g.sum())) < 1e-12                            # only relative logits move: mass shifts between w and l


@pytest.mark.parametrize("seed", [0, 1])
@checks("eq-online-dpo", "1c13e682")
def test_any_covering_sampler_has_the_kl_optimum_and_an_unseen_response_is_left_free(seed):
    rng = np.random.default_rng(seed)
    k, beta = 4, 0.5
    r = rng.normal(size=k)
    log_ref = np.log(rng.dirichlet(np.ones(k)))
    pref = expit(r[:, None] - r[None, :])                          # Bradley-Terry labels
    target = log_ref + r / beta
    target -= np.logaddexp.reduce(target)                          # pi_ref exp(r / beta) / Z
    for mu in (np.exp(log_ref), rng.dirichlet(np.ones(k))):        # offline (the reference) and another covering sampler
        fit = minimize(population_loss, np.zeros(k), args=(log_ref, mu, pref, beta), method="BFGS",
                       options={"gtol": 1e-10})
        logp = fit.x - np.logaddexp.reduce(fit.x)
        assert np.allclose(logp, target, atol=1e-4)
    # a sampler that never draws response 0: the loss does not depend on theta_0 at all
    mu = np.r_[0.0, rng.dirichlet(np.ones(k - 1))]
    theta = rng.normal(size=k)
    values = [population_loss(theta + np.r_[t, np.zeros(k - 1)], log_ref, mu, pref, beta) for t in (-3, 0, 5)]
    # the relative logits of the others are what matter: shifting theta_0 changes log Z for all, equally
    assert np.allclose(values, values[0], atol=1e-12)
    full = np.exp(log_ref)
    moved = [population_loss(theta + np.r_[t, np.zeros(k - 1)], log_ref, full, pref, beta) for t in (-3, 0, 5)]
    assert not np.allclose(moved, moved[0])                        # a covering sampler does constrain it


@pytest.mark.parametrize("seed", [0, 1, 2])
@checks("eq-rule-vote", "8b97bc8a")
def test_rule_vote_is_antisymmetric_and_reaches_one_only_when_every_weighted_rule_agrees(seed):
    rng = np.random.default_rng(seed)
    f = rng.integers(-2, 3, size=(5, 200, 2))                       # 5 rules, 200 pairs, scores of a and b
    w = rng.uniform(0, 2, size=5)
    w[0] = 0.0

    def vote(fa, fb):
        return 0.5 + 0.5 * (w[:, None] * np.sign(fa - fb)).sum(0) / w.sum()

    p, q = vote(f[..., 0], f[..., 1]), vote(f[..., 1], f[..., 0])
    assert np.allclose(p + q, 1.0) and (p >= 0).all() and (p <= 1).all()
    all_for_a = (f[1:, :, 0] > f[1:, :, 1]).all(0)                  # every rule of positive weight prefers a
    assert np.array_equal(np.isclose(p, 1.0), all_for_a)
    counted = np.array([sum(w[k] for k in range(5) if f[k, i, 0] > f[k, i, 1]) -
                        sum(w[k] for k in range(5) if f[k, i, 0] < f[k, i, 1]) for i in range(200)])
    assert np.allclose(p, 0.5 + 0.5 * counted / w.sum())


@checks("eq-bias-inherited", "4c8dd8f6")
def test_a_length_habit_tilts_the_optimum_and_a_random_order_offset_only_flattens_the_labels():
    rng = np.random.default_rng(0)
    k, beta, tau, lam = 6, 0.5, 0.25, 0.3
    r = rng.normal(scale=0.3, size=k)
    length = rng.integers(5, 30, size=k).astype(float)
    log_ref = np.log(rng.dirichlet(np.ones(k)))
    s = r / tau + lam * length
    mu = np.exp(log_ref)
    fit = minimize(population_loss, np.zeros(k), args=(log_ref, mu, expit(s[:, None] - s[None, :]), beta),
                   method="BFGS", options={"gtol": 1e-10})
    ratio = fit.x - np.logaddexp.reduce(fit.x) - log_ref
    assert np.allclose(ratio - ratio.mean(), (s - s.mean()) / beta, atol=1e-4)
    biased = np.exp(log_ref + s / beta - np.logaddexp.reduce(log_ref + s / beta))
    honest = np.exp(log_ref + r / tau / beta - np.logaddexp.reduce(log_ref + r / tau / beta))
    assert biased @ length > honest @ length                        # the habit makes the optimum longer
    # a position offset c under a random order: q(d) = (sigma(d + c) + sigma(d - c)) / 2 ranks like d, flatter at 0
    c, d = 1.0, np.linspace(-4, 4, 81)
    q = 0.5 * (expit(d + c) + expit(d - c))
    assert np.allclose(q + q[::-1], 1.0) and np.array_equal(np.sign(q - 0.5), np.sign(d))
    h = 1e-6
    slope = (0.5 * (expit(h + c) + expit(h - c)) - 0.5 * (expit(-h + c) + expit(-h - c))) / (2 * h)
    assert np.isclose(slope, expit(c) * (1 - expit(c)), rtol=1e-6) and slope < 0.25
    # and the population DPO optimum on such labels (small score gaps) keeps s's ranking but tilts less: its log
    # ratio is about 4 sigma(c)(1 - sigma(c)) s / beta instead of s / beta
    small = rng.normal(scale=0.3, size=k)
    gaps = small[:, None] - small[None, :]
    for c in (1.0, 2.0):
        fit = minimize(population_loss, np.zeros(k), args=(log_ref, mu, 0.5 * (expit(gaps + c) + expit(gaps - c)), beta),
                       method="BFGS", options={"gtol": 1e-10})
        tilt = fit.x - np.logaddexp.reduce(fit.x) - log_ref
        x, y = (small - small.mean()) / beta, tilt - tilt.mean()
        assert np.array_equal(np.argsort(y), np.argsort(small))
        assert np.isclose((x @ y) / (x @ x), 4 * expit(c) * (1 - expit(c)), rtol=0.05)


@pytest.mark.parametrize("c", [0.4, 1.0, -0.7])
@checks("eq-swap", "7444fae4")
def test_the_swap_averages_the_offset_out_and_consistency_is_a_margin_above_it(c):
    rng = np.random.default_rng(1)
    d = rng.normal(scale=2.0, size=2000)                            # s(a) - s(b)
    j_ab, j_ba = expit(d + c), expit(-d + c)
    p = 0.5 * (j_ab + 1 - j_ba)
    p_swapped = 0.5 * (j_ba + 1 - j_ab)
    assert np.allclose(p + p_swapped, 1.0)
    assert np.allclose(p, 0.5 * (expit(d + c) + expit(d - c)))
    assert np.array_equal(np.sign(p - 0.5), np.sign(d))
    consistent = (j_ab - 0.5) * (j_ba - 0.5) < 0
    assert np.array_equal(consistent, np.abs(d) > abs(c))
    assert (j_ab > 0.5).mean() != pytest.approx((p > 0.5).mean(), abs=0.02)   # one order alone is biased
