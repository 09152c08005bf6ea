"""Vectorised rollouts and evaluation on gymnasium environments.

Every episode of a batch runs in its own sub-environment of a
``SyncVectorEnv``, so one batched policy call acts for all of them and no
sub-environment is ever auto-reset: the arrays returned hold exactly the
``n_episodes`` episodes asked for, padded after each episode's end.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rlcourse.envs import make_envs
from rlcourse.progress import progress as progress_bar

PolicyFn = Callable[[np.ndarray], np.ndarray]
"""Maps a batch of observations ``(n, obs_dim)`` to a batch of actions ``(n, act_dim)``."""


@dataclass
class Episodes:
    """A batch of episodes, padded to the longest one.

    Shapes: ``obs`` ``(n, T, obs_dim)``, ``actions`` ``(n, T, act_dim)``,
    ``rewards`` ``(n, T)``, ``mask`` ``(n, T)`` (True on real steps),
    ``lengths`` ``(n,)``, ``terminated`` ``(n,)`` (ended by failure rather than by the time limit).
    """

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    mask: np.ndarray
    lengths: np.ndarray
    terminated: np.ndarray

    @property
    def returns(self) -> np.ndarray:
        """Undiscounted return of each episode, ``(n,)``."""
        return (self.rewards * self.mask).sum(axis=1)

    def flat(self) -> tuple[np.ndarray, np.ndarray]:
        """All real (observation, action) pairs, ``(sum(lengths), obs_dim)`` and ``(sum(lengths), act_dim)``."""
        return self.obs[self.mask], self.actions[self.mask]


def rollout(
    policy: PolicyFn,
    env_id: str,
    n_episodes: int,
    seed: int,
    max_steps: int | None = None,
    progress: bool | None = None,
    **env_kwargs,
) -> Episodes:
    """Run ``n_episodes`` episodes of ``policy`` in parallel, seeded ``seed, seed+1, ...``.

    The same seed and a deterministic policy give the same episodes.
    ``progress=None`` reports progress only for long runs (over 10,000 env steps): a bar at a terminal
    or in a notebook, a plain line every few seconds in a log (:func:`rlcourse.progress.progress`).
    """
    envs = make_envs(n_episodes, env_id, same_step_reset=False, **env_kwargs)  # no auto-reset is relied on
    horizon = max_steps or envs.envs[0].spec.max_episode_steps or 1000
    obs, _ = envs.reset(seed=seed)
    obs_buf = np.zeros((n_episodes, horizon) + obs.shape[1:], dtype=np.float32)
    act_buf = np.zeros((n_episodes, horizon) + envs.single_action_space.shape, dtype=np.float32)
    rew_buf = np.zeros((n_episodes, horizon), dtype=np.float32)
    mask = np.zeros((n_episodes, horizon), dtype=bool)
    alive = np.ones(n_episodes, dtype=bool)
    terminated_any = np.zeros(n_episodes, dtype=bool)
    show = progress if progress is not None else n_episodes * horizon > 10_000
    for t in progress_bar(range(horizon), desc=f"rollout {env_id}", disable=not show):
        actions = np.asarray(policy(obs), dtype=np.float32)
        obs_buf[:, t], act_buf[:, t], mask[:, t] = obs, actions, alive
        obs, reward, terminated, truncated, _ = envs.step(actions)
        rew_buf[:, t] = np.where(alive, reward, 0.0)
        terminated_any |= alive & terminated
        alive &= ~(terminated | truncated)
        if not alive.any():
            break
    envs.close()
    lengths = mask.sum(axis=1)
    T = int(lengths.max())
    return Episodes(obs_buf[:, :T], act_buf[:, :T], rew_buf[:, :T], mask[:, :T], lengths, terminated_any)


def evaluate(policy: PolicyFn, env_id: str, n_episodes: int = 20, seed: int = 0, **kwargs) -> tuple[float, float]:
    """Mean and standard deviation of the undiscounted return over ``n_episodes`` seeded episodes."""
    returns = rollout(policy, env_id, n_episodes, seed, **kwargs).returns
    return float(returns.mean()), float(returns.std())
