"""Numerical checks of the chapter `lectures/01b_multimodal.md` (hw1b): the L2 clone's conditional mean, the
mixture likelihood, straight paths and their marginal velocity, the continuity equation, the conditional
flow-matching loss and its gradient, Euler sampling and the chunk schedule.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lecture_links.py``) and compares the
lecture's statement with an independent computation: a generic optimiser, direct summation of densities,
Monte Carlo, finite differences, or a step-by-step simulation. The flow is that of a one-dimensional mixture of
two Gaussians (the chapter's figures), whose marginal velocity has a closed form.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.special import logsumexp
from scipy.stats import norm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_links import checks  # noqa: E402

W, MU, S = np.array([0.3, 0.7]), np.array([-1.0, 0.8]), 0.2        # p_1: a two-component mixture in 1-D


def sample_pairs(rng, n):
    """(a_0, a_1): independent draws of N(0, 1) and of p_1."""
    m = rng.choice(2, size=n, p=W)
    return rng.normal(size=n), MU[m] + S * rng.normal(size=n)


def density(a, t):
    """p_t(a) of a_t = (1 - t) a_0 + t a_1, summed component by component."""
    a, t = np.broadcast_arrays(np.asarray(a, float), np.asarray(t, float))
    var = (1 - t) ** 2 + t**2 * S**2
    return sum(w * norm.pdf(a, t * mu, np.sqrt(var)) for w, mu in zip(W, MU))


def velocity(a, t):
    """u_t(a) in closed form: per component the Gaussian regression of a_1 - a_0 on a_t, weighted by p(m | a_t)."""
    a, t = np.broadcast_arrays(np.asarray(a, float), np.asarray(t, float))
    var = (1 - t) ** 2 + t**2 * S**2
    parts = [w * norm.pdf(a, t * mu, np.sqrt(var)) for w, mu in zip(W, MU)]
    cond = [mu + (t * S**2 - (1 - t)) / var * (a - t * mu) for mu in MU]
    return sum(p * c for p, c in zip(parts, cond)) / sum(parts)


@checks("eq-mm-conditional-mean", "4a23bd42")
def test_least_squares_learns_the_conditional_mean():
    rng = np.random.default_rng(0)
    obs = rng.integers(0, 5, size=400)
    actions = np.where(rng.random(400) < 0.2 + 0.15 * obs, 1.0, -1.0) + 0.1 * rng.normal(size=400)
    fit = minimize(lambda f: np.mean((actions - f[obs]) ** 2), np.zeros(5), method="BFGS").x
    means = np.array([actions[obs == o].mean() for o in range(5)])
    assert np.allclose(fit, means, atol=1e-5)
    # the two-point case: +1 with probability q, -1 otherwise
    for q in (0.5, 0.8):
        best = minimize(lambda c: q * (1 - c[0]) ** 2 + (1 - q) * (1 + c[0]) ** 2, [0.3]).x[0]
        assert abs(best - (2 * q - 1)) < 1e-6


@checks("eq-mm-mixture-nll", "0a12babe")
def test_mixture_likelihood_in_log_space_equals_the_summed_density():
    rng = np.random.default_rng(1)
    M, D = 3, 2
    logits, mu, s = rng.normal(size=M), rng.normal(size=(M, D)), rng.uniform(-0.8, 0.4, size=(M, D))
    a = rng.normal(size=D)
    lecture = -logsumexp(logits - logsumexp(logits)
                         - (((a - mu) ** 2) / (2 * np.exp(2 * s)) + s + 0.5 * np.log(2 * np.pi)).sum(axis=1))
    weights = np.exp(logits) / np.exp(logits).sum()
    direct = -np.log(sum(w * np.prod(norm.pdf(a, m, np.exp(sd))) for w, m, sd in zip(weights, mu, s)))
    assert abs(lecture - direct) < 1e-10
    far = a + 300.0                                       # where the summed density underflows, the log form does not
    assert np.isfinite(-logsumexp(logits - logsumexp(logits) - (((far - mu) ** 2) / (2 * np.exp(2 * s)) + s).sum(axis=1)))


@checks("eq-mm-straight-path", "68642890")
def test_straight_paths_move_at_a1_minus_a0_and_have_the_stated_marginal():
    rng = np.random.default_rng(2)
    a0, a1 = sample_pairs(rng, 200_000)
    t, h = 0.37, 1e-6
    path = lambda s: (1 - s) * a0 + s * a1  # noqa: E731
    assert np.allclose((path(t + h) - path(t - h)) / (2 * h), a1 - a0, atol=1e-6)
    at = path(t)
    grid = np.linspace(-2.5, 2.5, 26)
    hist, edges = np.histogram(at, bins=grid, density=True)
    centres = (edges[1:] + edges[:-1]) / 2
    assert np.max(np.abs(hist - density(centres, t))) < 0.02


@pytest.mark.slow  # Monte Carlo over 2 million pairs
@checks("eq-mm-marginal-velocity", "66369006")
def test_marginal_velocity_is_the_average_velocity_through_each_point():
    rng = np.random.default_rng(3)
    a0, a1 = sample_pairs(rng, 2_000_000)
    for t in (0.2, 0.6, 0.9):
        at = (1 - t) * a0 + t * a1
        for a in (-0.8, 0.0, 0.5):
            near = (a1 - a0)[np.abs(at - a) < 0.01]
            standard_error = near.std() / np.sqrt(len(near))
            assert len(near) > 100 and abs(near.mean() - velocity(a, t)) < 4 * standard_error + 0.01, (t, a)


@checks("eq-mm-continuity", "c46d3717")
def test_density_and_velocity_satisfy_the_continuity_equation():
    a = np.linspace(-2.0, 2.0, 401)
    for t in (0.1, 0.5, 0.85):
        h = 1e-5
        dp_dt = (density(a, t + h) - density(a, t - h)) / (2 * h)
        flux = lambda x: density(x, t) * velocity(x, t)  # noqa: E731
        div = (flux(a + h) - flux(a - h)) / (2 * h)
        assert np.max(np.abs(dp_dt + div)) < 1e-5 * max(1.0, np.max(np.abs(dp_dt)))
        wrong = lambda x: density(x, t) * (velocity(x, t) + 0.1)  # noqa: E731 - a shifted field breaks it
        assert np.max(np.abs(dp_dt + (wrong(a + h) - wrong(a - h)) / (2 * h))) > 1e-2


def _losses_and_gradients(theta, a0, a1, t):
    """L_CFM, L_FM and their gradients for v(a, t) = theta_0 + theta_1 a + theta_2 t (Monte Carlo over the pairs)."""
    at = (1 - t) * a0 + t * a1
    v = theta[0] + theta[1] * at + theta[2] * t
    features = np.stack([np.ones_like(at), at, t])
    r_cfm, r_fm = v - (a1 - a0), v - velocity(at, t)
    return (np.mean(r_cfm**2), np.mean(r_fm**2), 2 * (features * r_cfm).mean(axis=1), 2 * (features * r_fm).mean(axis=1))


@pytest.mark.slow  # Monte Carlo over a million pairs
@checks("eq-mm-cfm-loss", "28e1590a")
@checks("eq-mm-cfm-gradient", "156c77b9")
def test_conditional_loss_differs_from_the_marginal_one_by_a_constant():
    rng = np.random.default_rng(4)
    n = 1_000_000
    a0, a1 = sample_pairs(rng, n)
    t = rng.uniform(size=n)
    gaps = []
    for theta in (np.array([0.2, -0.5, 1.0]), np.array([-1.0, 0.3, 0.1]), rng.normal(size=3)):
        cfm, fm, g_cfm, g_fm = _losses_and_gradients(theta, a0, a1, t)
        gaps.append(cfm - fm)
        assert np.allclose(g_cfm, g_fm, atol=0.02 * (1 + np.abs(g_fm).max())), (g_cfm, g_fm)
    assert np.ptp(gaps) < 0.01 and min(gaps) > 0.1     # the same positive constant for every field


@checks("eq-mm-euler", "397b5beb")
def test_euler_steps_one_step_is_the_mean_and_many_steps_sample_the_modes():
    rng = np.random.default_rng(5)
    a0 = rng.normal(size=10_000)

    def euler(a, K):
        for j in range(K):
            a = a + velocity(a, j / K) / K
        return a

    assert np.allclose(euler(a0, 1), W @ MU, atol=1e-9)             # u_0(a) = E[a_1] - a
    samples = euler(a0, 100)
    m = rng.choice(2, size=200_000, p=W)
    reference = MU[m] + S * rng.normal(size=200_000)
    for q in (0.1, 0.2, 0.45, 0.6, 0.9):                            # away from 0.3, the gap between the modes
        assert abs(np.quantile(samples, q) - np.quantile(reference, q)) < 0.05, q
    lam, K, a = -0.8, 7, 1.3                                         # a linear field: the iterates in closed form
    for j in range(K):
        a = a + lam * a / K
    assert np.isclose(a, (1 + lam / K) ** K * 1.3) and abs(a - np.exp(lam) * 1.3) < 0.05


@checks("eq-mm-chunk-index", "9bda063e")
def test_the_chunk_schedule_is_what_a_planner_that_replans_every_k_steps_runs():
    for H, k, T in ((4, 2, 11), (5, 5, 13), (3, 1, 7), (8, 3, 20)):
        chunks, executed, current, used = [], [], None, 0
        for t in range(T):                        # a simulation: plan when the current chunk's k actions are used up
            if current is None or used == k:
                current, used = [(len(chunks), j) for j in range(H)], 0
                chunks.append(t)
            executed.append(current[used])
            used += 1
        assert executed == [(t // k, t - k * (t // k)) for t in range(T)]
        assert chunks == list(range(0, T, k))     # chunk i is planned from the observation at step i k


def test_the_chapters_averaging_table_is_the_benchmarks():
    """The table of sec-mm-bites quotes bench/results/hw1b_multimodal.json (mean ± std over its 5 seeds)."""
    import json

    root = Path(__file__).resolve().parents[2]
    record = json.loads((root / "bench" / "results" / "hw1b_multimodal.json").read_text())
    text = (root / "lectures" / "01b_multimodal.md").read_text()
    ms = lambda x: f"{np.mean(x):.2f} ± {np.std(x):.2f}"  # noqa: E731
    for s in record["averaging"]["settings"]:
        row = (f"| {s['name']} ({s['swerve_rise']:g}) | {ms(s['l2'])} | {ms(s['mixture'])} | {ms(s['flow'])} | "
               f"{ms(s['l2_one_step'])} |")
        assert row in text, f"the chapter's row for the {s['name']} swerve differs from the benchmark's: {row}"
