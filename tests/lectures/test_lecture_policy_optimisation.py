"""Numerical checks of chapters 6 and 7: the reward model's gradient, PPO's surrogate and clip, GAE,
the KL to the reference, token-level RLHF, DPO on trajectories and DPO's minimiser.

Each test names its equations with ``@checks(label, digest)`` (see ``tests/lecture_links.py``) and
compares the lecture's formula with an independent computation: enumeration of trajectories or
sequences, a generic optimiser, Monte Carlo, finite differences, or an episode split by hand.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.optimize import minimize
from scipy.special import expit, log_expit, logsumexp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lecture_math as lm  # noqa: E402
from lecture_checks import central_difference, enumerate_trajectories as trajectories, random_policy  # noqa: E402
from lecture_links import checks  # noqa: E402


# ---------------------------------------------------------------------------
# the segment loss (chapter 6)
# ---------------------------------------------------------------------------


@checks("eq-segment-loss", "cfdc90b3")
def test_segment_loss_gradient_per_step_is_minus_the_misranking_probability():
    rng = np.random.default_rng(201)
    r1, r2 = rng.normal(size=(2, 6))  # predicted per-step rewards of two segments

    def loss(rewards, m1):
        p12 = expit(rewards[:6].sum() - rewards[6:].sum())
        return -(m1 * np.log(p12) + (1 - m1) * np.log(1 - p12))

    x = np.concatenate([r1, r2])
    for m1 in (1.0, 0.5, 0.0):
        grad = central_difference(lambda z: loss(z, m1), x)
        p12 = expit(r1.sum() - r2.sum())
        np.testing.assert_allclose(grad[:6], -(m1 - p12), atol=1e-8)  # the same for every step
        np.testing.assert_allclose(grad[6:], m1 - p12, atol=1e-8)
    # Hard label for segment 1: each of its steps gets -sigma(R2 - R1) (descent raises them).
    grad = central_difference(lambda z: loss(z, 1.0), x)
    np.testing.assert_allclose(grad[:6], -expit(r2.sum() - r1.sum()), atol=1e-8)
    assert np.all(grad[:6] < 0)


# ---------------------------------------------------------------------------
# PPO: performance difference, the surrogate, its bound, the clip
# ---------------------------------------------------------------------------


def finite_mdp(rng, n_states=3, n_actions=2):
    P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
    p0 = rng.dirichlet(np.ones(n_states))
    reward = rng.random((n_states, n_actions))
    return P, p0, reward


def returns_and_advantages(P, p0, reward, pi):
    """(J(pi) by enumeration, A^pi_t(s, a) by backward recursion)."""
    horizon, n_states, _ = pi.shape
    J = sum(prob * sum(reward[s, a] for s, a in traj) for traj, prob in trajectories(P, p0, pi))
    V = np.zeros(n_states)
    A = np.zeros(pi.shape)
    for t in reversed(range(horizon)):
        Q = reward + P @ V
        V = np.einsum("sa,sa->s", pi[t], Q)
        A[t] = Q - V[:, None]
    return J, A


def surrogate(P, p0, reward, pi, new_pi, J_pi, A):
    """L_pi(pi') of eq-ppo-surrogate: old state marginals, importance-weighted old actions."""
    d = lm.state_marginals(P, p0, pi)
    return J_pi + np.einsum("ts,tsa,tsa->", d, pi, new_pi / pi * A)


@checks("eq-pdl-rewards", "d2628449")
@checks("eq-ppo-surrogate", "610200ef")
@checks("eq-surrogate-bound", "417e7fe8")
def test_surrogate_agrees_to_first_order_and_its_error_obeys_the_bound():
    rng = np.random.default_rng(202)
    horizon = 4
    P, p0, reward = finite_mdp(rng)
    pi = random_policy(rng, horizon, 3, 2)
    direction = random_policy(rng, horizon, 3, 2)
    J_pi, A = returns_and_advantages(P, p0, reward, pi)
    a_max = np.abs(A).max()
    errors = {}
    for kappa in (0.0, 0.01, 0.02, 0.3, 0.8):
        new_pi = (1 - kappa) * pi + kappa * direction
        J_new, _ = returns_and_advantages(P, p0, reward, new_pi)
        # Performance difference with rewards: new policy's states and actions, old advantages.
        d_new = lm.state_marginals(P, p0, new_pi)
        assert np.einsum("ts,tsa,tsa->", d_new, new_pi, A) == pytest.approx(J_new - J_pi, abs=1e-12)
        L = surrogate(P, p0, reward, pi, new_pi, J_pi, A)
        alpha = 0.5 * np.abs(new_pi - pi).sum(axis=2).max()  # max total variation
        assert abs(J_new - L) <= 2 * alpha**2 * a_max * horizon * (horizon - 1) + 1e-12
        errors[kappa] = abs(J_new - L)
    assert errors[0.0] < 1e-12
    assert errors[0.8] > 1e-4  # away from pi the surrogate is wrong ...
    assert errors[0.02] / errors[0.01] == pytest.approx(4.0, rel=0.1)  # ... by a second-order amount

    def along(kappa, which):
        new_pi = (1 - kappa) * pi + kappa * direction
        if which == "J":
            return returns_and_advantages(P, p0, reward, new_pi)[0]
        return surrogate(P, p0, reward, pi, new_pi, J_pi, A)

    h = 1e-5
    slope_J = (along(h, "J") - along(-h, "J")) / (2 * h)
    slope_L = (along(h, "L") - along(-h, "L")) / (2 * h)
    assert slope_L == pytest.approx(slope_J, abs=1e-8)
    assert abs(slope_J) > 1e-3


@checks("eq-ppo-clip", "ad1165ca")
def test_clipped_objective_is_pessimistic_flat_where_the_lecture_says_and_matches_hw5_sign():
    eps = 0.2
    ratios = np.linspace(0.05, 2.5, 981)
    for adv in (1.7, -0.6):
        term = np.minimum(ratios * adv, np.clip(ratios, 1 - eps, 1 + eps) * adv)  # eq-ppo-clip, one sample
        # Piecewise by hand: flat beyond 1+eps for A > 0, below 1-eps for A < 0, ratio * A elsewhere.
        if adv > 0:
            by_hand = np.where(ratios > 1 + eps, (1 + eps) * adv, ratios * adv)
        else:
            by_hand = np.where(ratios < 1 - eps, (1 - eps) * adv, ratios * adv)
        np.testing.assert_allclose(term, by_hand, atol=1e-12)
        assert np.all(term <= ratios * adv + 1e-12)  # a pessimistic bound on the unclipped objective
        inside = np.abs(ratios - 1) <= eps
        np.testing.assert_allclose(term[inside], ratios[inside] * adv)
        slope = np.gradient(term, ratios)
        kink = 1 + eps if adv > 0 else 1 - eps
        away = np.abs(ratios - kink) > 0.01  # np.gradient averages the two sides at the kink itself
        flat = (ratios > kink) if adv > 0 else (ratios < kink)
        assert np.allclose(slope[flat & away], 0.0)
        np.testing.assert_allclose(slope[~flat & away], adv)
        # hw5's loss per token is max(-ratio A, -clip(ratio) A) = -(the clipped term).
        hw5 = np.maximum(-ratios * adv, -np.clip(ratios, 1 - eps, 1 + eps) * adv)
        np.testing.assert_allclose(hw5, -term, atol=1e-12)


# ---------------------------------------------------------------------------
# GAE
# ---------------------------------------------------------------------------


def gae_recursion(rewards, values, dones, last_value, gamma, lam):
    """eq-gae-recursion, one environment."""
    adv = np.zeros_like(rewards)
    next_adv, next_value = 0.0, last_value
    for t in reversed(range(len(rewards))):
        alive = 1.0 - dones[t]
        delta = rewards[t] + gamma * alive * next_value - values[t]
        next_adv = delta + gamma * lam * alive * next_adv
        adv[t], next_value = next_adv, values[t]
    return adv


def n_step_advantage(rewards, values, last_value, gamma, t, n):
    """A^(n)_t from raw rewards and values (no deltas), within a buffer without episode ends."""
    values_ext = np.append(values, last_value)
    return sum(gamma**k * rewards[t + k] for k in range(n)) + gamma**n * values_ext[t + n] - values[t]


@checks("eq-gae-recursion", "1d7573a4")
@checks("eq-gae-lambda", "7f2eef0b")
def test_gae_recursion_is_the_lambda_average_of_n_step_advantages_and_respects_episode_ends():
    rng = np.random.default_rng(203)
    T, gamma, lam = 9, 0.93, 0.8
    rewards, values = rng.normal(size=(2, T))
    last_value = rng.normal()
    adv = gae_recursion(rewards, values, np.zeros(T), last_value, gamma, lam)
    for t in range(T):
        M = T - t
        weighted = (1 - lam) * sum(lam ** (n - 1) * n_step_advantage(rewards, values, last_value, gamma, t, n)
                                   for n in range(1, M)) + lam ** (M - 1) * n_step_advantage(
            rewards, values, last_value, gamma, t, M)
        assert adv[t] == pytest.approx(weighted, abs=1e-12)
    # lambda = 1: Monte Carlo return (bootstrapped at the buffer's end) minus V; lambda = 0: delta.
    mc = [n_step_advantage(rewards, values, last_value, gamma, t, T - t) for t in range(T)]
    np.testing.assert_allclose(gae_recursion(rewards, values, np.zeros(T), last_value, gamma, 1.0), mc, atol=1e-12)
    np.testing.assert_allclose(gae_recursion(rewards, values, np.zeros(T), last_value, gamma, 0.0),
                               [n_step_advantage(rewards, values, last_value, gamma, t, 1) for t in range(T)])
    # Episode ends: the buffer split by hand into episodes, each terminated (value 0 after its end).
    dones = np.zeros(T)
    dones[[2, 6]] = 1.0
    adv = gae_recursion(rewards, values, dones, last_value, gamma, lam)
    pieces = [(0, 3, 0.0), (3, 7, 0.0), (7, 9, last_value)]
    by_episode = np.concatenate([gae_recursion(rewards[a:b], values[a:b], np.zeros(b - a), tail, gamma, lam)
                                 for a, b, tail in pieces])
    np.testing.assert_allclose(adv, by_episode, atol=1e-12)


def test_truncation_bootstrapped_from_the_final_observation_keeps_exact_targets():
    """A chain with reward 1 per step and an exact critic: bootstrapped truncations give targets V*, not less."""
    gamma, lam, limit = 0.9, 0.95, 5
    true_value = 1 / (1 - gamma)
    T = 3 * limit
    values = np.full(T, true_value)
    dones = ((np.arange(T) + 1) % limit == 0).astype(float)
    bootstrapped = gae_recursion(1.0 + dones * gamma * true_value, values, dones, true_value, gamma, lam) + values
    np.testing.assert_allclose(bootstrapped, true_value, atol=1e-12)
    as_termination = gae_recursion(np.ones(T), values, dones, true_value, gamma, lam) + values
    assert as_termination[limit - 1] == pytest.approx(1.0)  # the last step before the cut is worth 1 only
    assert np.all(as_termination[dones == 1] < true_value - 5)


# ---------------------------------------------------------------------------
# the KL to the reference
# ---------------------------------------------------------------------------


@checks("eq-kl-estimators", "2d5e091a")
def test_kl_estimators_bias_sign_and_variance():
    rng = np.random.default_rng(204)
    for closeness in (1.0, 0.01):
        pi = rng.dirichlet(np.ones(5))
        ref = (1 - closeness) * pi + closeness * rng.dirichlet(np.ones(5))
        kl = np.sum(pi * np.log(pi / ref))
        rho = ref / pi  # one entry per action a ~ pi
        k1, k2, k3 = -np.log(rho), 0.5 * np.log(rho) ** 2, (rho - 1) - np.log(rho)
        mean = lambda k: float(pi @ k)  # noqa: E731  exact expectation under pi
        var = lambda k: float(pi @ (k - mean(k)) ** 2)  # noqa: E731
        assert mean(k1) == pytest.approx(kl, abs=1e-14) and mean(k3) == pytest.approx(kl, abs=1e-14)
        assert np.all(k3 >= 0) and np.all(k2 >= 0) and np.any(k1 < 0)
        assert abs(mean(k2) - kl) > 1e-6 * kl  # k2 is biased ...
        if closeness < 0.1:  # ... by a third-order amount, and near the reference k3 beats k1
            assert abs(mean(k2) - kl) < 0.05 * kl
            assert var(k3) < 0.1 * var(k1)
    # Monte Carlo: sampled k1 and k3 average to the KL.
    samples = rng.choice(5, size=200_000, p=pi)
    for k in (k1, k3):
        assert k[samples].mean() == pytest.approx(kl, abs=5 * k[samples].std() / np.sqrt(len(samples)))


def _softmax(theta):
    z = np.exp(theta - theta.max())
    return z / z.sum()


@pytest.mark.parametrize("seed", [0, 1, 2])
@checks("eq-kl-estimator-grads", "dae1620a")
def test_kl_estimators_as_losses_have_the_gradients_the_lecture_states(seed):
    """Expected gradient of each estimator with the sampled action held fixed, by enumeration and finite differences."""
    rng = np.random.default_rng(300 + seed)
    theta, ref = 1.5 * rng.normal(size=5), rng.dirichlet(np.ones(5))
    estimators = {"k1": lambda r: -np.log(r), "k2": lambda r: 0.5 * np.log(r) ** 2, "k3": lambda r: r - 1 - np.log(r)}
    pi = _softmax(theta)                      # the sampling distribution, a constant weight once the action is drawn

    def held_fixed(k):                        # sum_a pi(a) grad_theta k(ref(a) / pi_theta(a)), pi(a) not differentiated
        return sum(pi[a] * central_difference(lambda t: k(ref[a] / _softmax(t)[a]), theta) for a in range(5))

    reverse = central_difference(lambda t: np.sum(_softmax(t) * np.log(_softmax(t) / ref)), theta)
    forward = central_difference(lambda t: np.sum(ref * np.log(ref / _softmax(t))), theta)
    g = {name: held_fixed(k) for name, k in estimators.items()}
    assert np.allclose(g["k1"], 0.0, atol=1e-8)
    assert np.allclose(g["k2"], reverse, atol=1e-7)
    assert np.allclose(g["k3"], forward, atol=1e-7)
    assert np.abs(reverse - forward).max() > 1e-3          # the two directions differ here, so the test can fail
    # Through the expectation: E_pi[k3] is the reverse KL for every theta, so its gradient is the reverse KL's.
    through = central_difference(lambda t: np.sum(_softmax(t) * estimators["k3"](ref / _softmax(t))), theta)
    assert np.allclose(through, reverse, atol=1e-7)
    # Near the reference the two gradients agree to first order: their gap shrinks like the square of the distance.
    base, direction = np.log(ref), rng.normal(size=5)
    gaps = []
    for eps in (1e-1, 1e-2):
        t0 = base + eps * direction
        rev = central_difference(lambda t: np.sum(_softmax(t) * np.log(_softmax(t) / ref)), t0)
        fwd = central_difference(lambda t: np.sum(ref * np.log(ref / _softmax(t))), t0)
        gaps.append(np.abs(rev - fwd).max())
    assert gaps[1] < 0.03 * gaps[0]


@checks("eq-gauss-kl", "3ada1c13")
def test_diagonal_gaussian_kl_against_integration_and_monte_carlo():
    rng = np.random.default_rng(205)
    mu, mu_ref = rng.normal(size=(2, 3))
    sigma, sigma_ref = np.exp(rng.normal(size=(2, 3)) * 0.4)
    closed = np.sum(np.log(sigma_ref / sigma) + (sigma**2 + (mu - mu_ref) ** 2) / (2 * sigma_ref**2) - 0.5)
    per_dim = [integrate.quad(lambda x, i=i: stats.norm.pdf(x, mu[i], sigma[i])
                              * (stats.norm.logpdf(x, mu[i], sigma[i]) - stats.norm.logpdf(x, mu_ref[i], sigma_ref[i])),
                              -np.inf, np.inf)[0] for i in range(3)]
    assert closed == pytest.approx(sum(per_dim), abs=1e-8)
    x = mu + sigma * rng.normal(size=(200_000, 3))
    log_ratio = (stats.norm.logpdf(x, mu, sigma) - stats.norm.logpdf(x, mu_ref, sigma_ref)).sum(axis=1)
    assert closed == pytest.approx(log_ratio.mean(), abs=5 * log_ratio.std() / np.sqrt(len(x)))


def kl_rows(pi, ref):
    return np.sum(pi * np.log(pi / ref), axis=-1)


@checks("eq-token-kl", "a2228f19")
def test_trajectory_kl_is_the_sum_of_expected_per_state_kls_dynamics_cancel():
    rng = np.random.default_rng(206)
    horizon, n_states, n_actions = 3, 3, 3
    P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))  # stochastic dynamics
    p0 = rng.dirichlet(np.ones(n_states))
    pi, ref = random_policy(rng, horizon, n_states, n_actions), random_policy(rng, horizon, n_states, n_actions)
    p_pi = dict(trajectories(P, p0, pi))
    p_ref = dict(trajectories(P, p0, ref))
    # KL between the trajectory distributions, dynamics included in both probabilities.
    kl_traj = sum(p * np.log(p / p_ref[traj]) for traj, p in p_pi.items())
    sampled_form = sum(p * sum(np.log(pi[t, s, a] / ref[t, s, a]) for t, (s, a) in enumerate(traj))
                       for traj, p in p_pi.items())
    per_state = np.sum(lm.state_marginals(P, p0, pi) * kl_rows(pi, ref))
    assert kl_traj == pytest.approx(sampled_form, abs=1e-12)
    assert kl_traj == pytest.approx(per_state, abs=1e-12)


@checks("eq-kl-gradient-split", "12560326")
def test_kl_gradient_has_a_direct_and_a_score_function_term():
    rng = np.random.default_rng(207)
    horizon, n_states, n_actions = 3, 3, 2
    P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
    p0 = rng.dirichlet(np.ones(n_states))
    ref = random_policy(rng, horizon, n_states, n_actions)
    theta = rng.normal(size=(horizon, n_states, n_actions))

    def policy(th):
        return np.exp(th - logsumexp(th, axis=-1, keepdims=True))

    def total_kl(th):
        pi = policy(th)
        return float(np.sum(lm.state_marginals(P, p0, pi) * kl_rows(pi, ref)))

    pi = policy(theta)
    kappa = kl_rows(pi, ref)  # (T, S)
    # d kappa_t(s) / d theta_t(s, .) for a softmax: pi * (log(pi/ref) - kappa).
    grad_kappa = pi * (np.log(pi / ref) - kappa[..., None])
    direct = np.zeros_like(theta)
    score = np.zeros_like(theta)
    for traj, prob in trajectories(P, p0, pi):
        for t, (s, a) in enumerate(traj):
            direct[t, s] += prob * grad_kappa[t, s]
            grad_log_pi = np.eye(n_actions)[a] - pi[t, s]
            later = sum(kappa[k, sk] for k, (sk, _) in enumerate(traj) if k > t)
            score[t, s] += prob * grad_log_pi * later
    numeric = central_difference(total_kl, theta)
    np.testing.assert_allclose(direct + score, numeric, atol=1e-8)
    assert np.abs(numeric - direct).max() > 1e-3  # the loss form's gradient misses a real term


# ---------------------------------------------------------------------------
# token-level RLHF
# ---------------------------------------------------------------------------


def response_distribution(rng, vocab, max_len):
    """A random distribution over responses (tuples ending with EOS = 0, or cut at max_len)."""
    responses = [seq for n in range(1, max_len + 1) for seq in itertools.product(range(vocab), repeat=n)
                 if (0 not in seq[:-1]) and (seq[-1] == 0 or n == max_len)]
    return responses, rng.dirichlet(np.ones(len(responses)))


def conditional(responses, probs, prefix, token):
    """pi(token | prefix), by marginalising the joint over continuations."""
    n = len(prefix)
    starts = [p for r, p in zip(responses, probs) if r[:n] == prefix and len(r) > n]
    follows = [p for r, p in zip(responses, probs) if r[:n] == prefix and len(r) > n and r[n] == token]
    return sum(follows) / sum(starts)


@checks("eq-token-rewards", "e24c1fb5")
@checks("eq-rlhf-objective", "83434b4e")
def test_token_rewards_add_up_to_score_minus_beta_log_ratio_and_gae_ignores_masked_positions():
    rng = np.random.default_rng(208)
    vocab, max_len, beta, prompt_len, width = 3, 3, 0.4, 2, 7
    responses, pi = response_distribution(rng, vocab, max_len)
    _, ref = response_distribution(rng, vocab, max_len)
    score = {r: rng.normal() for r in responses}
    # Objective {eq-rlhf-objective}: both lines agree by enumeration.
    first = sum(p * (score[r] - beta * np.log(p / q)) for r, p, q in zip(responses, pi, ref))
    second = sum(p * score[r] for r, p in zip(responses, pi)) - beta * np.sum(pi * np.log(pi / ref))
    assert first == pytest.approx(second, abs=1e-12)
    sampled = 0.0
    for r, p, q in zip(responses, pi, ref):
        mask = np.zeros(width)
        mask[prompt_len:prompt_len + len(r)] = 1.0  # prompt, then the completion, then padding
        logp = rng.normal(size=width) * 5  # garbage outside the mask
        logq = rng.normal(size=width) * 5
        for k, token in enumerate(r):
            logp[prompt_len + k] = np.log(conditional(responses, pi, r[:k], token))
            logq[prompt_len + k] = np.log(conditional(responses, ref, r[:k], token))
        last = prompt_len + len(r) - 1
        rewards = mask * (-beta * (logp - logq) + (np.arange(width) == last) * score[r])  # eq-token-rewards
        assert np.all(rewards[mask == 0] == 0)
        assert rewards.sum() == pytest.approx(score[r] - beta * np.log(p / q), abs=1e-12)  # chain rule
        sampled += p * rewards.sum()
        # gamma = 1, lambda = 1, V = 0 after the last token: targets are the return-to-go, whatever V is.
        values = rng.normal(size=width)
        positions = np.flatnonzero(mask)
        adv = gae_recursion(rewards[positions], values[positions], np.eye(len(positions))[-1], 0.0, 1.0, 1.0)
        np.testing.assert_allclose(adv + values[positions], np.cumsum(rewards[positions][::-1])[::-1], atol=1e-12)
    assert sampled == pytest.approx(first, abs=1e-12)


# ---------------------------------------------------------------------------
# chapter 7: DPO's minimiser, and DPO on trajectories
# ---------------------------------------------------------------------------


@checks("eq-dpo-loss", "655897a3")
@checks("eq-kl-optimum", "f52a9f5f")
@checks("eq-reward-reparam", "54dc0367")
def test_dpo_minimiser_is_the_kl_optimum_of_the_bradley_terry_mle_reward():
    """Arbitrary (not BT-consistent) counts: fit BT by maximum likelihood, tilt pi_ref by it, compare with DPO."""
    rng = np.random.default_rng(209)
    n_prompts, n_resp, beta = 2, 4, 0.5
    ref = rng.dirichlet(np.ones(n_resp), size=n_prompts)
    wins = rng.integers(1, 9, size=(n_prompts, n_resp, n_resp)).astype(float)  # wins[x, i, j]: i beat j
    for x in range(n_prompts):
        np.fill_diagonal(wins[x], 0.0)

    def bt_nll(r):
        r = r.reshape(n_prompts, n_resp)
        margin = r[:, :, None] - r[:, None, :]
        return -float(np.sum(wins * log_expit(margin)))

    r_mle = minimize(bt_nll, np.zeros(n_prompts * n_resp), method="BFGS", options={"gtol": 1e-10}).x
    target = lm.kl_regularised_optimum(ref, r_mle.reshape(n_prompts, n_resp), beta)

    def dpo(theta):
        theta = theta.reshape(n_prompts, n_resp)
        logp = theta - logsumexp(theta, axis=1, keepdims=True)
        implied = beta * (logp - np.log(ref))
        return -float(np.sum(wins * log_expit(implied[:, :, None] - implied[:, None, :])))

    theta = minimize(dpo, np.zeros(n_prompts * n_resp), method="BFGS", options={"gtol": 1e-10}).x
    theta = theta.reshape(n_prompts, n_resp)
    np.testing.assert_allclose(np.exp(theta - logsumexp(theta, axis=1, keepdims=True)), target, atol=1e-5)
    assert np.abs(target - ref).max() > 0.05  # the data moved the policy


def deterministic_problem(rng, n_states, n_actions):
    nxt = rng.integers(n_states, size=(n_states, n_actions))
    P = np.zeros((n_states, n_actions, n_states))
    P[np.arange(n_states)[:, None], np.arange(n_actions)[None, :], nxt] = 1.0
    return P


def traj_soft_vi(P, reward, ref, beta, horizon):
    """eq-traj-soft-vi: V_t(s) = beta log sum_a ref(a|s) exp(Q_t/beta), pi* = ref exp((Q - V)/beta)."""
    n_states = P.shape[0]
    V = np.zeros((horizon + 1, n_states))
    pi = np.zeros((horizon,) + reward.shape)
    for t in reversed(range(horizon)):
        Q = reward + P @ V[t + 1]
        V[t] = beta * logsumexp(Q / beta, b=ref, axis=1)
        pi[t] = ref * np.exp((Q - V[t][:, None]) / beta)
    return V, pi


@checks("eq-traj-soft-vi", "f9f601f3")
@checks("eq-traj-reparam", "75f04641")
def test_trajectory_kl_optimum_is_soft_vi_with_log_ref_and_its_log_ratio_is_return_minus_start_value():
    rng = np.random.default_rng(210)
    n_states, n_actions, horizon, beta = 4, 3, 3, 0.7
    P = deterministic_problem(rng, n_states, n_actions)
    reward = rng.normal(size=(n_states, n_actions))
    ref = random_policy(rng, n_states, n_actions)
    V, pi_star = traj_soft_vi(P, reward, ref, beta, horizon)
    ref_t = np.broadcast_to(ref, pi_star.shape)
    for start in range(n_states):
        p0 = np.eye(n_states)[start]
        trajs, p_ref = zip(*trajectories(P, p0, ref_t))
        returns = np.array([sum(reward[s, a] for s, a in tr) for tr in trajs])
        # The trajectory-level closed form (eq-kl-optimum with trajectories as responses) ...
        tilted = lm.kl_regularised_optimum(np.array(p_ref), returns, beta)
        p_star = dict(trajectories(P, p0, pi_star))
        np.testing.assert_allclose([p_star[tr] for tr in trajs], tilted, atol=1e-12)
        # ... its log-ratio is the return minus the start state's soft value ...
        log_ratio = beta * np.log(np.array([p_star[tr] for tr in trajs]) / np.array(p_ref))
        np.testing.assert_allclose(log_ratio, returns - V[0, start], atol=1e-10)
        assert V[0, start] == pytest.approx(beta * np.log(np.sum(np.array(p_ref) * np.exp(returns / beta))))
    # ... and with beta = 1 and a uniform reference it is chapter 3's soft VI on r - log |A|.
    _, pi_uniform = traj_soft_vi(P, reward, np.full((n_states, n_actions), 1 / n_actions), 1.0, horizon)
    _, _, pi_ch3 = lm.soft_value_iteration(P, reward - np.log(n_actions), horizon)
    np.testing.assert_allclose(pi_uniform, pi_ch3, atol=1e-12)
    # One step: chapter 7's pi* with the state as the prompt, V_0 = beta log Z.
    V1, pi1 = traj_soft_vi(P, reward, ref, beta, 1)
    np.testing.assert_allclose(pi1[0], lm.kl_regularised_optimum(ref, reward, beta), atol=1e-12)


@checks("eq-traj-bt", "b20ee76a")
def test_dpo_on_segments_recovers_pi_star_only_when_pairs_share_their_start():
    rng = np.random.default_rng(211)
    n_states, n_actions, horizon, beta = 3, 2, 2, 1.0
    P = deterministic_problem(rng, n_states, n_actions)
    reward = rng.normal(size=(n_states, n_actions))
    reward[0] += 1.5  # start state 0 is worth more than start state 1
    ref = random_policy(rng, n_states, n_actions)
    ref_t = np.broadcast_to(ref, (horizon, n_states, n_actions))
    V, pi_star = traj_soft_vi(P, reward, ref, beta, horizon)
    segs = []  # (start, trajectory, p_ref, return)
    for start in (0, 1):
        for tr, p in trajectories(P, np.eye(n_states)[start], ref_t):
            segs.append((start, tr, p, sum(reward[s, a] for s, a in tr)))
    p_star_all = {(s0, tr): p for s0 in (0, 1) for tr, p in trajectories(P, np.eye(n_states)[s0], pi_star)}
    # eq-traj-bt: Bradley-Terry on returns = sigma(log-ratio difference + V_0 difference).
    for (s1, t1, q1, R1), (s2, t2, q2, R2) in itertools.product(segs, repeat=2):
        g1, g2 = beta * np.log(p_star_all[(s1, t1)] / q1), beta * np.log(p_star_all[(s2, t2)] / q2)
        assert expit(R1 - R2) == pytest.approx(expit(g1 - g2 + V[0, s1] - V[0, s2]), abs=1e-12)

    def fit_dpo(same_start_only):
        pairs = [(a, b) for a, b in itertools.product(segs, repeat=2) if a[1] != b[1] or a[0] != b[0]]
        if same_start_only:
            pairs = [(a, b) for a, b in pairs if a[0] == b[0]]

        def loss(theta):
            pi = np.exp(theta.reshape(horizon, n_states, n_actions)
                        - logsumexp(theta.reshape(horizon, n_states, n_actions), axis=-1, keepdims=True))
            total = 0.0
            for (s1, t1, q1, R1), (s2, t2, q2, R2) in pairs:
                g1 = beta * sum(np.log(pi[t, s, a] / ref[s, a]) for t, (s, a) in enumerate(t1))
                g2 = beta * sum(np.log(pi[t, s, a] / ref[s, a]) for t, (s, a) in enumerate(t2))
                label = expit(R1 - R2)  # infinite data: the expected label
                total -= q1 * q2 * (label * log_expit(g1 - g2) + (1 - label) * log_expit(g2 - g1))
            return total

        theta = minimize(loss, np.zeros(horizon * n_states * n_actions), method="BFGS",
                         options={"gtol": 1e-9}).x.reshape(horizon, n_states, n_actions)
        pi = np.exp(theta - logsumexp(theta, axis=-1, keepdims=True))
        return np.array([np.prod([pi[t, s, a] for t, (s, a) in enumerate(tr)]) for _, tr, _, _ in segs])

    p_star = np.array([p_star_all[(s0, tr)] for s0, tr, _, _ in segs])
    np.testing.assert_allclose(fit_dpo(same_start_only=True), p_star, atol=1e-4)
    p_dpo = fit_dpo(same_start_only=False)
    assert np.abs(p_dpo - p_star).max() > 0.02
    # As chapter 7 says: far from the reference after the low-value start, closer to it after the high one.
    starts = np.array([s0 for s0, _, _, _ in segs])
    p_ref = np.array([q for _, _, q, _ in segs])
    low, high = (0, 1) if V[0, 0] < V[0, 1] else (1, 0)

    def kl_from_ref(p, start):
        m = starts == start
        return float(np.sum(p[m] * np.log(p[m] / p_ref[m])))

    assert kl_from_ref(p_dpo, low) > 2 * kl_from_ref(p_star, low)
    assert kl_from_ref(p_dpo, high) < kl_from_ref(p_star, high)


@checks("eq-gao-forms", "b91053cd")
def test_overoptimisation_forms_rise_peak_and_fall_where_the_closed_forms_say():
    rng = np.random.default_rng(212)
    d = np.linspace(1e-4, 60, 600_001)
    for _ in range(5):
        a_bon, b_bon, a_rl = rng.uniform(0.2, 2.0, size=3)
        b_rl = rng.uniform(0.5, 2.0)  # keeps the RL peak, exp(a/b - 1), inside the grid
        bon = d * (a_bon - b_bon * d)
        rl = d * (a_rl - b_rl * np.log(d))
        assert d[np.argmax(bon)] == pytest.approx(a_bon / (2 * b_bon), abs=1e-3)
        assert d[np.argmax(rl)] == pytest.approx(np.exp(a_rl / b_rl - 1), rel=1e-3)
        for curve in (bon, rl):
            peak = np.argmax(curve)
            assert 0 < peak < len(d) - 1 and curve[-1] < curve[peak]  # rises, peaks and falls
