"""Hidden tests of hw1b's `flow_matching_loss`, at linear velocity fields whose loss and gradient are known
in closed form (computed here, in float64)."""
import numpy as np
import torch

from autograder.suite import check_array, check_scalar, stub

HINT = ("a_t = (1 - t) a_0 + t a_1 with t broadcast over each chunk; target a_1 - a_0; loss = mean over samples of "
        "the squared error summed over the chunk's entries; call velocity(a_t, t, obs) once on the whole batch.")


def _instance(rng, n, shape, obs_dim=3):
    d = int(np.prod(shape))
    A = rng.normal(size=(d, d)) * 0.5
    b = rng.normal(size=d)
    C = rng.normal(size=(obs_dim, d)) * 0.5
    obs = rng.normal(size=(n, obs_dim))
    chunks = rng.uniform(-1, 1, size=(n,) + shape)
    noise = rng.normal(size=(n,) + shape)
    t = rng.uniform(0, 1, size=n)
    return A, b, C, obs, chunks, noise, t


def _closed_form(A, b, C, obs, chunks, noise, t):
    """The loss and its gradients with respect to A, b and C."""
    n = len(chunks)
    a1, a0 = chunks.reshape(n, -1), noise.reshape(n, -1)
    at = (1 - t[:, None]) * a0 + t[:, None] * a1
    residual = at @ A + t[:, None] * b + obs @ C - (a1 - a0)          # (n, D)
    loss = float((residual**2).sum(axis=1).mean())
    g = 2 * residual / n
    return loss, at.T @ g, (t[:, None] * g).sum(axis=0), obs.T @ g


def _call(student, inst):
    A, b, C, obs, chunks, noise, t = inst
    tensors = [torch.as_tensor(x, dtype=torch.float64) for x in (obs, chunks, noise, t)]
    out = student.helpers.flow_loss_and_grads(A, b, C, *tensors)
    assert isinstance(out, tuple) and len(out) == 3, "flow_matching_loss did not run"
    loss, grads, inputs = out
    assert type(loss) is torch.Tensor and loss.shape == (), \
        f"flow_matching_loss should return a 0-dimensional torch tensor, got {type(loss).__name__} {getattr(loss, 'shape', '')}"
    return loss, grads, inputs


@stub("flow_matching_loss", points=3, hint=HINT)
def test_value_at_a_linear_field(student, rng):
    """At a random linear field v = a A + t b + obs C: the loss equals its closed form, for chunks (N, H, act_dim) and (N, D)"""
    for shape in ((3, 2), (4,)):
        inst = _instance(rng, 11, shape)
        loss, _, _ = _call(student, inst)
        check_scalar(float(loss), _closed_form(*inst)[0], rtol=1e-6, name=f"the loss for chunks of shape (N,) + {shape}")


@stub("flow_matching_loss", points=2, hint="Do not detach the prediction or convert to numpy: the loss must carry the velocity network's gradient.")
def test_gradient_at_a_linear_field(student, rng):
    """The gradients with respect to the field's parameters equal their closed forms"""
    inst = _instance(rng, 9, (2, 2))
    _, grads, _ = _call(student, inst)
    assert grads is not None and all(g is not None for g in grads), \
        "the loss should be a tensor that requires grad (through the velocity network)"
    _, gA, gb, gC = _closed_form(*inst)
    for name, g, w in zip(("A", "b", "C"), grads, (gA, gb, gC)):
        check_array(g.numpy(), w, rtol=1e-6, atol=1e-9, name=f"the gradient with respect to {name}")


@stub("flow_matching_loss", points=1, hint="Give the velocity each sample's own t (shape (N,)) and call it once on the whole batch.")
def test_one_call_on_the_whole_batch(student, rng):
    """The velocity is called exactly once, on the whole batch of points a_t with each sample's own t"""
    inst = _instance(rng, 6, (3, 1))
    _, _, inputs = _call(student, inst)
    assert isinstance(inputs, list) and len(inputs) == 1, \
        f"call the velocity network once on the whole batch, it was called {len(inputs)} times"
    a_t, t = inputs[0]
    _, _, _, _, chunks, noise, times = inst
    check_array(t.numpy().astype(np.float64).reshape(-1), times, rtol=1e-12, atol=0,
                name="the t given to the velocity (each sample's own t, shape (N,))")
    want = (1 - times)[:, None, None] * noise + times[:, None, None] * chunks
    check_array(a_t.numpy().astype(np.float64).reshape(len(want), -1), want.reshape(len(want), -1), rtol=1e-9,
                atol=1e-12, name="the points a_t given to the velocity")
    loss, _, _ = _call(student, inst)
    check_scalar(float(loss), _closed_form(*inst)[0], rtol=1e-6, name="the loss")


@stub("flow_matching_loss", points=1, hint="At t = 1 the point is the data (a_t = a_1), at t = 0 the noise; the target is a_1 - a_0 either way.")
def test_end_points_of_the_path(student, rng):
    """t = 0 and t = 1 for every sample: the closed form at both ends"""
    A, b, C, obs, chunks, noise, _ = _instance(rng, 5, (2, 1))
    for value in (0.0, 1.0):
        inst = (A, b, C, obs, chunks, noise, np.full(5, value))
        loss, _, _ = _call(student, inst)
        check_scalar(float(loss), _closed_form(*inst)[0], rtol=1e-6, name=f"the loss with t = {value:g} everywhere")
