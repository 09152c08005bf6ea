"""Numerical checks of chapters 1 to 5 that `test_lecture_identities.py` did not cover.

Each test names its equations with ``@checks(label, digest)`` (see
``tests/lecture_links.py``): editing one of them fails the test until it has
been re-read against the new text. Every check compares the lecture's formula
with an independent computation (enumeration, a generic optimiser, Monte
Carlo, finite differences) on small random instances.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar
from scipy.special import expit, log_expit, logsumexp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lecture_math as lm  # noqa: E402
from lecture_checks import central_difference, enumerate_trajectories as trajectories, random_mdp, random_policy  # noqa: E402
from lecture_links import checks  # noqa: E402


# ---------------------------------------------------------------------------
# chapter 1
# ---------------------------------------------------------------------------


@checks("eq-performance-difference", "633c1e4e")
@checks("eq-total-cost", "1980a3bf")
def test_performance_difference_by_enumeration():
    """J(pi) - J(pi_E) = sum_t E_{d^pi_t, pi}[Q^E_t - V^E_t]; J itself by enumerating trajectories."""
    rng = np.random.default_rng(101)
    n_states, n_actions, horizon = 3, 2, 4
    P, p0, _ = random_mdp(rng, n_states, n_actions, 1)
    cost = rng.random((n_states, n_actions))
    expert = random_policy(rng, horizon, n_states, n_actions)
    learner = random_policy(rng, horizon, n_states, n_actions)

    def cost_by_enumeration(pi):
        return sum(prob * sum(cost[s, a] for s, a in traj) for traj, prob in trajectories(P, p0, pi))

    def cost_by_marginals(pi):  # second line of eq-total-cost
        return float(np.einsum("ts,tsa,sa->", lm.state_marginals(P, p0, pi), pi, cost))

    assert cost_by_marginals(learner) == pytest.approx(cost_by_enumeration(learner), abs=1e-12)
    V = np.zeros((horizon + 1, n_states))
    Q = np.zeros((horizon, n_states, n_actions))
    for t in reversed(range(horizon)):
        Q[t] = cost + P @ V[t + 1]
        V[t] = np.einsum("sa,sa->s", expert[t], Q[t])
    d = lm.state_marginals(P, p0, learner)
    rhs = np.einsum("ts,tsa,tsa->", d, learner, Q - V[:-1, :, None])
    gap = cost_by_enumeration(learner) - cost_by_enumeration(expert)
    assert rhs == pytest.approx(gap, abs=1e-12)
    # The states must come from the learner: the expert's marginals give a different number.
    wrong = np.einsum("ts,tsa,tsa->", lm.state_marginals(P, p0, expert), learner, Q - V[:-1, :, None])
    assert abs(wrong - gap) > 1e-3


def trap_mdp(rng, n_track: int, n_actions: int):
    """On-track states 0..n_track-1 (cost 0 under the expert's action) and an absorbing trap (cost 1).

    The expert's action keeps the car on the track (random moves among on-track states); any other
    action leads to the trap, which costs 1 per step forever. This is chapter 1's drift model with
    random dynamics, the instance on which behaviour cloning's T^2 is attained.
    """
    n_states = n_track + 1
    trap = n_track
    expert_action = rng.integers(n_actions, size=n_track)
    P = np.zeros((n_states, n_actions, n_states))
    cost = np.zeros((n_states, n_actions))
    for s in range(n_track):
        for a in range(n_actions):
            if a == expert_action[s]:
                P[s, a, :n_track] = rng.dirichlet(np.ones(n_track))
            else:
                P[s, a, trap] = 1.0
    P[trap, :, trap] = 1.0
    cost[trap] = 1.0
    p0 = np.append(rng.dirichlet(np.ones(n_track)), 0.0)
    expert_actions = np.append(expert_action, 0)
    return P, p0, cost, expert_actions


def bound_quantities(P, p0, cost, expert, learner):
    """(cost gap, epsilon on the expert's states, epsilon on the learner's states, u) as chapter 1 defines them."""
    horizon = expert.shape[0]

    def total_cost(pi):
        return float(np.einsum("ts,tsa,sa->", lm.state_marginals(P, p0, pi), pi, cost))

    mistake = 1.0 - np.einsum("tsa,tsa->ts", learner, expert)  # e_t(s)
    eps_expert = np.mean(np.sum(lm.state_marginals(P, p0, expert) * mistake, axis=1))
    eps_learner = np.mean(np.sum(lm.state_marginals(P, p0, learner) * mistake, axis=1))
    V = np.zeros(P.shape[0])
    u = 0.0
    for t in reversed(range(horizon)):
        Q = cost + P @ V
        V = np.einsum("sa,sa->s", expert[t], Q)
        u = max(u, float(np.max(Q - V[:, None])))
    return total_cost(learner) - total_cost(expert), eps_expert, eps_learner, u


@checks("eq-bc-bound", "b9b5aae9")
@checks("eq-dagger-bound", "989f6591")
def test_bc_bound_holds_and_only_the_quadratic_one_on_trap_mdps():
    """On random MDPs with an absorbing trap, J - J_E exceeds T eps (and eps), and stays below T^2 eps.

    A bound without T, or with one factor of T, fails on these instances; T^2 eps holds on all of them
    and on the random MDPs below. DAgger's u T eps~ holds too, with u of the order of T here.
    """
    rng = np.random.default_rng(102)
    n_actions, horizon = 3, 30
    worst_ratio = 0.0
    for _ in range(12):
        P, p0, cost, expert_actions = trap_mdp(rng, n_track=4, n_actions=n_actions)
        n_states = P.shape[0]
        expert = np.zeros((horizon, n_states, n_actions))
        expert[:, np.arange(n_states), expert_actions] = 1.0
        slip = rng.uniform(0.002, 0.02)
        learner = (1 - slip) * expert + slip * random_policy(rng, horizon, n_states, n_actions)
        gap, eps_expert, eps_learner, u = bound_quantities(P, p0, cost, expert, learner)
        assert gap <= horizon**2 * eps_expert + 1e-12
        assert gap <= u * horizon * eps_learner + 1e-12
        assert gap > horizon * eps_expert  # a linear-in-T bound would be wrong here
        worst_ratio = max(worst_ratio, gap / (horizon**2 * eps_expert))
    assert worst_ratio > 0.3  # and the quadratic one is attained up to a constant

    for _ in range(30):  # generic random MDPs: the bounds hold there too
        n_states = 4
        P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
        p0 = rng.dirichlet(np.ones(n_states))
        cost = rng.random((n_states, n_actions))
        expert = np.zeros((6, n_states, n_actions))
        expert[np.arange(6)[:, None], np.arange(n_states), rng.integers(n_actions, size=(6, n_states))] = 1.0
        learner = 0.85 * expert + 0.15 * random_policy(rng, 6, n_states, n_actions)
        gap, eps_expert, eps_learner, u = bound_quantities(P, p0, cost, expert, learner)
        assert gap <= 36 * eps_expert + 1e-12
        assert gap <= u * 6 * eps_learner + 1e-12


@checks("eq-bc-objective", "6e63bf54")
@checks("eq-bc-mean", "2f46a8de")
def test_squared_error_bc_fits_the_conditional_mean_and_misses_both_modes():
    rng = np.random.default_rng(103)
    n_states, n_per_state = 4, 400
    states = np.repeat(np.arange(n_states), n_per_state)
    modes = rng.normal(size=(n_states, 2)) * 2.0
    pick = rng.integers(2, size=states.size)
    actions = modes[states, pick] + 0.1 * rng.normal(size=states.size)

    def squared_error(mu):  # eq-bc-objective with the squared-error surrogate, a tabular policy
        return float(np.mean((mu[states] - actions) ** 2))

    fitted = minimize(squared_error, np.zeros(n_states), method="BFGS").x
    conditional_mean = np.array([actions[states == s].mean() for s in range(n_states)])
    np.testing.assert_allclose(fitted, conditional_mean, atol=1e-5)
    # A fixed-variance Gaussian's negative log-likelihood has the same minimiser.
    sigma = 0.7
    nll = minimize(lambda mu: float(np.mean((mu[states] - actions) ** 2 / (2 * sigma**2) + np.log(sigma))),
                   np.zeros(n_states), method="BFGS").x
    np.testing.assert_allclose(nll, conditional_mean, atol=1e-5)
    # With well-separated modes the mean is far from every demonstrated action.
    separated = np.abs(modes[:, 0] - modes[:, 1]) > 1.0
    for s in np.flatnonzero(separated):
        assert np.min(np.abs(actions[states == s] - fitted[s])) > 0.2


# ---------------------------------------------------------------------------
# chapter 2
# ---------------------------------------------------------------------------


@checks("eq-linear-return", "871ff4c4")
@checks("eq-empirical-features", "602301d7")
def test_linear_return_and_empirical_feature_average():
    """J(pi; w) by policy evaluation equals w.mu(pi); the sample average of F(tau) converges to mu(pi)."""
    rng = np.random.default_rng(104)
    n_states, n_actions, gamma, n_features = 4, 2, 0.8, 3
    P, p0, f = random_mdp(rng, n_states, n_actions, n_features)
    pi = random_policy(rng, n_states, n_actions)
    w = rng.normal(size=n_features)
    # Policy evaluation with the reward w.f, independent of occupancy measures.
    P_pi = np.einsum("sa,sax->sx", pi, P)
    r_pi = np.einsum("sa,sa->s", pi, f @ w)
    J = p0 @ np.linalg.solve(np.eye(n_states) - gamma * P_pi, r_pi)
    mu = lm.occupancy_weighted_features(lm.occupancy_discounted(P, p0, pi, gamma)[1], f)
    assert J == pytest.approx(w @ mu, abs=1e-10)
    # Sampled trajectories: the average of F(tau_i) estimates mu(pi) without bias.
    n_traj, horizon = 4000, 120
    s = rng.choice(n_states, size=n_traj, p=p0)
    F = np.zeros((n_traj, n_features))
    for t in range(horizon):
        a = (rng.random((n_traj, 1)) > np.cumsum(pi[s], axis=1)).sum(axis=1).clip(max=n_actions - 1)
        F += gamma**t * f[s, a]
        s = (rng.random((n_traj, 1)) > np.cumsum(P[s, a], axis=1)).sum(axis=1).clip(max=n_states - 1)
    mu_hat = F.mean(axis=0)
    se = F.std(axis=0) / np.sqrt(n_traj)
    assert np.all(np.abs(mu_hat - mu) < 5 * se)
    assert np.mean(F @ w) == pytest.approx(w @ mu_hat, abs=1e-10)  # the return is linear in the average


def optimal_q(P, reward_sas, gamma):
    """Q* by policy iteration (exact linear solves) for a reward r(s, a, s')."""
    n_states = P.shape[0]
    expected_r = np.einsum("sax,sax->sa", P, reward_sas)
    policy = np.zeros(n_states, dtype=int)
    while True:
        P_pi = P[np.arange(n_states), policy]
        V = np.linalg.solve(np.eye(n_states) - gamma * P_pi, expected_r[np.arange(n_states), policy])
        Q = expected_r + gamma * P @ V
        improved = np.where(Q.max(axis=1) > Q[np.arange(n_states), policy] + 1e-12, Q.argmax(axis=1), policy)
        if np.array_equal(improved, policy):
            return Q
        policy = improved


@checks("eq-shaping", "def5e798")
def test_potential_shaping_shifts_q_by_phi_and_keeps_the_optimal_policy():
    rng = np.random.default_rng(105)
    n_states, n_actions, gamma = 5, 3, 0.9
    P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
    r = rng.normal(size=(n_states, n_actions, n_states))
    flipped = 0
    for _ in range(20):
        phi = rng.normal(size=n_states) * 3
        shaped = r + gamma * phi[None, None, :] - phi[:, None, None]
        Q, Q_shaped = optimal_q(P, r, gamma), optimal_q(P, shaped, gamma)
        np.testing.assert_allclose(Q_shaped, Q - phi[:, None], atol=1e-8)
        np.testing.assert_array_equal(Q_shaped.argmax(axis=1), Q.argmax(axis=1))
        # Not potential-based (the potential of the *current* state added): the policy can change.
        other = r + phi[:, None, None] * rng.random((1, n_actions, 1)) * 2
        flipped += np.any(optimal_q(P, other, gamma).argmax(axis=1) != Q.argmax(axis=1))
    assert flipped > 0


@checks("eq-ng-russell", "4c88df5b")
def test_ng_russell_condition_is_exactly_optimality_of_the_observed_policy():
    rng = np.random.default_rng(106)
    n_states, n_actions, gamma = 3, 2, 0.85
    outcomes = {True: 0, False: 0}
    for _ in range(300):
        P = rng.dirichlet(np.ones(n_states) * 0.5, size=(n_states, n_actions))
        R = rng.normal(size=n_states)
        P_a = [P[:, a, :] for a in range(n_actions)]  # action 0 plays the observed a_1
        inverse = np.linalg.inv(np.eye(n_states) - gamma * P_a[0])
        condition = all(np.all((P_a[0] - P_a[a]) @ inverse @ R >= -1e-12) for a in range(1, n_actions))
        Q = optimal_q(P, np.broadcast_to(R[:, None, None], P.shape), gamma)
        optimal = bool(np.all(Q[:, 0] >= Q.max(axis=1) - 1e-9))
        assert condition == optimal
        outcomes[condition] += 1
    assert min(outcomes.values()) > 5  # both cases occurred


def deterministic_policy_features(P, p0, f, gamma):
    """(1 - gamma) mu(pi) for every deterministic stationary policy."""
    n_states, n_actions = P.shape[:2]
    out = []
    for acts in itertools.product(range(n_actions), repeat=n_states):
        pi = np.eye(n_actions)[list(acts)]
        out.append((1 - gamma) * lm.occupancy_weighted_features(lm.occupancy_discounted(P, p0, pi, gamma)[1], f))
    return np.array(out)


@checks("eq-projection-step", "4b7c7fa1")
def test_projection_method_stays_in_the_hull_and_approaches_the_expert():
    rng = np.random.default_rng(107)
    P, p0, f = random_mdp(rng, 5, 2, 3)
    gamma = 0.8
    corners = deterministic_policy_features(P, p0, f, gamma)
    expert_pi = random_policy(rng, 5, 2)
    expert = (1 - gamma) * lm.occupancy_weighted_features(lm.occupancy_discounted(P, p0, expert_pi, gamma)[1], f)
    bar, weights = corners[0].copy(), np.eye(len(corners))[0]  # mixture weights over the corners
    distance = np.linalg.norm(expert - bar)
    for _ in range(15):
        w = expert - bar
        j = int(np.argmax(corners @ w))  # an optimal policy for r_w among deterministic ones
        step = corners[j] - bar
        if step @ step < 1e-20:
            break
        eta = step @ (expert - bar) / (step @ step)  # eq-projection-step
        best = minimize_scalar(lambda e: np.linalg.norm(bar + e * step - expert), bounds=(-2, 3),
                               method="bounded", options={"xatol": 1e-12}).x
        assert eta == pytest.approx(best, abs=1e-6)  # the closest point on the line
        assert -1e-12 <= eta <= 1 + 1e-12  # inside the segment, so inside the hull
        bar = bar + eta * step
        weights = (1 - eta) * weights + eta * np.eye(len(corners))[j]
        np.testing.assert_allclose(weights @ corners, bar, atol=1e-12)  # a known mixture
        new_distance = np.linalg.norm(expert - bar)
        assert new_distance <= distance + 1e-12
        distance = new_distance
    assert distance < 0.2 * np.linalg.norm(expert - corners[0])


# ---------------------------------------------------------------------------
# chapter 3
# ---------------------------------------------------------------------------


@checks("eq-maxent-lagrangian", "c48b5b77")
def test_lagrangian_over_distributions_is_dual_minus_kl_and_over_all_p_only_at_one_lambda0():
    rng = np.random.default_rng(108)
    n, d = 6, 2
    F = rng.normal(size=(n, d))
    mu_hat = rng.dirichlet(np.ones(n)) @ F
    w = rng.normal(size=d)
    p_w = lm.exponential_family(F, w)
    g = lm.maxent_dual(w, F, mu_hat)

    def lagrangian(p, lam0):  # eq-maxent-lagrangian, term by term
        return -np.sum(p * np.log(p)) + w @ (F.T @ p - mu_hat) + lam0 * (p.sum() - 1)

    for lam0 in (-2.0, 0.3, 5.0):
        for _ in range(5):
            q = rng.dirichlet(np.ones(n))
            kl = np.sum(q * np.log(q / p_w))
            assert lagrangian(q, lam0) == pytest.approx(g - kl, abs=1e-12)
    # Over all p >= 0 (unnormalised) the maximum depends on lambda0 and is g only at 1 - log Z.
    log_z = logsumexp(F @ w)
    for lam0 in (0.0, 1.0 - log_z, 2.0):
        best = minimize(lambda x: -lagrangian(np.exp(x), lam0), np.zeros(n), method="BFGS",
                        options={"gtol": 1e-10}).fun
        closed = np.exp(lam0 - 1 + log_z) - lam0 - w @ mu_hat
        assert -best == pytest.approx(closed, abs=1e-7)
        assert (abs(closed - g) < 1e-9) == (abs(lam0 - (1 - log_z)) < 1e-12)


def causal_entropy_and_features(P, p0, pi, f):
    """(H^c(pi), mu(pi)) by enumerating trajectories."""
    entropy, mu = 0.0, np.zeros(f.shape[-1])
    for traj, prob in trajectories(P, p0, pi):
        entropy -= prob * sum(np.log(pi[t, s, a]) for t, (s, a) in enumerate(traj))
        mu += prob * sum(f[s, a] for s, a in traj)
    return entropy, mu


@checks("eq-mce-problem", "1f6a6b90")
def test_soft_policy_maximises_causal_entropy_among_policies_with_its_features():
    """H^c(pi) + w.mu(pi) <= E V_0 for every pi, with equality only at pi^w: so pi^w solves eq-mce-problem."""
    rng = np.random.default_rng(109)
    n_states, n_actions, horizon = 3, 2, 3
    P, p0, f = random_mdp(rng, n_states, n_actions, 2)
    w = rng.normal(size=2)
    _, V, pi_w = lm.soft_value_iteration(P, f @ w, horizon)
    bound = p0 @ V[0]
    h_w, mu_w = causal_entropy_and_features(P, p0, pi_w, f)
    assert h_w + w @ mu_w == pytest.approx(bound, abs=1e-12)
    for _ in range(20):
        pi = random_policy(rng, horizon, n_states, n_actions)
        h, mu = causal_entropy_and_features(P, p0, pi, f)
        assert h + w @ mu < bound - 1e-6


@checks("eq-mce-discounted", "d9ba922d")
def test_discounted_soft_value_iteration_gradient_uses_discounted_features_on_both_sides():
    """Stationary soft VI with discount gamma: the gradient of w.mu_E - E V(s0) is mu_E - mu_gamma(pi^w)."""
    rng = np.random.default_rng(110)
    n_states, n_actions, gamma = 4, 3, 0.7
    P, p0, f = random_mdp(rng, n_states, n_actions, 2)
    mu_hat = rng.normal(size=2)

    def soft_values(w):
        V = np.zeros(n_states)
        for _ in range(400):
            Q = f @ w + gamma * P @ V
            V = logsumexp(Q, axis=1)
        return Q, V

    def objective(w):
        return float(w @ mu_hat - p0 @ soft_values(w)[1])

    w = rng.normal(size=2)
    Q, V = soft_values(w)
    pi = np.exp(Q - V[:, None])
    mu_pi = lm.occupancy_weighted_features(lm.occupancy_discounted(P, p0, pi, gamma)[1], f)
    np.testing.assert_allclose(central_difference(objective, w), mu_hat - mu_pi, atol=1e-6)
    # The objective is the discounted causal one: E sum_t gamma^t (r_w - log pi) under pi^w equals E V(s0).
    _, rho = lm.occupancy_discounted(P, p0, pi, gamma)
    assert np.sum(rho * (f @ w - np.log(pi))) == pytest.approx(p0 @ V, abs=1e-9)


# ---------------------------------------------------------------------------
# chapters 4 and 5
# ---------------------------------------------------------------------------


@checks("eq-reward-rational", "f1600375")
def test_reward_rational_choice_reduces_to_bradley_terry_and_to_maxent():
    rng = np.random.default_rng(111)
    returns = rng.normal(size=7)
    for beta_h in (0.5, 2.0):
        probs = np.exp(beta_h * returns - logsumexp(beta_h * returns))
        assert probs.sum() == pytest.approx(1.0)
        # Two options: Bradley-Terry with utilities beta_h * R.
        pair = np.exp(beta_h * returns[:2] - logsumexp(beta_h * returns[:2]))
        assert pair[0] == pytest.approx(float(lm.bradley_terry_prob(beta_h * returns[0], beta_h * returns[1])))
    # All trajectories as options, beta_h = 1, R = w.F: the max-ent distribution.
    F = rng.normal(size=(7, 2))
    w = rng.normal(size=2)
    np.testing.assert_allclose(np.exp(F @ w - logsumexp(F @ w)), lm.exponential_family(F, w), atol=1e-14)


@checks("eq-rm-loss", "d0675517")
def test_reward_model_loss_gradient_and_consistency():
    """A linear reward model: the BT loss's gradient is observed minus expected; its minimiser approaches the truth."""
    rng = np.random.default_rng(112)
    n_pairs, dim = 20000, 3
    phi_true = rng.normal(size=dim)
    feat_w, feat_l = rng.normal(size=(2, n_pairs, dim))
    first_wins = rng.random(n_pairs) < expit((feat_w - feat_l) @ phi_true)
    chosen = np.where(first_wins[:, None], feat_w, feat_l)
    rejected = np.where(first_wins[:, None], feat_l, feat_w)

    def loss(phi):  # eq-rm-loss with r_phi(x, y) = phi . features(y)
        return float(-np.mean(log_expit((chosen - rejected) @ phi)))

    phi0 = rng.normal(size=dim)
    analytic = -np.mean(expit(-(chosen - rejected) @ phi0)[:, None] * (chosen - rejected), axis=0)
    np.testing.assert_allclose(central_difference(loss, phi0), analytic, atol=1e-8)
    fitted = minimize(loss, np.zeros(dim), method="BFGS").x
    assert np.linalg.norm(fitted - phi_true) < 0.1 * np.linalg.norm(phi_true)


@checks("eq-dueling-regret", "4c808b5a")
def test_dueling_regret_is_the_chance_that_the_winner_beats_a_drawn_arm_minus_a_half():
    rng = np.random.default_rng(113)
    k = 4
    u = np.sort(rng.normal(size=k))[::-1]  # arm 0 has the largest utility: the Condorcet winner
    p = expit(u[:, None] - u[None, :])
    delta = p[0] - 0.5  # Delta_{1j}
    for a, b in itertools.product(range(k), repeat=2):
        regret = (delta[a] + delta[b]) / 2
        assert (regret == 0) == (a == 0 and b == 0)
        assert regret >= 0
        # Simulation: the winner duels one of a, b drawn at random.
        n = 40000
        opponent = np.where(rng.random(n) < 0.5, a, b)
        wins = rng.random(n) < p[0, opponent]
        assert wins.mean() - 0.5 == pytest.approx(regret, abs=5 * 0.5 / np.sqrt(n) + 1e-12)
