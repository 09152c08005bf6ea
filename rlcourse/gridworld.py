"""Tabular gridworlds with terrain features and known, slippery dynamics (hw2).

A :class:`GridMDP` holds everything a maximum-entropy IRL learner is allowed to
know (the transition tensor ``P[s, a, s']``, the state features ``phi[s, f]``,
the start distribution ``p0[s]`` and the horizon ``T``) plus the *hidden* true
reward that generated the demonstrations, for evaluation only. States are grid
cells numbered ``row * size + col``; actions are ``stay, up, down, left, right``.

The simulated expert is *Boltzmann-rational*: at time ``t`` it picks action
``a`` with probability proportional to ``exp(beta * Q*_t(s, a))``, where
``Q*`` is the optimal finite-horizon action value of the true reward (hard
value iteration, :func:`optimal_q_values`). That is a common model of a noisy
human and, deliberately, not the maximum-entropy model the learner assumes.

Conventions: a trajectory visits ``s_0 .. s_{T-1}`` and collects ``r(s_t)`` at
each of them; it takes an action at every step (the last one changes nothing),
so a batch of ``N`` trajectories is ``states`` and ``actions``, both ``(N, T)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import matplotlib.pyplot as plt
import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.sparse import csr_array

ACTIONS = ("stay", "up", "down", "left", "right")
MOVES = np.array([[0, 0], [-1, 0], [1, 0], [0, -1], [0, 1]])  # (A, 2) row/col offsets
TERRAINS = ("road", "grass", "mud", "rocks")


class Demos(NamedTuple):
    """A batch of trajectories: ``states`` and ``actions``, both ``(N, T)`` integer arrays."""

    states: np.ndarray
    actions: np.ndarray


@dataclass(frozen=True)
class GridMDP:
    """A finite-horizon gridworld MDP with known dynamics and a hidden reward."""

    size: int                 # side of the square grid; S = size ** 2
    P: np.ndarray             # (S, A, S) transition probabilities P[s, a, s']
    features: np.ndarray      # (S, F) state features phi(s)
    feature_names: tuple[str, ...]
    p0: np.ndarray            # (S,) start distribution
    horizon: int              # T: number of visited states per trajectory
    true_reward: np.ndarray   # (S,) hidden reward, for evaluation only
    true_weights: np.ndarray | None  # (F,) when true_reward = features @ true_weights
    beta: float = 2.0         # the expert's rationality (inverse temperature)

    @property
    def n_states(self) -> int:
        return self.P.shape[0]

    @property
    def n_actions(self) -> int:
        return self.P.shape[1]

    def expert_policy(self) -> np.ndarray:
        """The expert's time-dependent policy ``(T, S, A)``: Boltzmann in the optimal Q-values."""
        return boltzmann_policy(optimal_q_values(self.P, self.true_reward, self.horizon), self.beta)

    def sample_expert(self, n: int, rng: np.random.Generator) -> Demos:
        """``n`` expert demonstrations (states and actions, ``(n, T)`` each)."""
        return sample_trajectories(self.P, self.expert_policy(), self.p0, n, rng)


def transition_tensor(size: int, slip: float) -> np.ndarray:
    """``P[s, a, s']`` of a ``size x size`` grid: the intended move with probability ``1 - slip``,
    otherwise a uniformly random action (possibly the intended one); moves off the grid stay put."""
    rows, cols = np.divmod(np.arange(size * size), size)
    target = np.stack([rows[:, None] + MOVES[None, :, 0], cols[:, None] + MOVES[None, :, 1]])  # (2, S, A)
    target = np.clip(target, 0, size - 1)
    next_state = target[0] * size + target[1]  # (S, A)
    n_states, n_actions = next_state.shape
    move = np.zeros((n_states, n_actions, n_states))
    move[np.arange(n_states)[:, None], np.arange(n_actions)[None, :], next_state] = 1.0
    return (1.0 - slip) * move + slip * move.mean(axis=1, keepdims=True)


def sample_trajectories(P: np.ndarray, policy: np.ndarray, p0: np.ndarray, n: int,
                        rng: np.random.Generator) -> Demos:
    """Sample ``n`` trajectories of length ``T = policy.shape[0]`` from a ``(T, S, A)`` policy."""
    horizon = policy.shape[0]
    states = np.empty((n, horizon), dtype=np.int64)
    actions = np.empty((n, horizon), dtype=np.int64)
    s = _sample_rows(np.broadcast_to(p0, (n, p0.shape[0])), rng)
    for t in range(horizon):
        a = _sample_rows(policy[t, s], rng)
        states[:, t], actions[:, t] = s, a
        s = _sample_rows(P[s, a], rng)
    return Demos(states, actions)


def _sample_rows(probs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One index per row of an ``(n, k)`` array of probabilities (inverse-CDF sampling)."""
    cdf = np.cumsum(probs, axis=1)
    u = rng.random((probs.shape[0], 1)) * cdf[:, -1:]
    return np.minimum((cdf < u).sum(axis=1), probs.shape[1] - 1)


def optimal_q_values(P: np.ndarray, reward: np.ndarray, horizon: int) -> np.ndarray:
    """Optimal finite-horizon action values ``Q*[t, s, a]`` (hard value iteration, ``(T, S, A)``)."""
    q = np.empty((horizon, *P.shape[:2]))
    P_flat = _sparse_rows(P)
    v_next = np.zeros(P.shape[0])
    for t in reversed(range(horizon)):
        q[t] = reward[:, None] + (P_flat @ v_next).reshape(P.shape[:2])
        v_next = q[t].max(axis=1)
    return q


def _sparse_rows(P: np.ndarray) -> csr_array:
    """``P[s, a, s']`` as a sparse ``(S * A, S)`` matrix (grid dynamics have a handful of successors)."""
    return csr_array(np.asarray(P, dtype=float).reshape(-1, P.shape[-1]))


def boltzmann_policy(q: np.ndarray, beta: float) -> np.ndarray:
    """``pi[t, s, a]`` proportional to ``exp(beta * q[t, s, a])``."""
    z = beta * (q - q.max(axis=-1, keepdims=True))
    p = np.exp(z)
    return p / p.sum(axis=-1, keepdims=True)


def terrain_grid(size: int = 20, horizon: int = 50, slip: float = 0.1, seed: int = 0,
                 beta: float = 2.0) -> GridMDP:
    """A gridworld of roads, grass, mud and rocks with a goal region, and a linear hidden reward.

    Features (F = 5): one-hot terrain (road, grass, mud, rocks) and a goal indicator. The expert
    starts in the left three columns and is paid for every step spent in the goal region
    (right side), at a cost that depends on the terrain crossed on the way.
    """
    rng = np.random.default_rng(seed)
    field = gaussian_filter(rng.normal(size=(size, size)), sigma=size / 8, mode="reflect")
    terrain = np.digitize(field, np.quantile(field, [0.45, 0.75])) + 1  # grass, mud, rocks
    road_row, road_col = rng.integers(size // 4, 3 * size // 4, size=2)
    terrain[road_row, :] = 0
    terrain[:, road_col] = 0
    goal = np.zeros((size, size), dtype=bool)
    g_row = rng.integers(1, size - 3)
    goal[g_row:g_row + 2, size - 3:size - 1] = True
    terrain[goal] = 1  # the goal is a grassy clearing
    features = np.concatenate([np.eye(len(TERRAINS))[terrain.ravel()], goal.reshape(-1, 1)], axis=1)
    weights = np.array([0.0, -0.3, -1.0, -2.0, 2.0])
    p0 = np.zeros((size, size))
    p0[:, :3] = 1.0
    return GridMDP(size=size, P=transition_tensor(size, slip), features=features,
                   feature_names=TERRAINS + ("goal",), p0=p0.ravel() / p0.sum(), horizon=horizon,
                   true_reward=features @ weights, true_weights=weights, beta=beta)


def object_grid(size: int = 16, horizon: int = 32, slip: float = 0.1, n_objects: int = 12,
                seed: int = 0, beta: float = 2.0) -> GridMDP:
    """A gridworld whose true reward is *not* linear in its features (for deep MaxEnt IRL).

    Objects of four colours sit on random cells. The features of a cell are its distances to
    the nearest object of each colour, scaled to [0, 1] (F = 4). The reward is +1 near colour 0
    *and* colour 1 (within 3 and 2 cells), -1 near colour 0 only, 0 elsewhere; colours 2 and 3
    are distractors. The expert starts anywhere.
    """
    rng = np.random.default_rng(seed)
    cells = rng.choice(size * size, size=n_objects, replace=False)
    colours = np.arange(n_objects) % 4
    rows, cols = np.divmod(np.arange(size * size), size)
    o_rows, o_cols = np.divmod(cells, size)
    dist = np.hypot(rows[:, None] - o_rows[None, :], cols[:, None] - o_cols[None, :])  # (S, n_objects)
    nearest = np.stack([dist[:, colours == c].min(axis=1) for c in range(4)], axis=1)  # (S, 4)
    near0, near1 = nearest[:, 0] <= 3.0, nearest[:, 1] <= 2.0
    reward = np.where(near0 & near1, 1.0, np.where(near0, -1.0, 0.0))
    return GridMDP(size=size, P=transition_tensor(size, slip), features=nearest / (size * np.sqrt(2)),
                   feature_names=tuple(f"distance to colour {c}" for c in range(4)),
                   p0=np.full(size * size, 1.0 / size**2), horizon=horizon, true_reward=reward,
                   true_weights=None, beta=beta)


def random_mdp(n_states: int, n_actions: int, n_features: int, horizon: int, seed: int,
               branching: int = 3, beta: float = 2.0) -> GridMDP:
    """A random MDP (not a grid: ``size`` is 0) with sparse stochastic dynamics, Gaussian features
    and a random linear reward; for tests."""
    rng = np.random.default_rng(seed)
    P = np.zeros((n_states, n_actions, n_states))
    for s in range(n_states):
        for a in range(n_actions):
            nxt = rng.choice(n_states, size=branching, replace=False)
            P[s, a, nxt] = rng.dirichlet(np.ones(branching))
    features = rng.normal(size=(n_states, n_features))
    weights = rng.normal(size=n_features)
    return GridMDP(size=0, P=P, features=features, feature_names=tuple(f"f{i}" for i in range(n_features)),
                   p0=rng.dirichlet(np.ones(n_states)), horizon=horizon, true_reward=features @ weights,
                   true_weights=weights, beta=beta)


def plot_grid(values: np.ndarray, size: int, ax: plt.Axes | None = None, title: str | None = None,
              cmap: str = "viridis", colorbar: bool = True) -> plt.Axes:
    """Heat map of one value per state of a ``size x size`` grid (row 0 at the top)."""
    ax = ax or plt.subplots(figsize=(3.6, 3.2))[1]
    image = ax.imshow(np.asarray(values).reshape(size, size), cmap=cmap)
    if colorbar:
        ax.figure.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def plot_paths(states: np.ndarray, size: int, ax: plt.Axes, color: str = "white", alpha: float = 0.5) -> None:
    """Overlay trajectories ``(N, T)`` of state indices on a grid plot (with a little jitter)."""
    rows, cols = np.divmod(np.asarray(states), size)
    jitter = np.random.default_rng(0).uniform(-0.2, 0.2, size=(2, rows.shape[0], 1))
    for r, c in zip(rows + jitter[0], cols + jitter[1]):
        ax.plot(c, r, color=color, alpha=alpha, linewidth=0.8)
