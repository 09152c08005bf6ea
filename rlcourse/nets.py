"""Small torch networks shared by every assignment.

The one policy class, :class:`GaussianPolicy`, is a multilayer perceptron that
outputs the mean of a diagonal Gaussian over actions, with a state-independent
log standard deviation. With ``squash=True`` the acting mean is passed through
``tanh`` (the form Soft Actor-Critic experts use); log-likelihoods are always of
the unsquashed Gaussian, which is what behaviour cloning and DPO on continuous
actions need.

Policies are saved in the course's one checkpoint format (:mod:`rlcourse.checkpoint`):
their constructor arguments, ``state_dict`` and metadata, so loading never unpickles
arbitrary objects.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from torch import nn
from torch.distributions import Independent, Normal

from rlcourse.checkpoint import load_model, save_model

ACTIVATIONS = {"relu": nn.ReLU, "tanh": nn.Tanh}


def mlp(sizes: Sequence[int], activation: str = "relu") -> nn.Sequential:
    """Linear layers of the given sizes with ``activation`` between them (not after the last)."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(n_in, n_out))
        if i < len(sizes) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


class GaussianPolicy(nn.Module):
    """pi(a|s) = N(mean(s), diag(exp(log_std))^2), with mean(s) an MLP.

    Shapes: ``obs`` is ``(..., obs_dim)``; means and actions are ``(..., act_dim)``.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: Sequence[int] = (64, 64),
        activation: str = "tanh",
        squash: bool = False,
        log_std_init: float = -0.5,
    ) -> None:
        super().__init__()
        self.config = dict(
            obs_dim=int(obs_dim), act_dim=int(act_dim), hidden=[int(h) for h in hidden],
            activation=activation, squash=bool(squash), log_std_init=float(log_std_init),
        )
        self.body = mlp([obs_dim, *hidden], activation)
        if hidden:  # the body ends on a linear layer; add its activation
            self.body.append(ACTIVATIONS[activation]())
        self.mean = nn.Linear(hidden[-1] if hidden else obs_dim, act_dim)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(log_std_init)))
        self.squash = squash

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean (before any squashing), ``(..., act_dim)``."""
        return self.mean(self.body(obs))

    def distribution(self, obs: torch.Tensor) -> Independent:
        """The action distribution at ``obs``: a diagonal Gaussian with event shape ``(act_dim,)``."""
        return Independent(Normal(self(obs), self.log_std.exp()), 1)

    def log_prob(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log pi(a|s) summed over action dimensions, ``(...,)``."""
        return self.distribution(obs).log_prob(actions)

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool = True, generator: torch.Generator | None = None) -> np.ndarray:
        """Actions for a batch (or one) of numpy observations, as float32 numpy."""
        obs_t = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
        mean = self(obs_t)
        if deterministic:
            action = mean
        else:
            noise = torch.randn(mean.shape, generator=generator)
            action = mean + self.log_std.exp() * noise
        if self.squash:
            action = torch.tanh(action)
        return action.numpy().astype(np.float32)


def save_policy(policy: GaussianPolicy, path: str | Path, **metadata: float | int | str) -> None:
    """Save ``policy`` as a checkpoint (config, ``state_dict``, metadata), atomically."""
    save_model(policy, path, policy.config, **metadata)


def load_policy(path: str | Path) -> GaussianPolicy:
    """A policy written by :func:`save_policy`, in eval mode, with its ``.metadata``."""
    return load_model(path, GaussianPolicy)
