"""Hidden tests of soft_value_iteration."""
import numpy as np
from scipy.special import logsumexp

from autograder.suite import check_array, stub
from rlcourse.gridworld import random_mdp


def mdp(seed, n_features=4):
    """A random sparse stochastic MDP: S = 15, A = 3, T = 8."""
    return random_mdp(15, 3, n_features, 8, seed=seed)


HINT = ("V_T = 0; for t = T-1..0: Q = r[:, None] + P @ V_next, V = logsumexp(Q, axis=1) computed stably "
        "(subtract the row max), pi[t] = exp(Q - V[:, None]). Return (T, S, A).")


@stub("soft_value_iteration", points=2, hint=HINT)
def test_matches_reference(student, reference, rng):
    """Random sparse stochastic MDPs (S = 15, A = 3) and horizons 1, 2 and 8"""
    for seed, horizon in ((1, 8), (2, 2), (3, 1)):
        m = mdp(seed)
        reward = rng.normal(size=m.n_states)
        check_array(student.soft_value_iteration(m.P, reward, horizon),
                    reference.soft_value_iteration(m.P, reward, horizon), rtol=1e-6, atol=1e-9,
                    name=f"the policy for T = {horizon}")


@stub("soft_value_iteration", points=1, hint=HINT)
def test_distributions_and_last_step(student, rng):
    """Each pi[t, s] sums to one; the last step is uniform; the step before it is softmax_a(P[s, a] . r)"""
    m = mdp(4)
    reward = rng.normal(size=m.n_states)
    pi = student.soft_value_iteration(m.P, reward, 6)
    assert np.shape(pi) == (6, m.n_states, m.n_actions), f"expected shape (T, S, A) = (6, 15, 3), got {np.shape(pi)}"
    check_array(pi.sum(axis=-1), np.ones((6, m.n_states)), name="the sum over actions of pi[t, s]")
    check_array(pi[-1], np.full((m.n_states, m.n_actions), 1.0 / m.n_actions), name="pi at the last step t = T-1")
    # V_{T-1}(s') = r(s') + log A, so pi_{T-2}(a|s) is proportional to exp(P[s, a] . r): a closed form.
    logits = m.P @ reward
    closed = np.exp(logits - logits.max(axis=1, keepdims=True))
    check_array(pi[-2], closed / closed.sum(axis=1, keepdims=True), rtol=1e-6, atol=1e-9,
                name="pi at t = T-2 (one step of look-ahead: softmax over a of sum_s' P(s'|s,a) r(s'))")
    # Two soft backups by hand: a hard max in place of the log-sum-exp first differs here.
    v = logsumexp(reward[:, None] + m.P @ (reward + np.log(m.n_actions)), axis=1)      # V at t = T-2
    q = reward[:, None] + m.P @ v
    check_array(pi[-3], np.exp(q - logsumexp(q, axis=1, keepdims=True)), rtol=1e-6, atol=1e-9,
                name="pi at t = T-3 (two backups: V(s) is the log-sum-exp of Q(s, .), not its max)")


@stub("soft_value_iteration", points=1, hint=HINT)
def test_extreme_rewards(student, reference, rng):
    """Rewards of +-100 and +-1000 over 20 steps: no overflow, same policy as the reference"""
    m = mdp(5)
    for scale in (100.0, 1000.0):
        reward = scale * rng.choice([-1.0, 1.0], size=m.n_states)
        check_array(student.soft_value_iteration(m.P, reward, 20), reference.soft_value_iteration(m.P, reward, 20),
                    rtol=1e-5, atol=1e-8, name=f"the policy with rewards of +-{scale:g}")


@stub("soft_value_iteration", points=1, hint=HINT)
def test_invariant_to_constant_shift(student, reference, rng):
    """pi(r + c) == pi(r) for c = 5 and c = -40, and pi(r) is the soft-optimal policy"""
    m = mdp(6)
    reward = rng.normal(size=m.n_states)
    base = student.soft_value_iteration(m.P, reward, 7)
    check_array(base, reference.soft_value_iteration(m.P, reward, 7), rtol=1e-6, atol=1e-9, name="the policy of r")
    for c in (5.0, -40.0):
        check_array(student.soft_value_iteration(m.P, reward + c, 7), base, rtol=1e-6, atol=1e-9,
                    name=f"the policy of r + {c:g} (should equal that of r)")
