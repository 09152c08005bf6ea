"""hw4's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). What these return is raw data that the
tests judge on the grader's side; the given classes come from the release by their full path.
"""
import numpy as np
import torch

from rlcourse.nets import GaussianPolicy
from rlcourse.ppo import make_envs


def dpo_policy(seed: int, log_std_init: float, shift=0.0, dstd=0.0) -> GaussianPolicy:
    """GaussianPolicy(11, 3, hidden=(8,)) seeded ``seed``, its mean's bias moved by ``shift`` and its log-std by ``dstd``."""
    torch.manual_seed(seed)
    policy = GaussianPolicy(11, 3, hidden=(8,), log_std_init=log_std_init)
    with torch.no_grad():
        policy.mean.bias.add_(torch.as_tensor(shift, dtype=torch.float32))
        policy.log_std.add_(torch.as_tensor(dstd, dtype=torch.float32))
    return policy


def hand_reward(obs, act):
    """The learned reward the wrapper's tests give it: a fixed function of the observation and the action."""
    return (obs[:, 1] - 2.0 * act[:, 2]).astype(np.float32)


def reward_wrapper(n_envs: int, mean: float, std: float, offset: float):
    """The submission's LearnedRewardWrapper around ``n_envs`` fresh Hopper environments, with :func:`hand_reward`."""
    return notebook["LearnedRewardWrapper"](make_envs(n_envs), hand_reward, mean, std, offset)  # noqa: F821


def wrapper_steps(wrapper, actions):
    """Step ``wrapper`` through ``actions``: per step (obs, reward, info['true_reward'], done, the info's keys)."""
    out = []
    for act in actions:
        obs, reward, terminated, truncated, info = wrapper.step(act)
        out.append((obs, np.asarray(reward, dtype=float), np.asarray(info["true_reward"], dtype=float),
                    terminated | truncated, sorted(info)))
    return out
