"""Hidden tests of state_visitation_frequency."""
import numpy as np

from autograder.suite import check_array, check_scalar, stub
from rlcourse.gridworld import random_mdp, sample_trajectories


def mdp(seed, n_features=4):
    """A random sparse stochastic MDP: S = 15, A = 3, T = 8."""
    return random_mdp(15, 3, n_features, 8, seed=seed)


HINT = ("d = p0; repeat T times: add d to the total, then d = sum over s, a of d(s) pi_t(a|s) P(s'|s,a) using "
        "pi[t] of the current step. The total sums to T.")


def _time_varying_policy(rng, horizon, m):
    return rng.dirichlet(np.ones(m.n_actions), size=(horizon, m.n_states))


@stub("state_visitation_frequency", points=2, hint=HINT)
def test_matches_reference(student, reference, rng):
    """A random time-dependent policy on a random MDP, T = 9"""
    m = mdp(11)
    policy = _time_varying_policy(rng, 9, m)
    check_array(student.state_visitation_frequency(m.P, policy, m.p0, 9),
                reference.state_visitation_frequency(m.P, policy, m.p0, 9), rtol=1e-6, atol=1e-10)


@stub("state_visitation_frequency", points=1, hint=HINT)
def test_sums_to_horizon_and_starts_at_p0(student, reference, rng):
    """sum(D) == T for T = 1, 4, 13, D == p0 when T = 1, and D moves with the dynamics (not T * p0) for T = 4"""
    m = mdp(12)
    for horizon in (1, 4, 13):
        got = student.state_visitation_frequency(m.P, _time_varying_policy(rng, horizon, m), m.p0, horizon)
        check_scalar(float(np.sum(got)), float(horizon), name=f"the total expected visits for T = {horizon}")
    check_array(student.state_visitation_frequency(m.P, _time_varying_policy(rng, 1, m), m.p0, 1), m.p0,
                name="D for T = 1")
    policy = _time_varying_policy(rng, 4, m)
    got = student.state_visitation_frequency(m.P, policy, m.p0, 4)
    assert not np.allclose(got, 4 * m.p0), "D for T = 4 is T * p0: the distribution must move with P and pi after each step"
    check_array(got, reference.state_visitation_frequency(m.P, policy, m.p0, 4), name="D for T = 4")


@stub("state_visitation_frequency", points=1, hint=HINT)
def test_agrees_with_monte_carlo(student, rng):
    """Within 5 standard errors of 20,000 sampled trajectories, and exact for T = 2"""
    m = mdp(13)
    policy = _time_varying_policy(rng, 6, m)
    got = student.state_visitation_frequency(m.P, policy, m.p0, 6)
    states = sample_trajectories(m.P, policy, m.p0, 20000, rng).states
    counts = np.stack([np.bincount(row, minlength=m.n_states) for row in states])  # (N, S)
    mean, stderr = counts.mean(axis=0), counts.std(axis=0) / np.sqrt(len(counts)) + 1e-3
    worst = np.max(np.abs(np.asarray(got) - mean) / stderr)
    assert worst < 5, f"D differs from a Monte-Carlo estimate by {worst:.1f} standard errors at some state"
    # ...and is exact where a hand computation is: a Monte-Carlo estimate itself (sample_trajectories is released)
    # passed the comparison above alone, 1 of 5 points for no forward pass.
    two = _time_varying_policy(rng, 2, m)
    by_hand = m.p0 + np.einsum("s,sa,sab->b", m.p0, two[0], m.P)           # Pr(s_0 = s) + Pr(s_1 = s)
    check_array(student.state_visitation_frequency(m.P, two, m.p0, 2), by_hand, rtol=1e-9, atol=1e-12,
                name="D for T = 2 (p0 plus one step of the dynamics under pi_0: exact, not estimated)")


@stub("state_visitation_frequency", points=1,
      hint="The analytic gradient mu_E - phi^T D must be the derivative of the expected log-likelihood: check "
           "that D uses pi_t at step t.")
def test_gradient_matches_finite_difference(student, reference, rng):
    """mu_E - phi^T D(w) equals a central finite difference of the expected causal log-likelihood"""
    m = mdp(14, n_features=3)
    expert = reference.soft_value_iteration(m.P, m.true_reward, m.horizon)
    svf = [reference.state_visitation_frequency(m.P, expert, m.p0, t) for t in range(m.horizon + 1)]
    occ = np.diff(np.array(svf), axis=0)                    # (T, S): Pr(s_t = s)
    mu_expert = m.features.T @ occ.sum(axis=0)

    # The policies are the reference's soft_value_iteration's: with the student's, a correct forward pass beside a
    # missing or wrong backward pass lost this point too.
    def loglik(w):
        log_pi = np.log(reference.soft_value_iteration(m.P, m.features @ w, m.horizon))
        return float(np.sum(occ[:, :, None] * expert * log_pi))

    w = rng.normal(size=3)
    visits = student.state_visitation_frequency(m.P, reference.soft_value_iteration(m.P, m.features @ w, m.horizon),
                                                m.p0, m.horizon)
    analytic = mu_expert - m.features.T @ np.asarray(visits)
    eps = 1e-5
    numeric = np.array([(loglik(w + eps * e) - loglik(w - eps * e)) / (2 * eps) for e in np.eye(3)])
    check_array(analytic, numeric, rtol=1e-4, atol=1e-5, name="the analytic gradient")
