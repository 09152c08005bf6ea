"""hw1b's suite helpers: run in the sandbox, beside the submission, after all its cells.

Trusted code the tests call as ``student.helpers.<name>(...)`` (and ``reference.helpers``): planners
and velocity fields whose answers the tests know in closed form. Student code can read this module, so
it holds nothing a student may not see; every value a test judges is recomputed on the grader's side.
``notebook`` is the submission's namespace (set by the worker).
"""
import numpy as np
import torch
from torch import nn


class LinearPlanner:
    """chunk[i, j, :] = tanh(obs[i] @ weights[j] + bias[j]): a deterministic planner that logs its calls.

    weights (H, obs_dim, act_dim), bias (H, act_dim). ``rows`` lists the batch size of every call.
    """

    def __init__(self, weights, bias) -> None:
        self.weights, self.bias = np.asarray(weights, dtype=np.float64), np.asarray(bias, dtype=np.float64)
        self.rows = []

    def __call__(self, obs):
        obs = np.asarray(obs, dtype=np.float64)
        self.rows.append(len(obs))
        return np.tanh(np.einsum("nd,hda->nha", obs, self.weights) + self.bias).astype(np.float32)


def run_chunked(env, weights, bias, execute: int):
    """The submission's chunked_rollout with a LinearPlanner: (its Episodes as a dict, the planner's call sizes)."""
    planner = LinearPlanner(weights, bias)
    episodes = notebook["chunked_rollout"](planner, env, execute)  # noqa: F821 - set by the worker
    fields = ("obs", "actions", "rewards", "mask", "lengths", "terminated")
    return {name: getattr(episodes, name, None) for name in fields}, list(planner.rows)


class LinearVelocity(nn.Module):
    """v(a, t, obs) = a @ A + t * b + obs @ C, with a flattened per sample; parameters A, b, C trainable.

    A (D, D), b (D,), C (obs_dim, D), where D is the number of entries of one sample's chunk.
    ``calls`` counts the forward calls; ``times`` keeps a copy of every t it was given.
    """

    def __init__(self, A, b, C) -> None:
        super().__init__()
        self.A = nn.Parameter(torch.as_tensor(np.asarray(A), dtype=torch.float64))
        self.b = nn.Parameter(torch.as_tensor(np.asarray(b), dtype=torch.float64))
        self.C = nn.Parameter(torch.as_tensor(np.asarray(C), dtype=torch.float64))
        self.calls, self.times = 0, []

    def forward(self, a, t, obs):
        self.calls += 1
        self.times.append(torch.as_tensor(t).detach().clone())
        flat = a.reshape(len(a), -1).to(torch.float64)
        out = flat @ self.A + torch.as_tensor(t, dtype=torch.float64).reshape(-1, 1) * self.b \
            + torch.as_tensor(obs, dtype=torch.float64) @ self.C
        return out.to(a.dtype).reshape(a.shape)


def flow_loss_and_grads(A, b, C, obs, chunks, noise, t):
    """The submission's flow_matching_loss at a LinearVelocity, its gradients (A, b, C) and the number of calls."""
    field = LinearVelocity(A, b, C)
    loss = notebook["flow_matching_loss"](field, obs, chunks, noise, t)  # noqa: F821
    if not isinstance(loss, torch.Tensor) or loss.dim() != 0 or not loss.requires_grad:
        return loss, None, field.calls
    grads = torch.autograd.grad(loss, [field.A, field.b, field.C])
    return loss.detach(), [g.detach() for g in grads], field.calls


def euler_with_linear_field(A, b, C, obs, noise, n_steps):
    """The submission's euler_sample with a LinearVelocity: (result, the times it was called with, noise afterwards,
    whether the result tracks gradients)."""
    field = LinearVelocity(A, b, C)
    kept = noise.clone()
    out = notebook["euler_sample"](field, obs, noise, n_steps)  # noqa: F821
    tracks = bool(getattr(out, "requires_grad", False))
    out = out.detach() if isinstance(out, torch.Tensor) else out
    return out, [t.to(torch.float64) for t in field.times], bool(torch.equal(kept, noise)), tracks


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


def try_chunked(env, weights, bias, execute: int) -> str:
    """The name of the exception the submission's chunked_rollout raises with a LinearPlanner, or "no error"."""
    try:
        notebook["chunked_rollout"](LinearPlanner(weights, bias), env, execute)  # noqa: F821
    except Exception as error:  # noqa: BLE001 - the test reads the type's name
        return type(error).__name__
    return "no error"


def try_call(name: str, *args) -> str:
    """The name of the exception the submission's ``name(*args)`` raises, or "no error"."""
    try:
        notebook[name](*args)  # noqa: F821
    except Exception as error:  # noqa: BLE001 - the test reads the type's name
        return type(error).__name__
    return "no error"
