"""The one factory for batches of gymnasium environments.

Rollouts (:mod:`rlcourse.rollouts`) run each episode in its own sub-environment and never rely on an
auto-reset; PPO (:mod:`rlcourse.ppo`) needs environments that reset themselves in the same step an
episode ends. Both get their ``SyncVectorEnv`` here.
"""
from __future__ import annotations

from typing import Callable, Optional

import gymnasium as gym

import rlcourse.mujoco_messages  # noqa: F401 - installs the handler that drops a warning students cannot act on

HOPPER = "Hopper-v5"
"""The MuJoCo task of hw4 (PPO, RLHF and DPO)."""


def make_envs(n_envs: int, env_id: str = HOPPER, wrap: Optional[Callable] = None, same_step_reset: bool = True,
              **env_kwargs) -> gym.vector.VectorEnv:
    """``n_envs`` copies of ``env_id`` (made with ``env_kwargs``) in one ``SyncVectorEnv``, optionally
    wrapped by ``wrap(envs)``.

    With ``same_step_reset`` a sub-environment resets itself in the step its episode ends, and the final
    observation is in ``info["final_obs"]``; without it, gymnasium's default applies (the reset happens
    on the next step), which callers that stop at the end of each episode never see.
    """
    mode = gym.vector.AutoresetMode.SAME_STEP if same_step_reset else gym.vector.AutoresetMode.NEXT_STEP
    envs = gym.vector.SyncVectorEnv([lambda: gym.make(env_id, **env_kwargs) for _ in range(n_envs)],
                                    autoreset_mode=mode)
    return wrap(envs) if wrap is not None else envs
