"""Tests of rlcourse.gridworld: dynamics, sampling, planning and the shipped worlds."""
import numpy as np
import pytest

from rlcourse.gridworld import (boltzmann_policy, object_grid, optimal_q_values, random_mdp, sample_trajectories,
                                terrain_grid, transition_tensor)


def policy_return(P, policy, reward, p0):
    """Exact expected return by backward policy evaluation (kept out of rlcourse: with indicator rewards it
    would answer hw2's state_visitation_frequency)."""
    v = np.zeros(P.shape[0])
    for t in reversed(range(policy.shape[0])):
        v = reward + (policy[t] * (P @ v)).sum(axis=1)
    return float(p0 @ v)


def test_transition_tensor_rows_are_distributions_with_slip():
    P = transition_tensor(4, slip=0.2)
    assert P.shape == (16, 5, 16)
    np.testing.assert_allclose(P.sum(axis=-1), 1.0)
    # from the top-left corner "up" bumps into the wall: stay with 1 - slip + slip * (stay, up, left)/5
    assert P[0, 1, 0] == pytest.approx(0.8 + 0.2 * 3 / 5)
    assert P[5, 4, 6] == pytest.approx(0.8 + 0.2 / 5)  # "right" from (1, 1) reaches (1, 2)


def test_sampled_visits_match_exact_distribution():
    m = random_mdp(6, 2, 2, horizon=3, seed=0)
    policy = np.full((3, 6, 2), 0.5)
    demos = sample_trajectories(m.P, policy, m.p0, 40000, np.random.default_rng(0))
    assert demos.states.shape == demos.actions.shape == (40000, 3)
    np.testing.assert_allclose(np.bincount(demos.states[:, 0], minlength=6) / 40000, m.p0, atol=0.01)
    d1 = m.p0 @ (0.5 * m.P[:, 0] + 0.5 * m.P[:, 1])
    np.testing.assert_allclose(np.bincount(demos.states[:, 1], minlength=6) / 40000, d1, atol=0.01)


def test_optimal_q_and_policy_return_on_a_chain():
    # two states; action 1 moves to state 1 (reward 1), action 0 stays; horizon 3
    P = np.zeros((2, 2, 2))
    P[:, 0, :] = np.eye(2)
    P[:, 1, 1] = 1.0
    reward = np.array([0.0, 1.0])
    q = optimal_q_values(P, reward, 3)
    assert q[0, 0, 1] == pytest.approx(2.0) and q[0, 0, 0] == pytest.approx(1.0)
    greedy = boltzmann_policy(q, beta=1e6)
    assert policy_return(P, greedy, reward, np.array([1.0, 0.0])) == pytest.approx(2.0)
    uniform = np.full((3, 2, 2), 0.5)
    assert policy_return(P, uniform, reward, np.array([1.0, 0.0])) == pytest.approx(0.5 + 0.75)


def test_expert_beats_random_and_worlds_are_well_formed():
    m = terrain_grid(size=10, horizon=20, seed=1)
    assert m.features.shape == (100, 5) and np.allclose(m.features[:, :4].sum(axis=1), 1.0)
    np.testing.assert_allclose(m.true_reward, m.features @ m.true_weights)
    assert m.p0.sum() == pytest.approx(1.0)
    uniform = np.full((m.horizon, m.n_states, m.n_actions), 1.0 / m.n_actions)
    assert policy_return(m.P, m.expert_policy(), m.true_reward, m.p0) > policy_return(m.P, uniform, m.true_reward, m.p0) + 5.0
    w = object_grid(size=8, horizon=10, seed=0)
    assert set(np.unique(w.true_reward)) <= {-1.0, 0.0, 1.0} and w.true_weights is None
    assert (w.true_reward == 1.0).any() and (w.true_reward == -1.0).any()
