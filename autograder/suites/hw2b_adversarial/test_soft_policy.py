"""Hidden tests of hw2b's `soft_policy`."""
import numpy as np

from autograder.suite import check_array, stub

HINT = ("Q_t(s, a) = reward[t, s, a] + sum_s' P[s, a, s'] V_{t+1}(s'), V_t = logsumexp_a Q_t, V_T = 0; "
        "pi_t = exp(Q_t - V_t), shape (T, S, A).")


def _mdp(rng, n_states=9, n_actions=3, branching=3):
    P = np.zeros((n_states, n_actions, n_states))
    for s in range(n_states):
        for a in range(n_actions):
            nxt = rng.choice(n_states, size=branching, replace=False)
            P[s, a, nxt] = rng.dirichlet(np.ones(branching))
    return P


@stub("soft_policy", points=2, hint=HINT)
def test_matches_reference(student, reference, rng):
    """A random MDP with a random time-dependent reward of state and action"""
    P = _mdp(rng)
    reward = rng.normal(size=(7, 9, 3))
    check_array(student.soft_policy(P, reward, 7), reference.soft_policy(P, reward, 7), rtol=1e-6, atol=1e-9,
                name="the policy")


@stub("soft_policy", points=1, hint="Two states, T = 2: the last step is a softmax of the reward alone.")
def test_two_state_chain_by_hand(student, rng):
    """Two states (action 0 stays, action 1 moves to state 1), T = 2, closed forms of both steps"""
    P = np.zeros((2, 2, 2))
    P[:, 0, :] = np.eye(2)
    P[:, 1, 1] = 1.0
    reward = rng.normal(size=(2, 2, 2))
    got = student.soft_policy(P, reward, 2)
    v1 = np.log(np.exp(reward[1]).sum(axis=1))                     # V_1(s)
    q0 = reward[0] + np.stack([v1, np.full(2, v1[1])], axis=1)     # action 0 stays in s, action 1 goes to 1
    want = np.stack([np.exp(q0 - np.log(np.exp(q0).sum(axis=1, keepdims=True))),
                     np.exp(reward[1] - v1[:, None])])
    check_array(got, want, rtol=1e-9, atol=1e-12, name="the policy of the two-state chain")


@stub("soft_policy", points=1, hint="Compute the log-sum-exp stably: subtract the row maximum before exponentiating.")
def test_large_rewards(student, reference, rng):
    """Rewards of a few hundred, spread wide and bunched close: finite and equal to the reference"""
    P = _mdp(rng, 6, 4)
    # Spread wide, every soft maximum is the hard one, so a hard backup (max for log-sum-exp) passed this test alone;
    # bunched within a few units of 300 (the same policy as without the 300), it does not.
    for reward, what in ((300.0 * rng.normal(size=(5, 6, 4)), "spread over a few hundred"),
                         (300.0 + rng.normal(size=(5, 6, 4)), "all near 300")):
        check_array(student.soft_policy(P, reward, 5), reference.soft_policy(P, reward, 5), rtol=1e-6, atol=1e-9,
                    name=f"the policy for rewards {what}")


@stub("soft_policy", points=1, hint="reward[t] is collected at step t only: changing reward[0] changes pi_0 alone.")
def test_reward_is_read_per_step(student, reference, rng):
    """Changing the reward of step 0 changes pi_0 and nothing after it"""
    P = _mdp(rng, 7, 3)
    reward = rng.normal(size=(4, 7, 3))
    bumped = reward.copy()
    bumped[0] += rng.normal(scale=2.0, size=(7, 3))
    a, b = student.soft_policy(P, reward, 4), student.soft_policy(P, bumped, 4)
    check_array(b, reference.soft_policy(P, bumped, 4), rtol=1e-6, atol=1e-9, name="the policy with step 0's reward changed")
    assert np.allclose(a[1:], b[1:], atol=1e-12), "a change of reward[0] changed the policy at later steps"
