"""Hidden tests of hw2b's `state_distributions`."""
import numpy as np

from autograder.suite import check_array, stub

HINT = "d[0] = p0, d[t + 1, s'] = sum_{s, a} d[t, s] policy[t, s, a] P[s, a, s']; shape (T, S)."


def _mdp(rng, n_states=8, n_actions=3):
    P = rng.dirichlet(np.ones(n_states) * 0.3, size=(n_states, n_actions))
    return P


@stub("state_distributions", points=2, hint=HINT)
def test_matches_reference(student, reference, rng):
    """A random MDP and a random time-dependent policy"""
    P = _mdp(rng)
    policy = rng.dirichlet(np.ones(3), size=(6, 8))
    p0 = rng.dirichlet(np.ones(8))
    check_array(student.state_distributions(P, policy, p0), reference.state_distributions(P, policy, p0),
                rtol=1e-9, atol=1e-12, name="the state distributions")


@stub("state_distributions", points=1, hint=HINT)
def test_step_by_step_by_hand(student, rng):
    """Each step against a direct sum over (s, a), with a policy that changes every step"""
    P = _mdp(rng, 5, 2)
    policy = rng.dirichlet(np.ones(2) * 0.5, size=(4, 5))
    p0 = np.eye(5)[rng.integers(5)]
    want = [p0]
    for t in range(3):
        want.append(np.einsum("s,sa,sab->b", want[-1], policy[t], P))
    check_array(student.state_distributions(P, policy, p0), np.stack(want), rtol=1e-9, atol=1e-12,
                name="the state distributions")


@stub("state_distributions", points=1, hint="A horizon of T gives T distributions, s_0 .. s_{T-1}: d[0] is p0.")
def test_one_step_and_a_cycle(student, rng):
    """T = 1 gives p0 alone; a policy that always moves on round a cycle moves the mass one state per step"""
    P = _mdp(rng, 4, 2)
    p0 = rng.dirichlet(np.ones(4))
    check_array(student.state_distributions(P, np.full((1, 4, 2), 0.5), p0), p0[None], rtol=1e-12, atol=1e-15,
                name="the distributions for T = 1")
    cycle = np.zeros((4, 2, 4))                         # action 0 moves on round the cycle, action 1 stays put
    cycle[np.arange(4), 0, (np.arange(4) + 1) % 4] = 1.0
    cycle[np.arange(4), 1, np.arange(4)] = 1.0
    always_move = np.zeros((5, 4, 2))
    always_move[..., 0] = 1.0                           # a policy that never stays: the policy decides, not P alone
    got = student.state_distributions(cycle, always_move, p0)
    check_array(got, np.stack([np.roll(p0, t) for t in range(5)]), rtol=1e-12, atol=1e-15,
                name="the distributions on a deterministic cycle, under a policy that always moves on")
