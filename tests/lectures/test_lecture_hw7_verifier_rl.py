"""Numerical checks of chapter 9 (`lectures/09_verifiers.md`): pass@k's estimator, expert iteration as EM, and the
group advantages of binary rewards.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lectures/lecture_links.py``) and compares
the lecture's statement with an independent computation: enumeration of subsets and of groups, exact rational
arithmetic, finite differences, simulation.
"""
from __future__ import annotations

import itertools
import sys
from fractions import Fraction
from math import comb
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_links import checks  # noqa: E402


def estimator(n: int, c: int, k: int) -> Fraction:
    return 1 - Fraction(comb(n - c, k), comb(n, k))


@pytest.mark.parametrize("n", [3, 5, 7])
@checks("eq-passk", "f4626e7d")
def test_the_estimator_is_the_subset_average_and_unbiased(n):
    """The estimate equals the average over all k-subsets of 'holds a pass', and its Binomial expectation is pass@k
    exactly (rational arithmetic); the plug-in's expectation is below it for k >= 2."""
    rng = np.random.default_rng(n)
    for _ in range(5):
        hits = rng.integers(0, 2, size=n)
        c = int(hits.sum())
        for k in range(1, n + 1):
            subsets = [max(hits[list(s)]) for s in itertools.combinations(range(n), k)]
            assert Fraction(sum(int(x) for x in subsets), len(subsets)) == estimator(n, c, k)
    p = Fraction(3, 10)
    for k in range(1, n + 1):
        mean = sum(comb(n, c) * p ** c * (1 - p) ** (n - c) * estimator(n, c, k) for c in range(n + 1))
        assert mean == 1 - (1 - p) ** k
        plug = sum(comb(n, c) * p ** c * (1 - p) ** (n - c) * (1 - (1 - Fraction(c, n)) ** k) for c in range(n + 1))
        assert (plug < mean) if k >= 2 else (plug == mean)


@checks("eq-passk-product", "cdbcc893")
def test_the_product_form_equals_the_ratio_and_survives_large_n():
    for n in range(1, 30):
        for c in range(n + 1):
            for k in range(1, n + 1):
                ratio = Fraction(comb(n - c, k), comb(n, k))
                prod = Fraction(1)
                for i in range(n - c + 1, n + 1):
                    prod *= 1 - Fraction(k, i)
                assert (prod if n - c >= k else 0) == ratio, (n, c, k)
    n, c, k = 20000, 7, 5000                       # comb(n, k) has thousands of digits; the product is a float loop
    prod = np.prod(1 - k / np.arange(n - c + 1, n + 1))
    assert np.isfinite(prod) and abs(prod - float(Fraction(comb(n - c, k), comb(n, k)))) < 1e-12


@checks("eq-passk-limits", "9b771e13")
def test_the_two_ends_of_the_curve():
    rng = np.random.default_rng(0)
    p = np.where(rng.random(50) < 0.3, 0.0, rng.beta(0.5, 0.5, size=50))
    assert np.isclose(np.mean(1 - (1 - p) ** 1), p.mean())
    big = np.mean(1 - (1 - p) ** 10**6)
    assert abs(big - np.mean(p > 0)) < 1e-3
    sharp = np.where(p > 0.5, 1.0, np.where(p < 0.1, 0.0, p))      # sharpened: up where good, gone where rare
    assert sharp.mean() > p.mean() and np.mean(sharp > 0) < np.mean(p > 0)


def _policy(theta):
    e = np.exp(theta - theta.max())
    return e / e.sum()


@checks("eq-ei-em", "cec39170")
def test_the_lower_bound_holds_for_any_q_and_is_tight_at_the_conditioned_policy():
    rng = np.random.default_rng(1)
    theta = rng.normal(size=6)
    r = np.array([1, 0, 1, 0, 0, 1.0])
    pi = _policy(theta)
    lhs = np.log(pi @ r)
    for _ in range(20):
        q = rng.dirichlet(np.ones(3))
        qq = np.zeros(6)
        qq[r > 0] = q
        bound = qq[r > 0] @ np.log(pi[r > 0]) - qq[r > 0] @ np.log(qq[r > 0])
        assert bound <= lhs + 1e-12
    post = pi * r / (pi @ r)
    m = r > 0
    assert np.isclose(post[m] @ np.log(pi[m]) - post[m] @ np.log(post[m]), lhs)
    # the M-step of one EM round does not lower log P(pass): maximise E_q[log pi] over the logits
    from scipy.optimize import minimize
    res = minimize(lambda t: -(post[m] @ np.log(_policy(t)[m])), theta, method="BFGS")
    assert np.log(_policy(res.x) @ r) >= lhs - 1e-9


@checks("eq-ei-gradient", "2c6ad6ac")
def test_filtered_likelihood_gradient_is_the_gradient_of_log_pass_rate():
    rng = np.random.default_rng(2)
    theta = rng.normal(size=5)
    r = np.array([0, 1, 1, 0, 0.0])
    pi = _policy(theta)
    post = pi * r / (pi @ r)
    score = np.eye(5) - pi                                    # d log pi_y / d theta, row y
    filtered = post @ score
    h = 1e-6
    fd = np.array([(np.log(_policy(theta + h * e) @ r) - np.log(_policy(theta - h * e) @ r)) / (2 * h) for e in np.eye(5)])
    assert np.allclose(filtered, fd, atol=1e-8)
    assert np.allclose(filtered, (pi * (r - pi @ r)) / (pi @ r), atol=1e-12)      # grad P / P


@pytest.mark.parametrize("g", [3, 20])
def test_keeping_every_pass_weights_by_pass_rate_and_a_cap_of_one_by_one_minus_miss_probability(g):
    """Section "Expert iteration": over groups of G samples, the expected summed log-likelihood gradient of the kept
    samples is G grad P when every pass is kept, and (1 - (1 - P)^G) grad log P with at most one kept (the first
    pass), so a cap restores the log weighting only where G P >> 1. By simulation against the closed forms."""
    rng = np.random.default_rng(g)
    theta = np.array([-2.0, -0.5, 0.3, 1.0, -3.0])
    r = np.array([1, 0, 0, 0, 1.0])                                   # answers 0 and 4 pass
    pi = _policy(theta)
    p = pi @ r
    score = np.eye(5) - pi
    grad_p = pi * (r - p)
    groups = rng.choice(5, size=(100_000, g), p=pi)
    passed = r[groups] > 0
    every = (score[groups] * passed[..., None]).sum(axis=1)
    first = np.argmax(passed, axis=1)
    capped = score[groups[np.arange(len(groups)), first]] * passed.any(axis=1)[:, None]
    for sampled, closed in ((every, g * grad_p), (capped, (1 - (1 - p) ** g) * grad_p / p)):
        se = sampled.std(axis=0) / np.sqrt(len(sampled))
        assert np.all(np.abs(sampled.mean(axis=0) - closed) < 5 * se + 1e-9)
    if g * p < 1:                                                      # rarely solved: far below the log weighting
        assert 1 - (1 - p) ** g < 0.7


def _explicit(k, g, kind, eps=0.0):
    rew = np.r_[np.ones(k), np.zeros(g - k)]
    if kind == "grpo":
        a = (rew - rew.mean()) / (rew.std(ddof=1) + eps)
    elif kind == "dr_grpo":
        a = rew - rew.mean()
    else:
        a = rew - (rew.sum() - rew) / (g - 1)
    return a[0], a[-1]


@checks("eq-binary-weights", "0033cd03")
def test_binary_advantages_and_their_expected_updates():
    for g in (2, 3, 8):
        for k in range(1, g):
            p = k / g
            s = np.sqrt(k * (g - k) / (g * (g - 1)))
            assert np.allclose(_explicit(k, g, "grpo", 1e-4), ((1 - p) / (s + 1e-4), -p / (s + 1e-4)))
            assert np.allclose(_explicit(k, g, "dr_grpo"), (1 - p, -p))
            assert np.allclose(_explicit(k, g, "rloo"), ((g - k) / (g - 1), -k / (g - 1)))
    # expected update of a one-logit coin, k ~ Binomial(G, p): RLOO p(1-p), Dr. GRPO (G-1)/G p(1-p), GRPO -> sqrt(p(1-p))
    for g, p in ((4, 0.2), (8, 0.6)):
        def update(kind):
            tot = 0.0
            for k in range(1, g):
                a_pass, a_fail = _explicit(k, g, kind)
                tot += comb(g, k) * p ** k * (1 - p) ** (g - k) * (k * a_pass * (1 - p) - (g - k) * a_fail * p) / g
            return tot
        assert np.isclose(update("rloo"), p * (1 - p))
        assert np.isclose(update("dr_grpo"), (g - 1) / g * p * (1 - p))
    for p in (0.1, 0.5):
        g = 4000
        ks = np.arange(1, g)
        from scipy.stats import binom
        w = binom.pmf(ks, g, p)
        grpo = (w * ks * (g - ks) / (g ** 2 * np.sqrt(ks * (g - ks) / (g * (g - 1))))).sum()
        assert abs(grpo - np.sqrt(p * (1 - p))) < 2e-3


@checks("eq-equal-groups", "442e41cb")
def test_all_equal_groups_by_simulation_and_minimum():
    rng = np.random.default_rng(3)
    for g, p in ((4, 0.1), (8, 0.5), (8, 0.9)):
        k = rng.binomial(g, p, size=200_000)
        assert abs(np.mean((k == 0) | (k == g)) - (p ** g + (1 - p) ** g)) < 4e-3
    grid = np.linspace(0.001, 0.999, 999)
    f = grid ** 8 + (1 - grid) ** 8
    assert abs(grid[f.argmin()] - 0.5) < 1e-9 and np.isclose(f.min(), 2.0 ** -7)
