"""hw1's suite helpers: run in the sandbox, beside the submission, after all its cells.

Trusted code the tests call as ``student.helpers.<name>(...)`` (and ``reference.helpers``): it
builds objects that cannot cross the channel, in ordinary Python instead of expressions in
strings. Student code can read this module, so it holds nothing a student may not see.
``notebook`` is the submission's namespace (set by the worker).
"""
import torch

from rlcourse.nets import GaussianPolicy


def make_policy(obs_dim: int, act_dim: int, hidden: tuple[int, ...] = (), seed: int = 0) -> GaussianPolicy:
    """A freshly initialised GaussianPolicy, its weights drawn under ``seed``."""
    torch.manual_seed(seed)
    return GaussianPolicy(obs_dim, act_dim, hidden=tuple(hidden))


def train_fresh_policy(obs, actions, hidden: tuple[int, ...] = (), policy_seed: int = 0, **train_kwargs):
    """(policy, history) of the submission's ``train_bc`` on a fresh seeded policy."""
    policy = make_policy(obs.shape[1], actions.shape[1], hidden, policy_seed)
    return policy, notebook["train_bc"](policy, obs, actions, **train_kwargs)  # noqa: F821 - set by the worker


def inputs_after_training(obs, actions, hidden: tuple[int, ...] = (), policy_seed: int = 0, **train_kwargs):
    """(history, obs, actions) after the submission's ``train_bc``: the arrays as it left them."""
    _, history = train_fresh_policy(obs, actions, hidden, policy_seed, **train_kwargs)
    return history, obs, actions
