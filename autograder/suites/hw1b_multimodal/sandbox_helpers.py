"""hw1b's suite helpers: run in the sandbox, beside the submission, after all its cells.

Trusted code the tests call as ``student.helpers.<name>(...)`` (and ``reference.helpers``): planners
and velocity fields whose answers the tests know in closed form. Student code can read this module, so
it holds nothing a student may not see; every value a test judges is recomputed on the grader's side.
``notebook`` is the submission's namespace (set by the worker).
"""
import numpy as np
import torch
from torch import nn


def run_chunked(env, planner, execute: int):
    """The submission's chunked_rollout with a lent planner (``planner.plan`` runs in the grader, which records its
    calls) on a lent environment: its Episodes as a dict."""
    episodes = notebook["chunked_rollout"](planner.plan, env, execute)  # noqa: F821 - set by the worker
    fields = ("obs", "actions", "rewards", "mask", "lengths", "terminated")
    return {name: getattr(episodes, name, None) for name in fields}


class LinearVelocity(nn.Module):
    """v(a, t, obs) = a @ A + t * b + obs @ C, with a flattened per sample; parameters A, b, C trainable.

    A (D, D), b (D,), C (obs_dim, D), where D is the number of entries of one sample's chunk.
    ``inputs`` keeps a copy of the (a, t) of every call (raw data: the tests count and check them).
    """

    def __init__(self, A, b, C) -> None:
        super().__init__()
        self.A = nn.Parameter(torch.as_tensor(np.asarray(A), dtype=torch.float64))
        self.b = nn.Parameter(torch.as_tensor(np.asarray(b), dtype=torch.float64))
        self.C = nn.Parameter(torch.as_tensor(np.asarray(C), dtype=torch.float64))
        self.inputs = []

    def forward(self, a, t, obs):
        self.inputs.append((torch.as_tensor(a).detach().clone(), torch.as_tensor(t).detach().clone()))
        flat = a.reshape(len(a), -1).to(torch.float64)
        out = flat @ self.A + torch.as_tensor(t, dtype=torch.float64).reshape(-1, 1) * self.b \
            + torch.as_tensor(obs, dtype=torch.float64) @ self.C
        return out.to(a.dtype).reshape(a.shape)


def _field_grads(value, field):
    """d value / d (A, b, C), or None where ``value`` carries no autograd graph (raw data, judged by the test)."""
    if not (isinstance(value, torch.Tensor) and value.requires_grad):
        return None
    return [g.detach() for g in torch.autograd.grad(value.sum(), [field.A, field.b, field.C], allow_unused=True)]


def flow_loss_and_grads(A, b, C, obs, chunks, noise, t):
    """The submission's flow_matching_loss at a LinearVelocity: (loss, its gradients (A, b, C) or None, the (a, t)
    of every call of the field)."""
    field = LinearVelocity(A, b, C)
    loss = notebook["flow_matching_loss"](field, obs, chunks, noise, t)  # noqa: F821
    grads = _field_grads(loss, field)
    return (loss.detach() if isinstance(loss, torch.Tensor) else loss), grads, field.inputs


def euler_with_linear_field(A, b, C, obs, noise, n_steps):
    """The submission's euler_sample with a LinearVelocity: (result, the times it was called with, the noise as the
    call left it, the gradients of the result's sum with respect to (A, b, C) or None)."""
    field = LinearVelocity(A, b, C)
    out = notebook["euler_sample"](field, obs, noise, n_steps)  # noqa: F821
    grads = _field_grads(out, field)
    out = out.detach() if isinstance(out, torch.Tensor) else out
    return out, [t.to(torch.float64) for _, t in field.inputs], noise, grads


class MLPVelocity(nn.Module):
    """A small seeded tanh network v(a, t, obs) with a nonlinear dependence on all three inputs."""

    def __init__(self, dim: int, obs_dim: int, seed: int) -> None:
        super().__init__()
        generator = torch.Generator().manual_seed(seed)
        self.w1 = nn.Parameter(torch.randn(dim + 1 + obs_dim, 16, generator=generator, dtype=torch.float64) * 0.7)
        self.w2 = nn.Parameter(torch.randn(16, dim, generator=generator, dtype=torch.float64) * 0.7)

    def forward(self, a, t, obs):
        x = torch.cat([a.reshape(len(a), -1).to(torch.float64), torch.as_tensor(t, dtype=torch.float64).reshape(-1, 1),
                       torch.as_tensor(obs, dtype=torch.float64)], dim=-1)
        return (torch.tanh(x @ self.w1) @ self.w2).to(a.dtype).reshape(a.shape)


def euler_with_mlp(dim: int, obs_dim: int, seed: int, obs, noise, n_steps):
    """euler_sample (the namespace's) with an MLPVelocity built from ``seed``."""
    return notebook["euler_sample"](MLPVelocity(dim, obs_dim, seed), obs, noise, n_steps)  # noqa: F821
