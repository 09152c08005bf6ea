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


class FormulaOnlyPolicy(GaussianPolicy):
    """A GaussianPolicy without its own log-density: the notebook asks ``bc_loss`` to write the formula from
    ``policy(obs)`` and ``policy.log_std``, and ``-policy.log_prob(obs, actions).mean()`` would be the whole stub."""

    def distribution(self, obs):
        raise RuntimeError("bc_loss should compute the Gaussian negative log-likelihood itself, from policy(obs) "
                           "and policy.log_std, not with policy.log_prob or policy.distribution")

    def log_prob(self, obs, actions):
        return self.distribution(obs)


def bc_policy(seed: int, obs_dim: int, act_dim: int, log_std, hidden: tuple[int, ...] = (16, 16)) -> GaussianPolicy:
    """A seeded policy for bc_loss's tests, with the given log_std, whose log_prob and distribution raise."""
    torch.manual_seed(seed)
    policy = FormulaOnlyPolicy(obs_dim, act_dim, hidden=tuple(hidden))
    with torch.no_grad():
        policy.log_std.copy_(torch.as_tensor(log_std, dtype=torch.float32))
    return policy
