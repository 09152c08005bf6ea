"""Pieces that hw1's behaviour cloning and DAgger share: demonstrations, the expert/learner mixture, the data buffer.

- :class:`Demonstrations` holds expert episodes stored flat (every step of every
  episode, one after the other) with the episode lengths as boundaries, the
  format of ``datasets/demos/*.npz`` written by ``datasets/scripts/make_demos.py``.
- :class:`MixturePolicy` acts for a batch of environments, choosing the expert
  with probability ``beta`` and the learner otherwise, independently at every
  step and in every environment (the policy DAgger rolls out).
- :class:`AggregatedDataset` grows by appending (observation, label) batches.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from rlcourse import data
from rlcourse.nets import GaussianPolicy

PolicyFn = Callable[[np.ndarray], np.ndarray]


@dataclass
class Demonstrations:
    """Expert episodes stored flat.

    Shapes: ``obs`` ``(N, obs_dim)``, ``actions`` ``(N, act_dim)``, ``rewards`` ``(N,)`` with
    ``N = lengths.sum()``; ``lengths`` ``(n_episodes,)``; ``terminated`` ``(n_episodes,)`` is True for
    an episode that ended by failure rather than by the time limit.
    """

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    lengths: np.ndarray
    terminated: np.ndarray

    @classmethod
    def load(cls, name: str) -> "Demonstrations":
        """Load ``datasets/<name>`` (checked against the MANIFEST), e.g. ``"demos/Hopper-v5.npz"``."""
        arrays = data.load_npz(name)
        return cls(**{key: arrays[key] for key in ("obs", "actions", "rewards", "lengths", "terminated")})

    @classmethod
    def from_episodes(cls, episodes) -> "Demonstrations":
        """Flatten a padded :class:`rlcourse.rollouts.Episodes` batch."""
        return cls(episodes.obs[episodes.mask], episodes.actions[episodes.mask], episodes.rewards[episodes.mask],
                   episodes.lengths.astype(np.int64), episodes.terminated.astype(bool))

    @property
    def n_episodes(self) -> int:
        return len(self.lengths)

    @property
    def returns(self) -> np.ndarray:
        """Undiscounted return of each episode, ``(n_episodes,)``."""
        return np.add.reduceat(self.rewards, np.r_[0, np.cumsum(self.lengths)[:-1]]) if len(self.lengths) else np.zeros(0)

    def first(self, k: int) -> "Demonstrations":
        """The first ``k`` episodes."""
        if not 0 <= k <= self.n_episodes:
            raise ValueError(f"asked for {k} episodes; there are {self.n_episodes}")
        n = int(self.lengths[:k].sum())
        return Demonstrations(self.obs[:n], self.actions[:n], self.rewards[:n], self.lengths[:k], self.terminated[:k])


class MixturePolicy:
    """Per step and per environment: the expert's action with probability ``beta``, else the learner's.

    ``expert`` and ``learner`` map observations ``(n, obs_dim)`` to actions ``(n, act_dim)``; only the
    policies that some environment needs at a step are asked. ``rng`` draws the coin flips, so a seeded
    generator gives reproducible rollouts. ``n_expert_steps`` and ``n_steps`` count what was chosen.
    """

    def __init__(self, expert: PolicyFn, learner: PolicyFn, beta: float, rng: np.random.Generator) -> None:
        if not 0.0 <= beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {beta}")
        self.expert, self.learner, self.beta, self.rng = expert, learner, float(beta), rng
        self.n_expert_steps = self.n_steps = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        use_expert = self.rng.random(len(obs)) < self.beta
        actions = None
        for chosen, policy in ((use_expert, self.expert), (~use_expert, self.learner)):
            if chosen.any():
                part = np.asarray(policy(obs[chosen]), dtype=np.float32)
                if actions is None:
                    actions = np.zeros((len(obs),) + part.shape[1:], dtype=np.float32)
                actions[chosen] = part
        self.n_expert_steps += int(use_expert.sum())
        self.n_steps += len(obs)
        return actions


class AggregatedDataset:
    """A growing set of (observation, action label) pairs, started from a first batch.

    ``add`` appends a batch; ``obs`` ``(len(self), obs_dim)`` and ``actions`` ``(len(self), act_dim)``
    (float32) hold everything added so far, oldest first.
    """

    def __init__(self, obs: np.ndarray, actions: np.ndarray) -> None:
        self.obs, self.actions = self._checked(obs, actions)

    def _checked(self, obs: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        obs, actions = np.array(obs, dtype=np.float32), np.array(actions, dtype=np.float32)
        if obs.ndim != 2 or actions.ndim != 2 or len(obs) != len(actions):
            raise ValueError("expected observations (n, obs_dim) and actions (n, act_dim) with the same n, "
                             f"got {obs.shape} and {actions.shape}")
        if hasattr(self, "obs") and (obs.shape[1:] != self.obs.shape[1:] or actions.shape[1:] != self.actions.shape[1:]):
            raise ValueError(f"a batch of shapes {obs.shape} and {actions.shape} does not match the dataset's "
                             f"{self.obs.shape[1:]} and {self.actions.shape[1:]}")
        return obs, actions

    def add(self, obs: np.ndarray, actions: np.ndarray) -> None:
        """Append ``n`` observations ``(n, obs_dim)`` with their labels ``(n, act_dim)`` (copied)."""
        obs, actions = self._checked(obs, actions)
        self.obs, self.actions = np.concatenate([self.obs, obs]), np.concatenate([self.actions, actions])

    def __len__(self) -> int:
        return len(self.obs)


class NormalisedPolicy(GaussianPolicy):
    """A :class:`~rlcourse.nets.GaussianPolicy` that standardises its input with fixed statistics.

    ``forward(obs)`` is the Gaussian policy's mean at ``(obs - obs_mean) / obs_std``; the statistics are
    buffers (saved in the ``state_dict``, never trained). Use it when observation scales differ a lot
    (MuJoCo velocities against joint angles), with the statistics of the first demonstrations.
    """

    def __init__(self, obs_mean: np.ndarray, obs_std: np.ndarray, act_dim: int, **kwargs) -> None:
        obs_mean = torch.as_tensor(np.asarray(obs_mean), dtype=torch.float32)
        super().__init__(len(obs_mean), act_dim, **kwargs)
        self.register_buffer("obs_mean", obs_mean.clone())
        self.register_buffer("obs_std", torch.as_tensor(np.asarray(obs_std), dtype=torch.float32).clamp_min(1e-3))

    @classmethod
    def for_data(cls, obs: np.ndarray, act_dim: int, **kwargs) -> "NormalisedPolicy":
        """A policy standardising with the mean and standard deviation of ``obs`` ``(n, obs_dim)``."""
        return cls(np.mean(obs, axis=0), np.std(obs, axis=0), act_dim, **kwargs)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return super().forward((obs - self.obs_mean) / self.obs_std)
