"""Numerical checks of the chapter `lectures/03b_adversarial.md` (hw2b): GAIL's saddle point, its optimal
discriminator and the Jensen-Shannon value, the policy's rewards, AIRL's discriminator and shaping, and the
disentanglement identity with the conditions under which it pins down the reward.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lectures/lecture_links.py``) and
compares the lecture's statement with an independent computation: a generic optimiser, scipy's Jensen-Shannon
distance, finite-horizon and discounted soft value iteration, and the rank of a linear system.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.distance import jensenshannon

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_checks import discounted_soft_vi  # noqa: E402
from lecture_links import checks  # noqa: E402

from rlcourse.adversarial import sample_transitions  # noqa: E402
from rlcourse.gridworld import random_mdp  # noqa: E402


def inner_objective(logits, p_e, p_pi):
    """E_E[log D] + E_pi[log(1 - D)] with D = sigmoid(logits), one logit per pair."""
    return (p_e * -np.logaddexp(0, -logits)).sum() + (p_pi * -np.logaddexp(0, logits)).sum()


def best_discriminator(p_e, p_pi):
    """The inner maximum by L-BFGS over the logits, from zero; (logits, value)."""
    res = minimize(lambda l: -inner_objective(l, p_e, p_pi), np.zeros(len(p_e)), method="L-BFGS-B",
                   options={"gtol": 1e-12, "ftol": 1e-15, "maxiter": 10000})
    return res.x, -res.fun


@checks("eq-gail-objective", "91455be9")
@checks("eq-gail-optimal-discriminator", "aeea9727")
def test_the_optimal_discriminator_is_the_density_ratio():
    rng = np.random.default_rng(0)
    for _ in range(3):
        p_e, p_pi = rng.dirichlet(np.ones(12)), rng.dirichlet(np.ones(12))
        logits, _ = best_discriminator(p_e, p_pi)
        d = 1 / (1 + np.exp(-logits))
        assert np.allclose(d, p_e / (p_e + p_pi), atol=1e-5)
        assert np.allclose(logits, np.log(p_e / p_pi), atol=1e-4)


@checks("eq-gail-js", "2ec3ecc2")
def test_the_inner_maximum_is_twice_jensen_shannon_less_2_log_2():
    rng = np.random.default_rng(1)
    for _ in range(3):
        p_e, p_pi = rng.dirichlet(np.ones(9) * 0.7), rng.dirichlet(np.ones(9) * 0.7)
        _, value = best_discriminator(p_e, p_pi)
        js = jensenshannon(p_e, p_pi) ** 2                     # scipy's distance is the square root of JS (nats)
        assert np.isclose(value, 2 * js - 2 * np.log(2), atol=1e-8)
        assert 0 < js <= np.log(2)
    same = rng.dirichlet(np.ones(9))
    assert np.isclose(best_discriminator(same, same)[1], -2 * np.log(2), atol=1e-9)


@checks("eq-gail-objective", "91455be9")
def test_the_outer_problem_is_solved_by_the_expert():
    """One state and five actions (the occupancy is the policy): max_D of the objective, lambda = 0, is smallest at
    the expert's policy, where it is -2 log 2, and larger at every other policy drawn."""
    rng = np.random.default_rng(2)
    expert = rng.dirichlet(np.ones(5))
    at_expert = best_discriminator(expert, expert)[1]
    others = [best_discriminator(expert, rng.dirichlet(np.ones(5)))[1] for _ in range(20)]
    assert np.isclose(at_expert, -2 * np.log(2), atol=1e-9) and min(others) > at_expert


@checks("eq-gail-objective", "91455be9")
@checks("eq-gail-js", "2ec3ecc2")
def test_with_an_entropy_bonus_the_saddle_point_is_not_the_expert():
    """One state, five actions: the outer problem 2 JS - lambda H (the inner maximum, less 2 log 2) is minimised
    at the expert with JS = 0 and D* = 1/2 only for lambda = 0; for lambda > 0 its minimiser has more entropy than
    the expert, JS > 0 and D* != 1/2, and it is the minimiser of JS - (lambda/2) H, not of JS - lambda H."""
    expert = np.array([0.7, 0.15, 0.1, 0.04, 0.01])

    def entropy(q):
        return float(-(q * np.log(q)).sum())

    def js(q):                                                  # in nats, written out (scipy's is checked above)
        m = (expert + q) / 2
        return float(0.5 * (expert * np.log(expert / m)).sum() + 0.5 * (q * np.log(q / m)).sum())

    def minimiser(weight_js, lam):
        def outer(z):
            q = np.exp(z - np.logaddexp.reduce(z))
            return weight_js * js(q) - lam * entropy(q)
        z = minimize(outer, np.zeros(5), method="BFGS", options={"gtol": 1e-10}).x
        return np.exp(z - np.logaddexp.reduce(z))

    at_zero = minimiser(2, 0.0)
    assert np.allclose(at_zero, expert, atol=1e-4)
    assert np.allclose(expert / (expert + at_zero), 0.5, atol=1e-4)
    for lam in (0.2, 0.5):
        saddle = minimiser(2, lam)
        assert js(saddle) > 1e-3 and entropy(saddle) > entropy(expert)
        assert np.abs(expert / (expert + saddle) - 0.5).max() > 0.01
        assert np.allclose(saddle, minimiser(1, lam / 2), atol=1e-4)
        assert np.abs(saddle - minimiser(1, lam)).max() > 1e-2, "JS less lambda H is another problem"


@checks("eq-gail-rewards", "b092a7a2")
def test_the_three_rewards_and_where_the_gail_reward_saturates():
    rng = np.random.default_rng(3)
    d = rng.uniform(1e-6, 1 - 1e-6, size=50)
    l = np.log(d) - np.log1p(-d)
    softplus = lambda x: np.logaddexp(0, x)  # noqa: E731
    assert np.allclose(-np.log1p(-d), softplus(l), rtol=1e-9)
    assert np.allclose(np.log(d), -softplus(-l), rtol=1e-9)
    assert np.allclose(np.log(d) - np.log1p(-d), -np.log1p(-d) + np.log(d))   # the logit is the sum of the two
    # rejected policy samples, D from 1e-4 to 1e-3: -log(1 - D) barely tells them apart, log D by log 10
    assert -np.log1p(-1e-3) + np.log1p(-1e-4) < 1e-3 and np.isclose(np.log(1e-3) - np.log(1e-4), np.log(10))


@checks("eq-airl-discriminator", "b0e2edee")
def test_airl_logit_and_the_soft_rl_problem_it_sets():
    rng = np.random.default_rng(4)
    f, pi = rng.normal(size=30), rng.uniform(0.01, 1, size=30)
    d = np.exp(f) / (np.exp(f) + pi)
    assert np.allclose(np.log(d) - np.log(1 - d), f - np.log(pi))
    # one state: E_pi[f - log pi] = E_pi[f] + H(pi), maximised by softmax(f) (checked with a generic optimiser)
    f5 = rng.normal(size=5)
    objective = lambda z: -(np.exp(z - np.logaddexp.reduce(z)) * (f5 - (z - np.logaddexp.reduce(z)))).sum()  # noqa: E731
    z = minimize(objective, np.zeros(5), method="BFGS").x
    assert np.allclose(np.exp(z - np.logaddexp.reduce(z)), np.exp(f5) / np.exp(f5).sum(), atol=1e-5)


def soft_optimal_policy(P, reward, horizon, gamma=1.0):
    """Finite-horizon soft value iteration (the return and the causal entropy discounted by ``gamma``) for a reward
    (S,) or (T, S, A), written out here."""
    reward = np.broadcast_to(reward[:, None] if np.ndim(reward) == 1 else reward, (horizon, *P.shape[:2]))
    v, policy = np.zeros(P.shape[0]), np.empty((horizon, *P.shape[:2]))
    for t in reversed(range(horizon)):
        q = reward[t] + gamma * P @ v
        v = np.logaddexp.reduce(q, axis=1)
        policy[t] = np.exp(q - v[:, None])
    return policy


@checks("eq-airl-f", "1d1abe23")
def test_shaping_leaves_the_policy_alone():
    mdp = random_mdp(n_states=12, n_actions=3, n_features=2, horizon=6, seed=0)
    rng = np.random.default_rng(5)
    g, h = rng.normal(size=12), rng.normal(size=12)
    # finite horizon, gamma = 1, h(s') dropped on the last step: the same soft-optimal policy as for g alone
    f = np.broadcast_to(g[None, :, None] - h[None, :, None] + mdp.P @ h, (6, 12, 3)).copy()
    f[-1] = g[:, None] - h[:, None]
    assert np.allclose(soft_optimal_policy(mdp.P, f, 6), soft_optimal_policy(mdp.P, g, 6), atol=1e-10)
    # along sampled trajectories the shaping telescopes to -h(s_0)
    batch = sample_transitions(mdp.P, soft_optimal_policy(mdp.P, g, 6), mdp.p0, 5, rng)
    per_step = g[batch.states] + h[batch.next_states] - h[batch.states]
    per_step[:, -1] -= h[batch.next_states[:, -1]]
    assert np.allclose(per_step.sum(axis=1), g[batch.states].sum(axis=1) - h[batch.states[:, 0]])
    # finite horizon, gamma = 0.9 inside f: the same policy when the return is discounted by the same gamma, but
    # not for the undiscounted sum of f, which keeps -(1 - gamma) sum_{t >= 1} h(s_t)
    gamma = 0.9
    f = np.broadcast_to(g[None, :, None] - h[None, :, None] + gamma * mdp.P @ h, (6, 12, 3)).copy()
    f[-1] = g[:, None] - h[:, None]
    assert np.allclose(soft_optimal_policy(mdp.P, f, 6, gamma), soft_optimal_policy(mdp.P, g, 6, gamma), atol=1e-10)
    assert np.abs(soft_optimal_policy(mdp.P, f, 6) - soft_optimal_policy(mdp.P, g, 6)).max() > 1e-3
    # discounted infinite horizon, gamma = 0.9: the same soft-optimal policy too
    gamma = 0.9
    _, log_pi_g = discounted_soft_vi(mdp.P, np.repeat(g[:, None], 3, axis=1), gamma)
    _, log_pi_f = discounted_soft_vi(mdp.P, g[:, None] + gamma * mdp.P @ h - h[:, None], gamma)
    assert np.allclose(log_pi_f, log_pi_g, atol=1e-8)


def shaped_system(successor, gamma):
    """The linear map (g, h) -> f(s, a) = g(s) + gamma h(T(s, a)) - h(s) over all pairs, as a matrix."""
    n_states, n_actions = successor.shape
    rows = []
    for s in range(n_states):
        for a in range(n_actions):
            row = np.zeros(2 * n_states)
            row[s] += 1.0
            row[n_states + successor[s, a]] += gamma
            row[n_states + s] -= 1.0
            rows.append(row)
    return np.array(rows)


@checks("eq-airl-disentangled", "f659bbfb")
def test_the_soft_advantage_identity_and_when_it_identifies_the_reward():
    rng = np.random.default_rng(6)
    n_states, n_actions, gamma = 10, 3, 0.9
    # deterministic dynamics on a ring: stay, one step, two steps (random successor tables can fail the rank
    # condition below: a state that no action distinguishes from another leaves h a free direction)
    successor = (np.arange(n_states)[:, None] + np.arange(n_actions)[None, :]) % n_states
    P = np.zeros((n_states, n_actions, n_states))
    P[np.arange(n_states)[:, None], np.arange(n_actions)[None, :], successor] = 1.0
    r = rng.normal(size=n_states)
    v, log_pi = discounted_soft_vi(P, np.repeat(r[:, None], n_actions, axis=1), gamma)
    assert np.allclose(log_pi, r[:, None] + gamma * v[successor] - v[:, None], atol=1e-9)
    # mixing dynamics: the only freedom is (g, h) -> (g + (1 - gamma) c, h + c), and g recovers r up to a constant
    A = shaped_system(successor, gamma)
    assert np.linalg.matrix_rank(A) == 2 * n_states - 1
    null = np.linalg.svd(A)[2][-1]
    assert np.allclose(null[:n_states] / null[n_states:], 1 - gamma)
    sol = np.linalg.lstsq(A, log_pi.ravel(), rcond=None)[0]
    assert np.allclose(A @ sol, log_pi.ravel(), atol=1e-8)
    assert np.ptp(sol[:n_states] - r) < 1e-8
    # every action leads to the same successor: the action never matters and g is not identified at all
    same = np.repeat(rng.integers(0, n_states, size=(n_states, 1)), n_actions, axis=1)
    assert 2 * n_states - np.linalg.matrix_rank(shaped_system(same, gamma)) >= n_states
