"""Numerical checks of the identities derived in the lecture notes.

Each test names the labelled equations it checks with ``@checks(label,
digest)`` (``tests/lecture_links.py``). The digest is a hash of the equation's
TeX source as it stands in ``lectures/``: when someone edits an equation, every
test tied to it fails before running, naming the file and line, until the test
has been re-read against the new text (and fixed, or the equation fixed) and
the digest updated; ``tests/test_lecture_links.py`` fails while any labelled
equation in any chapter has no test. Print an equation's digest with
``python tests/lecture_links.py eq-name``. Each test compares the formula, as
the lecture states it (often in ``lecture_math.py``), with an independent
computation on small random instances: exhaustive enumeration, a generic
optimiser, Monte Carlo, finite differences, or a case worked by hand. None
compares with a copied expected number.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.special import expit, log_expit, logsumexp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lecture_math as lm  # noqa: E402
from lecture_checks import central_difference, enumerate_trajectories, random_mdp, random_policy  # noqa: E402
from lecture_links import checks  # noqa: E402


# ---------------------------------------------------------------------------
# (a) maximum entropy = exponential family with weights from the dual
# ---------------------------------------------------------------------------


@checks("eq-maxent-problem", "02a6c56e")
@checks("eq-maxent-solution", "4526ce08")
@checks("eq-maxent-dual", "a4ce3354")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_maxent_primal_equals_exponential_family(seed):
    rng = np.random.default_rng(seed)
    n_outcomes, n_features = 8, 3
    F = rng.normal(size=(n_outcomes, n_features))
    mu_hat = rng.dirichlet(np.ones(n_outcomes)) @ F  # feasible, interior target

    def neg_entropy(p):
        p = np.clip(p, 1e-12, None)
        return float(np.sum(p * np.log(p)))

    constraints = [
        {"type": "eq", "fun": lambda p: np.sum(p) - 1.0},
        {"type": "eq", "fun": lambda p: F.T @ p - mu_hat},
    ]
    primal = minimize(
        neg_entropy,
        np.full(n_outcomes, 1.0 / n_outcomes),
        method="SLSQP",
        bounds=[(0.0, 1.0)] * n_outcomes,
        constraints=constraints,
        options={"ftol": 1e-14, "maxiter": 1000},
    )
    assert primal.success
    dual = minimize(
        lm.maxent_dual,
        np.zeros(n_features),
        args=(F, mu_hat),
        jac=lm.maxent_dual_grad,
        method="BFGS",
        options={"gtol": 1e-11},
    )
    p_w = lm.exponential_family(F, dual.x)
    np.testing.assert_allclose(p_w @ F, mu_hat, atol=1e-7)  # w satisfies the constraints
    np.testing.assert_allclose(primal.x, p_w, atol=2e-5)
    # Strong duality: the optimal entropy equals the minimum of the dual.
    entropy = -np.sum(p_w * np.log(p_w))
    assert entropy == pytest.approx(lm.maxent_dual(dual.x, F, mu_hat), abs=1e-8)


@checks("eq-maxent-solution", "4526ce08")
def test_maxent_solution_beats_every_feasible_perturbation():
    """H(q) = H(p_w) - KL(q || p_w) for every feasible q (the Gibbs proof)."""
    rng = np.random.default_rng(3)
    F = rng.normal(size=(7, 2))
    w = rng.normal(size=2)
    p_w = lm.exponential_family(F, w)
    mu_hat = p_w @ F
    # Directions that keep sum(q) = 1 and E_q[F] = mu_hat.
    constraint_matrix = np.vstack([np.ones(7), F.T])
    null_space = np.linalg.svd(constraint_matrix)[2][constraint_matrix.shape[0]:]
    for _ in range(50):
        q = p_w + 0.02 * (rng.normal(size=null_space.shape[0]) @ null_space)
        if np.any(q <= 0):
            continue
        np.testing.assert_allclose(q @ F, mu_hat, atol=1e-12)
        h_q = -np.sum(q * np.log(q))
        h_p = -np.sum(p_w * np.log(p_w))
        kl = np.sum(q * np.log(q / p_w))
        assert h_q == pytest.approx(h_p - kl, abs=1e-12)
        assert h_q < h_p


# ---------------------------------------------------------------------------
# (b) occupancy measures: flow constraints and the occupancy identity
# ---------------------------------------------------------------------------


@checks("eq-marginal-recursion", "5c2ca5e7")
@checks("eq-occ-finite", "e11089a6")
@checks("eq-flow-finite", "914b97d7")
@checks("eq-occupancy-identity", "8dc26784")
@pytest.mark.parametrize("gamma", [1.0, 0.8])
def test_occupancy_identity_finite_horizon_by_enumeration(gamma):
    rng = np.random.default_rng(4)
    P, p0, f = random_mdp(rng, n_states=3, n_actions=2, n_features=2)
    horizon = 4
    pi = random_policy(rng, horizon, 3, 2)

    expected = np.zeros(2)
    total = 0.0
    for traj, prob in enumerate_trajectories(P, p0, pi):
        total += prob
        expected += prob * sum(gamma**t * f[s, a] for t, (s, a) in enumerate(traj))
    assert total == pytest.approx(1.0)

    rho = lm.occupancy_finite(P, p0, pi, gamma)
    np.testing.assert_allclose(lm.occupancy_weighted_features(rho, f), expected, atol=1e-12)

    # Flow constraints, one time step at a time (undiscounted marginals).
    d = lm.state_marginals(P, p0, pi)
    rho_t = d[:, :, None] * pi
    np.testing.assert_allclose(rho_t[0].sum(axis=1), p0)
    for t in range(1, horizon):
        inflow = np.einsum("sa,sax->x", rho_t[t - 1], P)
        np.testing.assert_allclose(rho_t[t].sum(axis=1), inflow, atol=1e-12)
    # Total mass of the discounted occupancy.
    assert rho.sum() == pytest.approx(np.sum(gamma ** np.arange(horizon)))


@checks("eq-occ-discounted", "af332a3b")
@checks("eq-flow-state", "82867720")
@checks("eq-flow-sa", "53c8964f")
@checks("eq-occupancy-identity", "8dc26784")
def test_occupancy_identity_discounted():
    rng = np.random.default_rng(5)
    n_states, n_actions, gamma = 5, 3, 0.9
    P, p0, f = random_mdp(rng, n_states, n_actions, n_features=2)
    pi = random_policy(rng, n_states, n_actions)
    rho_s, rho_sa = lm.occupancy_discounted(P, p0, pi, gamma)

    # Flow constraints.
    np.testing.assert_allclose(rho_sa, pi * rho_s[:, None])
    inflow = p0 + gamma * np.einsum("sa,sax->x", rho_sa, P)
    np.testing.assert_allclose(rho_s, inflow, atol=1e-12)
    assert rho_s.sum() == pytest.approx(1.0 / (1.0 - gamma))

    # Independent route 1: policy evaluation with the features as rewards
    # (the Bellman equation V = f_pi + gamma P_pi V), then average over p0.
    P_pi = np.einsum("sa,sax->sx", pi, P)
    f_pi = np.einsum("sa,sak->sk", pi, f)
    values = np.linalg.solve(np.eye(n_states) - gamma * P_pi, f_pi)
    np.testing.assert_allclose(lm.occupancy_weighted_features(rho_sa, f), p0 @ values, atol=1e-10)

    # Independent route 2: Monte Carlo over sampled trajectories.
    n_episodes, horizon = 20000, 200  # gamma^200 < 1e-9
    cum_P = np.cumsum(P, axis=2)
    cum_pi = np.cumsum(pi, axis=1)
    s = rng.choice(n_states, size=n_episodes, p=p0)
    returns = np.zeros((n_episodes, 2))
    for t in range(horizon):
        a = (rng.random((n_episodes, 1)) > cum_pi[s]).sum(axis=1)
        a = np.minimum(a, n_actions - 1)
        returns += gamma**t * f[s, a]
        s = np.minimum((rng.random((n_episodes, 1)) > cum_P[s, a]).sum(axis=1), n_states - 1)
    mc_mean = returns.mean(axis=0)
    mc_se = returns.std(axis=0) / np.sqrt(n_episodes)
    assert np.all(np.abs(mc_mean - lm.occupancy_weighted_features(rho_sa, f)) < 5 * mc_se)

    # Converse: the policy read off the occupancy reproduces the occupancy.
    pi_back = lm.policy_from_occupancy(rho_sa)
    np.testing.assert_allclose(lm.occupancy_discounted(P, p0, pi_back, gamma)[1], rho_sa, atol=1e-10)


# ---------------------------------------------------------------------------
# (c) MaxEnt IRL: likelihood gradient, deterministic and causal versions
# ---------------------------------------------------------------------------


def deterministic_mdp(rng, n_states, n_actions):
    next_state = rng.integers(n_states, size=(n_states, n_actions))
    P = np.zeros((n_states, n_actions, n_states))
    P[np.arange(n_states)[:, None], np.arange(n_actions)[None, :], next_state] = 1.0
    return P


@checks("eq-soft-q", "5603f823")
@checks("eq-soft-v", "319357d0")
@checks("eq-soft-policy", "0549568e")
def test_soft_policy_reproduces_trajectory_distribution_deterministic():
    """With deterministic dynamics, prod_t pi_t(a_t|s_t) = exp(R(tau)) / Z(s_0)."""
    rng = np.random.default_rng(6)
    n_states, n_actions, horizon = 4, 3, 4
    P = deterministic_mdp(rng, n_states, n_actions)
    r = rng.normal(size=(n_states, n_actions))
    _, V, pi = lm.soft_value_iteration(P, r, horizon)
    p0 = np.eye(n_states)[1]
    trajs, probs = zip(*enumerate_trajectories(P, p0, pi))
    returns = np.array([sum(r[s, a] for s, a in traj) for traj in trajs])
    assert len(trajs) == n_actions**horizon  # every action sequence is feasible once
    np.testing.assert_allclose(np.array(probs), np.exp(returns - logsumexp(returns)), atol=1e-12)
    assert V[0, 1] == pytest.approx(logsumexp(returns))  # V_0(s_0) = log Z(s_0)


@checks("eq-irl-loglik", "37404f5e")
@checks("eq-irl-gradient", "6a71fb1a")
@checks("eq-irl-gradient-visits", "671c734b")
@checks("eq-svf", "c60b4fe5")
def test_irl_gradient_deterministic_matches_finite_difference():
    rng = np.random.default_rng(7)
    n_states, n_actions, horizon, n_features = 5, 3, 5, 3
    P = deterministic_mdp(rng, n_states, n_actions)
    f = rng.normal(size=(n_states, n_actions, n_features))
    start = 2
    p0 = np.eye(n_states)[start]

    # Enumerate the trajectories from s_0 = start (one per action sequence).
    trajs = []
    for actions in itertools.product(range(n_actions), repeat=horizon):
        s, feats = start, np.zeros(n_features)
        for a in actions:
            feats += f[s, a]
            s = int(np.argmax(P[s, a]))
        trajs.append(feats)
    F = np.array(trajs)  # F(tau), undiscounted, t = 0..T-1
    demos = rng.integers(len(F), size=20)  # indices of 20 "demonstrations"
    mu_hat = F[demos].mean(axis=0)  # average per trajectory

    def mean_log_likelihood(w):
        logits = F @ w
        return float(np.mean(logits[demos]) - logsumexp(logits))

    w = rng.normal(size=n_features)
    grad = lm.maxent_irl_gradient(P, p0, f, w, horizon, mu_hat)
    np.testing.assert_allclose(grad, central_difference(mean_log_likelihood, w), atol=1e-7)


@checks("eq-mce-objective", "c18dc17b")
def test_causal_irl_gradient_matches_finite_difference_stochastic():
    rng = np.random.default_rng(8)
    n_states, n_actions, horizon, n_features = 4, 3, 4, 3
    P, p0, f = random_mdp(rng, n_states, n_actions, n_features)
    mu_hat = rng.normal(size=n_features)
    w = rng.normal(size=n_features)

    def objective(weights):
        return lm.causal_dual_objective(P, p0, f, weights, horizon, mu_hat)

    grad = lm.maxent_irl_gradient(P, p0, f, w, horizon, mu_hat)
    np.testing.assert_allclose(grad, central_difference(objective, w), atol=1e-7)


@checks("eq-mce-objective", "c18dc17b")
def test_causal_objective_is_expected_causal_log_likelihood():
    """E_{tau ~ pi_D}[sum_t log pi^w_t(a_t|s_t)] = w.mu_D - E_{p0} V_0 (exact enumeration)."""
    rng = np.random.default_rng(9)
    n_states, n_actions, horizon, n_features = 3, 2, 3, 2
    P, p0, f = random_mdp(rng, n_states, n_actions, n_features)
    w = rng.normal(size=n_features)
    _, _, pi_w = lm.soft_value_iteration(P, f @ w, horizon)
    pi_data = random_policy(rng, horizon, n_states, n_actions)  # any demonstrator

    expected_loglik, mu_data = 0.0, np.zeros(n_features)
    for traj, prob in enumerate_trajectories(P, p0, pi_data):
        expected_loglik += prob * sum(np.log(pi_w[t, s, a]) for t, (s, a) in enumerate(traj))
        mu_data += prob * sum(f[s, a] for s, a in traj)
    assert lm.causal_dual_objective(P, p0, f, w, horizon, mu_data) == pytest.approx(
        expected_loglik, abs=1e-12
    )


@checks("eq-maxent-2008", "d6c67072")
def test_risky_lottery_example():
    """Chapter 3's example: trajectory-level form is optimistic, causal form is not."""
    stake = 4.0
    outcomes = np.array([stake, -stake])  # risky action: +4 or -4 with prob 1/2
    causal_q = np.array([0.5 * outcomes.sum(), 0.0])  # Q(risky), Q(safe)
    pi_causal = np.exp(causal_q - logsumexp(causal_q))
    weight_risky = 0.5 * np.exp(outcomes).sum()  # sum_tau P(tau) exp(R(tau))
    p_risky_2008 = weight_risky / (weight_risky + 1.0)
    assert pi_causal[0] == pytest.approx(0.5)
    assert p_risky_2008 == pytest.approx(0.965, abs=5e-4)
    # The soft backward pass computes the causal answer.
    P = np.zeros((3, 2, 3))
    P[0, 0, 1] = P[0, 0, 2] = 0.5  # risky: to s1 (+4) or s2 (-4)
    P[0, 1, 0] = 1.0  # safe: stay
    P[1, :, 1] = P[2, :, 2] = 1.0
    r = np.zeros((2, 3, 2))
    r[1, 1, :] = stake - np.log(2)  # step 1 reward, minus log |A| so V_1 = reward exactly
    r[1, 2, :] = -stake - np.log(2)
    r[1, 0, :] = -np.log(2)
    _, _, pi = lm.soft_value_iteration(P, r, horizon=2)
    assert pi[0, 0, 0] == pytest.approx(pi_causal[0])


# ---------------------------------------------------------------------------
# (d) the KL-regularised optimum
# ---------------------------------------------------------------------------


@checks("eq-kl-objective", "d1aabb94")
@checks("eq-kl-optimum", "f52a9f5f")
@pytest.mark.parametrize("beta", [0.3, 1.0, 4.0])
def test_kl_regularised_optimum_matches_generic_optimiser(beta):
    rng = np.random.default_rng(10)
    n = 6
    pi_ref = rng.dirichlet(np.ones(n))
    r = rng.normal(size=n)

    def neg_objective(pi):
        pi = np.clip(pi, 1e-12, None)
        return -(pi @ r - beta * np.sum(pi * np.log(pi / pi_ref)))

    result = minimize(
        neg_objective,
        pi_ref.copy(),
        method="SLSQP",
        bounds=[(0.0, 1.0)] * n,
        constraints=[{"type": "eq", "fun": lambda p: p.sum() - 1.0}],
        options={"ftol": 1e-14, "maxiter": 1000},
    )
    assert result.success
    pi_star = lm.kl_regularised_optimum(pi_ref, r, beta)
    np.testing.assert_allclose(result.x, pi_star, atol=1e-5)
    # The optimal value is beta log Z.
    log_z = logsumexp(np.log(pi_ref) + r / beta)
    assert -neg_objective(pi_star) == pytest.approx(beta * log_z, abs=1e-10)


# ---------------------------------------------------------------------------
# (e) DPO: gradient, and equality with the Bradley-Terry likelihood
# ---------------------------------------------------------------------------


def preference_data(rng, n_prompts, n_responses, n_pairs):
    prompts = rng.integers(n_prompts, size=n_pairs)
    chosen = rng.integers(n_responses, size=n_pairs)
    rejected = (chosen + rng.integers(1, n_responses, size=n_pairs)) % n_responses
    return prompts, chosen, rejected


@checks("eq-dpo-loss", "655897a3")
@checks("eq-dpo-grad", "e9c312e0")
def test_dpo_gradient_matches_finite_difference():
    rng = np.random.default_rng(11)
    n_prompts, n_responses, beta = 3, 5, 0.5
    prompts, chosen, rejected = preference_data(rng, n_prompts, n_responses, 40)
    ref_logp = np.log(rng.dirichlet(np.ones(n_responses), size=n_prompts))
    theta = rng.normal(size=(n_prompts, n_responses))

    def loss(th):
        logp = th - logsumexp(th, axis=1, keepdims=True)
        return lm.dpo_loss(
            logp[prompts, chosen],
            logp[prompts, rejected],
            ref_logp[prompts, chosen],
            ref_logp[prompts, rejected],
            beta,
        )

    grad = lm.dpo_grad_tabular(theta, ref_logp, prompts, chosen, rejected, beta)
    np.testing.assert_allclose(grad, central_difference(loss, theta), atol=1e-8)


@checks("eq-reward-reparam", "54dc0367")
@checks("eq-bt-policy", "30b3eba1")
@checks("eq-dpo-loss", "655897a3")
def test_dpo_objective_is_bradley_terry_likelihood_of_implied_reward():
    rng = np.random.default_rng(12)
    n_prompts, n_responses, beta = 4, 6, 0.7
    prompts, chosen, rejected = preference_data(rng, n_prompts, n_responses, 60)
    pi_ref = rng.dirichlet(np.ones(n_responses), size=n_prompts)

    # (1) For any policy, the BT negative log-likelihood of the implied reward
    #     beta log(pi/pi_ref) + c(x), with an arbitrary per-prompt shift c(x),
    #     equals the DPO loss.
    pi = rng.dirichlet(np.ones(n_responses), size=n_prompts)
    shift = rng.normal(size=(n_prompts, 1)) * 10
    implied = beta * np.log(pi / pi_ref) + shift
    bt_nll = -np.mean(
        log_expit(implied[prompts, chosen] - implied[prompts, rejected])
    )
    dpo = lm.dpo_loss(
        np.log(pi[prompts, chosen]),
        np.log(pi[prompts, rejected]),
        np.log(pi_ref[prompts, chosen]),
        np.log(pi_ref[prompts, rejected]),
        beta,
    )
    assert dpo == pytest.approx(bt_nll, abs=1e-12)

    # (2) At pi = pi* for a reward r, the DPO loss is the BT loss of r itself:
    #     the partition function Z(x) cancels.
    r = rng.normal(size=(n_prompts, n_responses))
    pi_star = lm.kl_regularised_optimum(pi_ref, r, beta)
    dpo_star = lm.dpo_loss(
        np.log(pi_star[prompts, chosen]),
        np.log(pi_star[prompts, rejected]),
        np.log(pi_ref[prompts, chosen]),
        np.log(pi_ref[prompts, rejected]),
        beta,
    )
    bt_r = -np.mean(log_expit(r[prompts, chosen] - r[prompts, rejected]))
    assert dpo_star == pytest.approx(bt_r, abs=1e-12)


# ---------------------------------------------------------------------------
# (f) Bradley-Terry, Plackett-Luce, ties, MM, winners
# ---------------------------------------------------------------------------


@checks("eq-plackett-luce", "94f4c78d")
@checks("eq-bt", "e1e5b35c")
def test_plackett_luce_two_items_is_bradley_terry():
    rng = np.random.default_rng(13)
    for _ in range(20):
        u = rng.normal(size=2) * 3
        assert lm.plackett_luce_prob(u, np.array([0, 1])) == pytest.approx(
            float(lm.bradley_terry_prob(u[0], u[1])), abs=1e-14
        )


@checks("eq-plackett-luce", "94f4c78d")
def test_plackett_luce_is_a_distribution_and_matches_gumbel_sampling():
    rng = np.random.default_rng(14)
    u = rng.normal(size=4)
    perms = list(itertools.permutations(range(4)))
    probs = np.array([lm.plackett_luce_prob(u, np.array(p)) for p in perms])
    assert probs.sum() == pytest.approx(1.0, abs=1e-12)
    # Ranking by u_i + Gumbel noise is an independent sampler of Plackett-Luce.
    n = 200_000
    orders = np.argsort(-(u + rng.gumbel(size=(n, 4))), axis=1)
    codes = orders @ (4 ** np.arange(4)[::-1])
    perm_codes = np.array(perms) @ (4 ** np.arange(4)[::-1])
    freq = np.array([(codes == c).mean() for c in perm_codes])
    se = np.sqrt(probs * (1 - probs) / n)
    assert np.all(np.abs(freq - probs) < 5 * se + 1e-4)


@checks("eq-bt-loglik", "8928ba20")
@checks("eq-bt-grad", "2f0dab09")
@checks("eq-mm-update", "99523cd7")
def test_bt_gradient_and_mm_reach_the_logistic_mle():
    rng = np.random.default_rng(15)
    k = 5
    u_true = rng.normal(size=k)
    pairs = np.array([(i, j) for i in range(k) for j in range(k) if i < j] * 30)
    i_idx, j_idx = pairs[:, 0], pairs[:, 1]
    i_wins = rng.random(len(pairs)) < expit(u_true[i_idx] - u_true[j_idx])
    winners = np.where(i_wins, i_idx, j_idx)
    losers = np.where(i_wins, j_idx, i_idx)

    u0 = rng.normal(size=k)
    np.testing.assert_allclose(
        lm.bt_gradient(u0, winners, losers),
        central_difference(lambda u: lm.bt_log_likelihood(u, winners, losers), u0),
        atol=1e-6,
    )
    # Identifiability: adding a constant changes nothing.
    assert lm.bt_log_likelihood(u0 + 3.0, winners, losers) == pytest.approx(
        lm.bt_log_likelihood(u0, winners, losers)
    )
    # MLE by a generic optimiser (logistic regression), centred.
    mle = minimize(
        lambda u: -lm.bt_log_likelihood(u, winners, losers),
        np.zeros(k),
        jac=lambda u: -lm.bt_gradient(u, winners, losers),
        method="BFGS",
        options={"gtol": 1e-10},
    ).x
    mle -= mle.mean()
    # MM iterations (Hunter 2004).
    wins = np.bincount(winners, minlength=k).astype(float)
    counts = np.zeros((k, k))
    np.add.at(counts, (i_idx, j_idx), 1.0)
    counts += counts.T
    gamma = np.full(k, 1.0 / k)
    previous = -np.inf
    for _ in range(2000):
        gamma = lm.mm_update(gamma, wins, counts)
        current = lm.bt_log_likelihood(np.log(gamma), winners, losers)
        assert current >= previous - 1e-9  # monotone ascent
        previous = current
    u_mm = np.log(gamma)
    np.testing.assert_allclose(u_mm - u_mm.mean(), mle, atol=1e-6)


@checks("eq-rao-kupper", "48db9141")
@checks("eq-davidson", "a7ba7990")
def test_tie_models_are_distributions_and_reduce_to_bt():
    rng = np.random.default_rng(16)
    for _ in range(20):
        ui, uj = rng.normal(size=2)
        theta, nu = 1.0 + rng.random() * 3, rng.random() * 2
        assert sum(lm.rao_kupper_probs(ui, uj, theta)) == pytest.approx(1.0)
        assert sum(lm.davidson_probs(ui, uj, nu)) == pytest.approx(1.0)
        bt = float(expit(ui - uj))
        assert lm.rao_kupper_probs(ui, uj, 1.0)[0] == pytest.approx(bt)
        assert lm.davidson_probs(ui, uj, 0.0)[0] == pytest.approx(bt)


@checks("eq-bt", "e1e5b35c")
def test_bt_strong_stochastic_transitivity():
    rng = np.random.default_rng(17)
    for _ in range(200):
        u = rng.normal(size=3)
        p = expit(u[:, None] - u[None, :])
        for i, j, k in itertools.permutations(range(3)):
            if p[i, j] >= 0.5 and p[j, k] >= 0.5:
                assert p[i, k] >= max(p[i, j], p[j, k]) - 1e-15


@checks("eq-copeland", "2c93e163")
@checks("eq-borda", "c82237ff")
def test_winner_definitions_on_the_lecture_example():
    """The 4-arm matrix of chapter 5: Condorcet = Copeland = A, Borda = B."""
    p = np.array(
        [
            [0.50, 0.55, 0.55, 0.55],
            [0.45, 0.50, 0.95, 0.95],
            [0.45, 0.05, 0.50, 0.50],
            [0.45, 0.05, 0.50, 0.50],
        ]
    )
    np.testing.assert_allclose(p + p.T, 1.0)
    copeland = lm.copeland_scores(p)
    borda = lm.borda_scores(p)
    np.testing.assert_array_equal(copeland, [3, 2, 0, 0])
    assert int(np.argmax(borda)) == 1
    # Borda score = win rate against a uniformly drawn opponent (simulation).
    rng = np.random.default_rng(18)
    opponents = rng.choice([0, 2, 3], size=100_000)
    wins = rng.random(100_000) < p[1, opponents]
    assert wins.mean() == pytest.approx(borda[1], abs=0.01)


# ---------------------------------------------------------------------------
# (g) best-of-n
# ---------------------------------------------------------------------------


@checks("eq-bon-discrete", "0b8941bd")
def test_best_of_n_distribution_by_enumeration():
    rng = np.random.default_rng(19)
    q = rng.dirichlet(np.ones(5))  # atoms already sorted by increasing reward
    n = 3
    exact = np.zeros(5)
    for draw in itertools.product(range(5), repeat=n):
        exact[max(draw)] += np.prod(q[list(draw)])
    np.testing.assert_allclose(lm.best_of_n_probs(q, n), exact, atol=1e-14)


@checks("eq-bon-kl", "c88ef030")
@pytest.mark.parametrize("n", [2, 4, 16, 64])
def test_best_of_n_kl_formula_in_the_fine_grid_limit(n):
    fine = np.full(200_000, 1.0 / 200_000)
    assert lm.best_of_n_kl(fine, n) == pytest.approx(lm.best_of_n_kl_formula(n), abs=2e-3)
    # Coarse or uneven discrete bases stay below the formula (upper bound).
    rng = np.random.default_rng(n)
    for size in [2, 5, 50]:
        q = rng.dirichlet(np.ones(size))
        assert lm.best_of_n_kl(q, n) <= lm.best_of_n_kl_formula(n) + 1e-12


# ---------------------------------------------------------------------------
# (h) compounding error: the drift model, and the bounds on random MDPs
# ---------------------------------------------------------------------------


def simulate_drift(eps, horizon, recoverable, n_runs, rng):
    """Monte Carlo of the on-track/off-track chain of chapter 1."""
    off = np.zeros(n_runs, dtype=bool)
    cost = np.zeros(n_runs)
    for _ in range(horizon):
        cost += off
        mistake = rng.random(n_runs) < eps
        if recoverable:
            off = mistake  # from either state, only a mistake leaves/keeps us off track
        else:
            off = off | mistake  # off track is absorbing
    return cost.mean(), cost.std() / np.sqrt(n_runs)


@checks("eq-drift-bc", "ba888058")
@checks("eq-drift-dagger", "17c3df78")
def test_drift_model_quadratic_versus_linear():
    rng = np.random.default_rng(20)
    eps = 0.002
    horizons = np.array([10, 20, 40, 80])
    bc, dagger = [], []
    for horizon in horizons:
        m_bc, se_bc = simulate_drift(eps, horizon, False, 100_000, rng)
        m_dg, se_dg = simulate_drift(eps, horizon, True, 100_000, rng)
        assert abs(m_bc - lm.drift_cost_bc(eps, horizon)) < 5 * se_bc + 1e-9
        assert abs(m_dg - lm.drift_cost_dagger(eps, horizon)) < 5 * se_dg + 1e-9
        bc.append(lm.drift_cost_bc(eps, horizon))
        dagger.append(lm.drift_cost_dagger(eps, horizon))
    slope_bc = np.polyfit(np.log(horizons), np.log(bc), 1)[0]
    slope_dagger = np.polyfit(np.log(horizons), np.log(dagger), 1)[0]
    assert 1.8 < slope_bc < 2.2
    assert 0.9 < slope_dagger < 1.15
    for horizon, cost in zip(horizons, bc):
        assert cost <= horizon**2 * eps  # the T^2 eps bound
        assert cost >= 0.4 * horizon**2 * eps  # and it is attained up to a constant


# ---------------------------------------------------------------------------
# the per-step constant that segment comparisons cannot identify (lecture 6)
# ---------------------------------------------------------------------------
@checks("eq-segment-bt", "4927e9ff")
def test_segment_comparisons_ignore_a_per_step_constant_that_early_termination_does_not():
    """Equal-length segments: P(a > b) is unchanged by r -> r + c. An MDP whose "fall" action ends the
    episode: the optimal first action flips from staying up to falling as c goes from +1 to -1."""
    rng = np.random.default_rng(3)
    seg_a, seg_b = rng.normal(size=(50, 7)), rng.normal(size=(50, 7))
    for c in (-2.0, 0.5, 3.0):
        assert np.allclose(lm.bradley_terry_prob((seg_a + c).sum(1), (seg_b + c).sum(1)),
                           lm.bradley_terry_prob(seg_a.sum(1), seg_b.sum(1)))
    # Unequal lengths (a segment cut short by a fall) do see the constant.
    assert not np.allclose(lm.bradley_terry_prob((seg_a[:, :4] + 1.0).sum(1), (seg_b + 1.0).sum(1)),
                           lm.bradley_terry_prob(seg_a[:, :4].sum(1), seg_b.sum(1)))

    # States 0..3, action 0 "walk" (reward r[s], next state uniform), action 1 "lunge": reward r[s] + 0.5,
    # then the episode ends. Horizon 20. Backward induction with termination.
    n_states, horizon = 4, 20
    r = rng.uniform(-0.2, 0.2, size=n_states)

    def first_action(c: float) -> np.ndarray:
        V = np.zeros(n_states)
        for _ in range(horizon):
            q_walk = r + c + V.mean()
            q_lunge = r + 0.5 + c
            V = np.maximum(q_walk, q_lunge)
        return (q_lunge > q_walk).astype(int)

    assert (first_action(+1.0) == 0).all() and (first_action(-1.0) == 1).all()


def _fit_segment_bt(features: np.ndarray, first_wins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximum-likelihood weights of sigma(features @ w) for Bernoulli outcomes (scipy's BFGS), and the
    Fisher information at the optimum."""
    nll = lambda w: -(first_wins * log_expit(features @ w) + (1 - first_wins) * log_expit(-features @ w)).sum()
    grad = lambda w: -features.T @ (first_wins - expit(features @ w))
    w = minimize(nll, np.zeros(features.shape[1]), jac=grad, method="BFGS", options={"gtol": 1e-8}).x
    p = expit(features @ w)
    return w, (features * (p * (1 - p))[:, None]).T @ features


@checks("eq-absorbing-return", "79b8b059")
def test_pairs_with_a_fall_identify_the_upright_constant_that_upright_pairs_cannot():
    """Upright reward x . w + c per step, absorbing state 0, segments of L = 10 steps. Pairs labelled by
    Bradley-Terry on the returns of eq-absorbing-return. Fitting (w, c - r_abs) by maximum likelihood: with
    falls in the data the constant is recovered; with upright segments only, the Fisher information is
    singular along it (the likelihood is flat in c). And the invariance the lecture states: adding a
    constant to the upright steps and to the absorbing state alike changes no probability."""
    rng = np.random.default_rng(7)
    L, n_pairs, dim = 10, 20_000, 3
    w_true, c_true, r_abs = np.array([0.4, -0.3, 0.2]), 1.0, 0.0

    def segments(n: int, fall_rate: float) -> tuple[np.ndarray, np.ndarray]:
        x = rng.normal(size=(n, L, dim))
        k = np.where(rng.random(n) < fall_rate, rng.integers(1, L, size=n), L)  # real steps
        return x, k

    def returns(x, k, w, c, absorbing):
        real = np.arange(L) < k[:, None]
        return ((x @ w + c) * real).sum(1) + (L - k) * absorbing

    for fall_rate in (0.3, 0.0):
        (xa, ka), (xb, kb) = segments(n_pairs, fall_rate), segments(n_pairs, fall_rate)
        first_wins = (rng.random(n_pairs) < expit(returns(xa, ka, w_true, c_true, r_abs)
                                                  - returns(xb, kb, w_true, c_true, r_abs))).astype(float)
        # R_a - R_b is linear in (w, d = c - r_abs): features are the summed real-step x and k_a - k_b
        real_sum = lambda x, k: (x * (np.arange(L) < k[:, None])[..., None]).sum(1)
        features = np.column_stack([real_sum(xa, ka) - real_sum(xb, kb), ka - kb])
        w_fit, fisher = _fit_segment_bt(features, first_wins)
        if fall_rate > 0:
            assert abs(w_fit[-1] - (c_true - r_abs)) < 0.1, f"fitted constant {w_fit[-1]:.3f}, true {c_true - r_abs}"
            assert np.allclose(w_fit[:dim], w_true, atol=0.05)
            assert np.linalg.eigvalsh(fisher).min() > 100.0
        else:
            assert np.abs(fisher[-1]).max() == 0.0  # k_a - k_b = 0 on every pair: no information on c
            assert abs(w_fit[-1]) < 1e-6  # the optimiser never moves it from where it started
    # Shifting the upright reward and the absorbing reward by the same constant changes no probability;
    # shifting only the upright reward changes those of pairs whose segments differ in length.
    x1, k1 = segments(200, 0.5)
    x2, k2 = segments(200, 0.5)
    p = lambda c, a: lm.bradley_terry_prob(returns(x1, k1, w_true, c, a), returns(x2, k2, w_true, c, a))
    assert np.allclose(p(3.0, 2.0), p(1.0, 0.0))
    differ = k1 != k2
    assert differ.any() and not np.allclose(p(2.0, 0.0)[differ], p(1.0, 0.0)[differ])
    assert np.allclose(p(2.0, 0.0)[~differ], p(1.0, 0.0)[~differ])
