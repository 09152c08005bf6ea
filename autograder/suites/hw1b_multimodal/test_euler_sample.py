"""Hidden tests of hw1b's `euler_sample`, on velocity fields whose Euler iterates are known exactly."""
import numpy as np
import torch

from autograder.suite import check_array, check_tensor, stub

HINT = ("a <- a + (1/K) * velocity(a, t_j, obs) for j = 0..K-1 with t_j = j/K (a tensor of shape (N,)), starting from "
        "a copy of the noise; return the final a, without gradient tracking.")


def _field(rng, d, obs_dim, a_scale=1.0, t_scale=1.0, o_scale=1.0):
    return (rng.normal(size=(d, d)) * 0.4 * a_scale, rng.normal(size=d) * t_scale, rng.normal(size=(obs_dim, d)) * o_scale)


def _run(student, A, b, C, obs, noise, K):
    out = student.helpers.euler_with_linear_field(A, b, C, torch.as_tensor(obs), torch.as_tensor(noise), K)
    assert isinstance(out, tuple) and len(out) == 4, "euler_sample did not run"
    result, times, noise_after, grads = out
    assert type(result) is torch.Tensor, f"euler_sample should return a torch tensor, got {type(result).__name__}"
    assert result.shape == tuple(np.shape(noise)), f"the result should be shaped like the noise {np.shape(noise)}, got {tuple(result.shape)}"
    return result, times, noise_after, grads


def _euler(A, b, C, obs, noise, K):
    """The exact Euler iterates of v = a A + t b + obs C (float64)."""
    n = len(noise)
    a = noise.reshape(n, -1).copy()
    for j in range(K):
        a = a + (a @ A + (j / K) * b + obs @ C) / K
    return a.reshape(noise.shape)


@stub("euler_sample", points=2, hint=HINT)
def test_linear_field_exact_iterates(student, rng):
    """v = a A (no time or observation): K steps give a_0 (I + A/K)^K exactly"""
    d, K = 3, int(rng.integers(3, 9))
    A, _, _ = _field(rng, d, 2)
    noise = rng.normal(size=(5, d))
    result, _, _, _ = _run(student, A, np.zeros(d), np.zeros((2, d)), np.zeros((5, 2)), noise, K)
    want = noise @ np.linalg.matrix_power(np.eye(d) + A / K, K)
    check_array(result.numpy().astype(np.float64), want, rtol=1e-8, atol=1e-10, name=f"the result of {K} Euler steps")


@stub("euler_sample", points=2, hint="Step j uses t = j / K (0, 1/K, ..., (K-1)/K), the same for every sample.")
def test_time_and_observation_enter_the_field(student, rng):
    """v = a A + t b + obs C on chunks (N, H, act_dim): the iterates, and the times 0, 1/K, ..., (K-1)/K"""
    n, shape, obs_dim, K = 4, (2, 2), 3, int(rng.integers(3, 7))
    A, b, C = _field(rng, 4, obs_dim)
    obs, noise = rng.normal(size=(n, obs_dim)), rng.normal(size=(n,) + shape)
    result, times, _, _ = _run(student, A, b, C, obs, noise, K)
    check_array(result.numpy().astype(np.float64), _euler(A, b, C, obs, noise, K), rtol=1e-8, atol=1e-10,
                name="the result")
    assert len(times) == K, f"{K} Euler steps call the velocity {K} times, it was called {len(times)} times"
    for j, t in enumerate(times):
        assert tuple(t.shape) == (n,), f"t should be a tensor of shape (N,) = ({n},), got shape {tuple(t.shape)}"
        check_array(t.numpy(), np.full(n, j / K), rtol=0, atol=1e-12, name=f"the time of step {j}")


@stub("euler_sample", points=1, hint="With K = 1 the sample is a_0 + v(a_0, 0 | obs).")
def test_one_step_sampler(student, reference, rng):
    """K = 1 on a nonlinear field: noise plus the velocity at t = 0"""
    obs = torch.as_tensor(rng.normal(size=(6, 2)))
    noise = torch.as_tensor(rng.normal(size=(6, 3, 1)))
    seed = int(rng.integers(0, 10**6))
    got = student.helpers.euler_with_mlp(3, 2, seed, obs, noise, 1)
    want = reference.helpers.euler_with_mlp(3, 2, seed, obs, noise, 1)
    check_tensor(got, want, rtol=1e-7, atol=1e-9, name="the one-step sample")
    many = int(rng.integers(4, 12))
    check_tensor(student.helpers.euler_with_mlp(3, 2, seed, obs, noise, many),
                 reference.helpers.euler_with_mlp(3, 2, seed, obs, noise, many), rtol=1e-7, atol=1e-9,
                 name=f"the sample with K = {many}")


@stub("euler_sample", points=1, hint="Start from a copy of the noise (no in-place updates of it) and run under torch.no_grad().")
def test_leaves_the_noise_alone_and_tracks_no_gradient(student, rng):
    """The noise is unchanged afterwards, and the result does not require grad though the field has parameters"""
    A, b, C = _field(rng, 2, 2)
    obs, noise = rng.normal(size=(3, 2)), rng.normal(size=(3, 2))
    result, _, noise_after, grads = _run(student, A, b, C, obs, noise, 3)
    assert type(noise_after) is torch.Tensor and torch.equal(noise_after, torch.as_tensor(noise)), \
        "euler_sample modified the noise tensor in place"
    assert grads is None or all(g is None for g in grads), \
        "the result should not require grad: sample under torch.no_grad()"
    check_array(result.numpy().astype(np.float64), _euler(A, b, C, obs, noise, 3), rtol=1e-8, atol=1e-10, name="the result")


@stub("euler_sample", points=1, hint="Use exactly n_steps steps of size 1 / n_steps: a field constant in a gives a_0 + its integral.")
def test_field_of_time_only(student, rng):
    """v = t b + obs C: the Riemann sum b (K-1)/(2K) + obs C, exactly"""
    n, d, K = 4, 2, int(rng.integers(2, 10))
    _, b, C = _field(rng, d, 3)
    obs, noise = rng.normal(size=(n, 3)), rng.normal(size=(n, d))
    result, _, _, _ = _run(student, np.zeros((d, d)), b, C, obs, noise, K)
    check_array(result.numpy().astype(np.float64), noise + b * (K - 1) / (2 * K) + obs @ C, rtol=1e-8, atol=1e-10,
                name=f"the result of {K} steps")
