"""Numerical checks of chapter 8 (`lectures/08_group_rl.md`): group baselines, GRPO's normalisations, IPO, KTO,
the over-optimisation laws and best-of-n from a pool.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lecture_links.py``) and compares the
lecture's statement with an independent computation: exhaustive enumeration, binomial sums, a generic optimiser,
finite differences, autograd on a direct implementation. Where the lecture's formula is also the course's code
(`rlcourse.group_rl`), the code is checked against the brute force too.
"""
from __future__ import annotations

import itertools
import sys
from math import comb
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.optimize import minimize_scalar
from scipy.special import expit, log_expit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_links import checks  # noqa: E402

from rlcourse import group_rl as G  # noqa: E402


def softmax(theta):
    p = np.exp(theta - theta.max())
    return p / p.sum()


def all_groups(k: int, g: int) -> np.ndarray:
    """Every ordered group of ``g`` answers out of ``k``, shape (k^g, g)."""
    return np.array(list(itertools.product(range(k), repeat=g)))


def expected_group_update(advantage, theta, r, g):
    """E over all groups of (1/G) sum_i A_i grad log pi(y_i), by enumeration (softmax policy on k answers)."""
    p = softmax(theta)
    groups = all_groups(len(theta), g)
    weight = p[groups].prod(axis=1)
    adv = advantage(r[groups])
    score = np.eye(len(theta))[groups] - p                      # grad_theta log softmax, (k^g, g, k)
    return (weight[:, None] * (adv[..., None] * score).mean(axis=1)).sum(axis=0)


def true_gradient(theta, r):
    p = softmax(theta)
    return p * (r - p @ r)


@pytest.mark.parametrize("seed", [0, 1, 2])
@checks("eq-pg-baseline", "39b5730d")
def test_any_constant_baseline_gives_the_gradient(seed):
    """E[(r - b) grad log pi] = grad J for constant b, by enumeration; a response-dependent b does not."""
    rng = np.random.default_rng(seed)
    theta, r = rng.normal(size=4), rng.normal(size=4)
    p = softmax(theta)
    score = np.eye(4) - p
    h = 1e-6
    fd = np.array([(softmax(theta + h * e) @ r - softmax(theta - h * e) @ r) / (2 * h) for e in np.eye(4)])
    for b in (0.0, 3.0, -rng.exponential()):
        assert np.allclose((p[:, None] * (r - b)[:, None] * score).sum(0), fd, atol=1e-8)
    bad = (p[:, None] * (r - r / 2)[:, None] * score).sum(0)       # b(y) = r(y)/2 halves it
    assert not np.allclose(bad, fd, atol=1e-6)


@pytest.mark.parametrize("g", [2, 3, 4])
@checks("eq-group-advantages", "28b57768")
@checks("eq-rloo-unbiased", "91995dca")
def test_leave_one_out_is_unbiased_and_the_mean_shrinks_by_g_minus_1_over_g(g):
    rng = np.random.default_rng(g)
    theta, r = rng.normal(size=3), rng.uniform(-1, 1, size=3)

    def rloo(x):
        return x - (x.sum(1, keepdims=True) - x) / (x.shape[1] - 1)

    def centred(x):
        return x - x.mean(1, keepdims=True)

    def grpo(x):
        s = x.std(1, ddof=1, keepdims=True)
        return np.where(s > 0, centred(x) / np.where(s > 0, s, 1.0), 0.0)

    true = true_gradient(theta, r)
    assert np.allclose(expected_group_update(rloo, theta, r, g), true, atol=1e-12)
    assert np.allclose(expected_group_update(centred, theta, r, g), (g - 1) / g * true, atol=1e-12)
    x = rng.normal(size=(5, g))
    assert np.allclose(centred(x), (g - 1) / g * rloo(x))
    # standardising is not a uniform rescaling of the true gradient
    ratio = expected_group_update(grpo, theta, r, g) / true
    assert np.ptp(ratio) > 1e-3
    # and equal rewards give zero advantages under both
    same = np.full((1, g), rng.normal())
    assert np.allclose(rloo(same), 0) and np.allclose(grpo(same), 0)


@pytest.mark.parametrize("p", [0.05, 0.3, 0.5, 0.9])
@checks("eq-grpo-binary", "4a14fc71")
def test_grpo_on_a_pass_fail_reward_reweights_by_one_over_sqrt_p_1_minus_p(p):
    """The exact expected GRPO update (binomial sum over the number of correct answers) tends to sqrt(p(1-p))."""
    def exact(g):
        k = np.arange(g + 1)
        pk = np.array([comb(g, int(j)) for j in k], dtype=float) * p ** k * (1 - p) ** (g - k)
        s = np.sqrt(k * (g - k) / (g * (g - 1)))
        term = np.where(s > 0, k * (g - k) / (g ** 2 * np.where(s > 0, s, 1.0)), 0.0)
        return float((pk * term).sum())

    # the summand is the group average of A_i (y_i - p), checked on one group by direct computation
    rng = np.random.default_rng(0)
    y = (rng.random(9) < 0.5).astype(float)
    a = (y - y.mean()) / y.std(ddof=1)
    k = y.sum()
    assert np.isclose((a * (y - p)).mean(), k * (9 - k) / (81 * y.std(ddof=1)))
    limit = np.sqrt(p * (1 - p))
    assert abs(exact(1000) - limit) < 0.02 * limit + 1e-3
    assert abs(exact(1000) - limit) < abs(exact(10) - limit) + 1e-12
    true = p * (1 - p)
    assert not np.isclose(limit, true)


def grpo_binary_update(p: float, g: int) -> float:
    """The exact expected GRPO update of a one-logit pass/fail policy, E[k(G-k)/(G^2 s)] over k ~ Binomial(G, p)."""
    k = np.arange(g + 1)
    pk = np.array([comb(g, int(j)) for j in k], dtype=float) * p ** k * (1 - p) ** (g - k)
    s = np.sqrt(k * (g - k) / (g * (g - 1)))
    return float((pk * np.where(s > 0, k * (g - k) / (g ** 2 * np.where(s > 0, s, 1.0)), 0.0)).sum())


def test_small_groups_blunt_grpos_reweighting_by_the_factors_the_lecture_quotes():
    """Section "What the normalisations do": the update over the true gradient p(1-p) at G = 4 and 64, as quoted
    there (and, for G = 4, in chapter 9's binary groups), against a Monte Carlo of GRPO's own advantages; it
    approaches 1/sqrt(p(1-p)) only as G grows."""
    lectures = Path(__file__).resolve().parents[2] / "lectures"
    chapter_8, chapter_9 = (lectures / "08_group_rl.md").read_text(), (lectures / "09_verifiers.md").read_text()
    for g, quoted in ((4, {0.1: "1.46", 0.5: "1.40"}), (64, {0.1: "3.23", 0.5: "1.97"})):
        for p, figure in quoted.items():
            assert f"{grpo_binary_update(p, g) / (p * (1 - p)):.2f}" == figure and f"${figure}$" in chapter_8
            assert g != 4 or f"${figure}$ at $p = {p}$" in chapter_9
    rng = np.random.default_rng(0)
    y = (rng.random((200_000, 4)) < 0.1).astype(float)               # groups of four passes and fails at p = 0.1
    s = y.std(axis=1, ddof=1, keepdims=True)
    a = np.where(s > 0, (y - y.mean(axis=1, keepdims=True)) / np.where(s > 0, s, 1.0), 0.0)
    sampled = (a * (y - 0.1)).mean(axis=1)                            # (1/G) sum_i A_i d/dtheta log pi(y_i)
    assert abs(sampled.mean() - grpo_binary_update(0.1, 4)) < 4 * sampled.std() / np.sqrt(len(sampled))
    ratios = [grpo_binary_update(0.1, g) / 0.09 for g in (4, 8, 64, 1000)]
    assert all(np.diff(ratios) > 0) and abs(ratios[-1] - 1 / np.sqrt(0.09)) < 0.01


@pytest.mark.parametrize("seed", [0, 1])
def test_the_variance_minimising_constant_baseline_is_not_the_expected_reward(seed):
    """Section "Baselines": b* = E[r |g|^2] / E[|g|^2] minimises E|(r - b) g|^2 (checked by a generic optimiser on a
    softmax policy); on the one-logit pass/fail policy it is 1 - p, not p, and leaves no variance."""
    rng = np.random.default_rng(seed)
    theta, r = rng.normal(size=6), rng.normal(size=6)
    pi = softmax(theta)
    score2 = ((np.eye(6) - pi) ** 2).sum(axis=1)                      # |grad log pi(y)|^2 for each answer y

    def second_moment(b):
        return float(pi @ ((r - b) ** 2 * score2))

    best = minimize_scalar(second_moment).x
    assert np.isclose(best, pi @ (r * score2) / (pi @ score2), atol=1e-6)
    assert second_moment(best) <= second_moment(pi @ r)
    for p in (0.1, 0.5, 0.9):                                         # pass (r = 1, score 1 - p) and fail (r = 0, -p)
        prob, reward, score = np.array([p, 1 - p]), np.array([1.0, 0.0]), np.array([1 - p, -p])
        b_star = prob @ (reward * score ** 2) / (prob @ score ** 2)
        assert np.isclose(b_star, 1 - p) and (p == 0.5 or not np.isclose(b_star, prob @ reward))
        per_sample = (reward - b_star) * score
        assert np.allclose(per_sample, p * (1 - p)), "every sample gives the true gradient"


def _losses(lp, lp_old, lp_ref, adv, mask, eps, beta, t_const):
    ratio = torch.exp(lp - lp_old)
    a = adv[:, None]
    per = torch.maximum(-ratio * a, -ratio.clamp(1 - eps, 1 + eps) * a)
    per = per + beta * (torch.exp(lp_ref - lp) - (lp_ref - lp) - 1)
    per = per * mask
    b = mask.shape[0]
    return (per.sum(1) / mask.sum(1)).sum() / b, per.sum() / (b * t_const)


@checks("eq-grpo-loss", "7a4e649a")
@checks("eq-token-weights", "43451a89")
def test_token_weights_of_the_two_normalisations():
    rng = np.random.default_rng(3)
    b, t = 4, 9
    lengths = np.array([2, 9 - 1, 5, 3])
    mask = torch.as_tensor((np.arange(t)[None] >= 1) & (np.arange(t)[None] < 1 + lengths[:, None]), dtype=torch.float64)
    lp_old = torch.as_tensor(-rng.exponential(size=(b, t)))
    adv = torch.as_tensor(rng.normal(size=b))
    lp = lp_old.clone().requires_grad_()
    g_grpo, = torch.autograd.grad(_losses(lp, lp_old, lp_old, adv, mask, 0.2, 0.0, t)[0], lp)
    g_dr, = torch.autograd.grad(_losses(lp, lp_old, lp_old, adv, mask, 0.2, 0.0, t)[1], lp)
    want_grpo = -(adv[:, None] / (b * mask.sum(1, keepdim=True))) * mask
    want_dr = -(adv[:, None] / (b * t)) * mask
    assert torch.allclose(g_grpo, want_grpo) and torch.allclose(g_dr, want_dr)
    # the weight per token falls with the length under GRPO and not under Dr. GRPO
    assert len(set(np.round((g_dr[mask > 0] / -adv.repeat_interleave(torch.as_tensor(lengths))).numpy(), 12))) == 1
    # away from rho = 1 and with the KL term: autograd through the definition agrees with finite differences
    lp1 = lp_old + torch.as_tensor(rng.normal(scale=0.3, size=(b, t)))
    lp_ref = lp_old + torch.as_tensor(rng.normal(scale=0.3, size=(b, t)))
    h = 1e-6
    for which in (0, 1):
        f = lambda x: float(_losses(x, lp_old, lp_ref, adv, mask, 0.2, 0.1, t)[which])  # noqa: E731
        x = lp1.clone().requires_grad_()
        auto, = torch.autograd.grad(_losses(x, lp_old, lp_ref, adv, mask, 0.2, 0.1, t)[which], x)
        for (i, j) in [(0, 1), (1, 5), (3, 2)]:
            e = torch.zeros(b, t, dtype=torch.float64)
            e[i, j] = h
            assert np.isclose((f(lp1 + e) - f(lp1 - e)) / (2 * h), float(auto[i, j]), rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("beta", [0.1, 0.5, 2.0])
@checks("eq-ipo", "3b902791")
def test_ipo_and_dpo_optimal_margins(beta):
    """The minimisers of the expected losses, by a generic optimiser, against the closed forms."""
    for q in (0.55, 0.7, 0.9):
        def ipo(h):
            return q * (h - 1 / (2 * beta)) ** 2 + (1 - q) * (-h - 1 / (2 * beta)) ** 2

        def dpo(h):
            return -q * log_expit(beta * h) - (1 - q) * log_expit(-beta * h)

        h_ipo = minimize_scalar(ipo, bounds=(-100, 100), method="bounded", options={"xatol": 1e-10}).x
        h_dpo = minimize_scalar(dpo, bounds=(-100, 100), method="bounded", options={"xatol": 1e-10}).x
        assert np.isclose(h_ipo, (q - 0.5) / beta, atol=1e-6)
        assert np.isclose(h_dpo, np.log(q / (1 - q)) / beta, atol=1e-5)
    # q = 1: DPO's loss keeps falling (no finite minimiser); IPO's minimiser is 1/(2 beta)
    hs = np.array([1.0, 10.0, 100.0]) / beta
    assert np.all(np.diff(-log_expit(beta * hs)) < 0)
    h1 = minimize_scalar(lambda h: (h - 1 / (2 * beta)) ** 2, bounds=(-100, 100), method="bounded").x
    assert np.isclose(h1, 1 / (2 * beta), atol=1e-5)


@checks("eq-kto", "608ea775")
@checks("eq-kto-grad", "f96158a4")
def test_kto_gradient_and_saturation():
    rng = np.random.default_rng(5)
    beta, z0 = 0.7, 0.4
    lam = {True: 1.3, False: 2.1}

    def loss(r, desirable):
        u = beta * (r - z0) if desirable else beta * (z0 - r)
        return lam[desirable] - lam[desirable] * expit(u)

    for desirable in (True, False):
        for r in rng.normal(scale=2, size=5):
            h = 1e-6
            fd = (loss(r + h, desirable) - loss(r - h, desirable)) / (2 * h)
            u = beta * (r - z0) if desirable else -beta * (r - z0)
            stated = (-1 if desirable else 1) * lam[desirable] * beta * expit(u) * (1 - expit(u))
            assert np.isclose(fd, stated, rtol=1e-6, atol=1e-10)
        # saturation: the gradient is largest at the reference point and vanishes far from it
        grads = [abs(loss(z0 + d + 1e-6, desirable) - loss(z0 + d - 1e-6, desirable)) / 2e-6 for d in (0.0, 5.0, 50.0)]
        assert grads[0] > grads[1] > grads[2] and grads[2] < 1e-8
        assert np.isclose(grads[0], lam[desirable] * beta / 4, rtol=1e-5)


@pytest.mark.parametrize("alpha,beta", [(0.5, 0.1), (1.2, 0.7), (0.3, 0.05)])
@checks("eq-law-peaks", "2fbae672")
def test_law_peaks_by_a_generic_optimiser_and_the_fits_recover_coefficients(alpha, beta):
    bon = minimize_scalar(lambda d: -G.bon_law(d, alpha, beta), bounds=(1e-6, 1e3), method="bounded",
                          options={"xatol": 1e-10})
    rl = minimize_scalar(lambda d: -G.rl_law(d, alpha, beta), bounds=(1e-6, 1e3), method="bounded",
                         options={"xatol": 1e-10})
    assert np.isclose(bon.x, alpha / (2 * beta), rtol=1e-5) and np.isclose(G.bon_law_peak(alpha, beta), alpha / (2 * beta))
    assert np.isclose(rl.x, np.exp(alpha / beta - 1), rtol=1e-5) and np.isclose(G.rl_law_peak(alpha, beta), rl.x, rtol=1e-5)
    assert np.isclose(-bon.fun, alpha ** 2 / (4 * beta), rtol=1e-8)
    assert np.isclose(-rl.fun, beta * np.exp(alpha / beta - 1), rtol=1e-6)
    d = np.linspace(0.1, 3.0, 12)
    assert np.allclose(G.fit_bon_law(d, G.bon_law(d, alpha, beta)), (alpha, beta))
    assert np.allclose(G.fit_rl_law(d, G.rl_law(d, alpha, beta)), (alpha, beta))
    assert np.isclose(G.bon_kl_formula(G.n_for_kl(2.0)), 2.0)


@pytest.mark.parametrize("m,n", [(7, 1), (7, 3), (8, 8), (9, 4)])
@checks("eq-bon-pool", "439aa4eb")
def test_best_of_n_from_a_pool_by_enumerating_subsets(m, n):
    rng = np.random.default_rng(m * 10 + n)
    select, value = rng.normal(size=(2, m)), rng.normal(size=(2, m))
    brute = np.array([np.mean([value[b][list(s)][np.argmax(select[b][list(s)])]
                               for s in itertools.combinations(range(m), n)]) for b in range(2)])
    assert np.allclose(G.best_of_n_from_pool(select, value, n), brute)
    order = np.argsort(select[0])
    formula = sum(comb(k - 1, n - 1) / comb(m, n) * value[0][order[k - 1]] for k in range(n, m + 1))
    assert np.isclose(formula, brute[0])


@pytest.mark.parametrize("n", [1, 2, 3, 5])
@checks("eq-bon-ties", "881f65dd")
def test_best_of_n_kl_with_ties_by_enumerating_draws(n):
    """Exact KL over responses (all ordered n-tuples of draws, ties broken uniformly) against the atom formula."""
    scores = np.array([0.0, 1.0, 1.0, 2.0, 2.0, 2.0])          # six equally likely responses, two tied atoms
    m = len(scores)
    prob = np.zeros(m)
    for draw in itertools.product(range(m), repeat=n):
        best = max(scores[list(draw)])
        winners = [i for i in draw if scores[i] == best]
        for i in winners:
            prob[i] += (1 / m) ** n / len(winners)
    keep = prob > 0
    kl = float(np.sum(prob[keep] * np.log(prob[keep] * m)))
    assert np.isclose(G.best_of_n_kl(scores, n), kl)
    assert kl <= -np.log(3 / 6) + 1e-12                          # the bound -log q_K (top atom has mass 1/2)
    assert kl <= G.bon_kl_formula(n) + 1e-12
    # without ties, and a fine grid, the formula is approached
    assert np.isclose(G.best_of_n_kl(np.arange(20000.0), n), G.bon_kl_formula(n), atol=1e-3)
