"""Brute-force helpers the lecture tests share: random MDPs and policies, trajectory enumeration, finite
differences and discounted soft value iteration, each independent of the formulas the tests check."""
from __future__ import annotations

import itertools

import numpy as np


def random_mdp(rng: np.random.Generator, n_states: int, n_actions: int, n_features: int):
    """Random dynamics P[s,a,s'], start distribution p0[s] and features f[s,a,k]."""
    P = rng.dirichlet(np.ones(n_states), size=(n_states, n_actions))
    p0 = rng.dirichlet(np.ones(n_states))
    f = rng.normal(size=(n_states, n_actions, n_features))
    return P, p0, f


def random_policy(rng: np.random.Generator, *shape: int) -> np.ndarray:
    """Random policy with the action axis last."""
    return rng.dirichlet(np.ones(shape[-1]), size=shape[:-1])


def enumerate_trajectories(P, p0, pi):
    """All trajectories ((s_0,a_0),...,(s_{T-1},a_{T-1})) with their probabilities.

    Independent of the occupancy recursion: multiplies out the trajectory
    distribution p0(s_0) prod_t pi_t(a_t|s_t) P(s_{t+1}|s_t,a_t) term by term.
    """
    horizon, n_states, n_actions = pi.shape
    steps = list(itertools.product(range(n_states), range(n_actions)))
    for traj in itertools.product(steps, repeat=horizon):
        prob = p0[traj[0][0]]
        for t, (s, a) in enumerate(traj):
            prob *= pi[t, s, a]
            if t + 1 < horizon:
                prob *= P[s, a, traj[t + 1][0]]
        if prob > 0:
            yield traj, prob


def central_difference(fun, x: np.ndarray, h: float = 1e-5) -> np.ndarray:
    """Central finite-difference gradient of a scalar function."""
    grad = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        step = np.zeros_like(x)
        step[idx] = h
        grad[idx] = (fun(x + step) - fun(x - step)) / (2 * h)
    return grad


def discounted_soft_vi(P: np.ndarray, reward_sa: np.ndarray, gamma: float, n_iter: int = 3000
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Infinite-horizon discounted soft value iteration, written out: (V, log pi)."""
    v = np.zeros(P.shape[0])
    for _ in range(n_iter):
        q = reward_sa + gamma * P @ v
        v = np.logaddexp.reduce(q, axis=1)
    return v, q - v[:, None]
