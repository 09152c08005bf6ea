"""Hidden tests of hw6's `kto_loss`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import expect_close, scalar

HINT = ("r = pi - ref; desirable: w_d * sigmoid(beta (r - z0)), undesirable: w_u * sigmoid(beta (z0 - r)); "
        "the loss is the mean over ALL completions of (w - v), z0 detached.")


# Losses and gradients are compared at rtol 1e-5: the docstring fixes no dtype, and the same loss computed in
# float32 (the models are float32) is off by about 1e-6; every mistake in a formula is off by far more.


def _sigmoid(x):
    return 1 / (1 + np.exp(-x))


def _by_hand(pi, ref, des, z0, beta, wd, wu):
    r = pi - ref
    w = np.where(des, wd, wu)
    v = w * _sigmoid(beta * np.where(des, r - z0, z0 - r))
    return float(np.mean(w - v))


def _inputs(rng, n=12):
    ref = rng.normal(loc=-15, scale=3, size=n)
    pi = ref + rng.normal(scale=2, size=n)
    des = rng.random(n) < 0.5
    des[:2] = [True, False]
    if 2 * des.sum() == n:   # never as many desirable as undesirable: a mean per kind would then equal the mean
        des[2] = not des[2]
    return pi, ref, des, float(rng.uniform(0.1, 1.5))


@stub("kto_loss", points=3, hint=HINT)
def test_by_hand_with_weights(student, rng):
    """Random completions, a mix of desirable and undesirable, unequal weights, z0 > 0"""
    pi, ref, des, z0 = _inputs(rng)
    beta, wd, wu = float(rng.uniform(0.1, 1.0)), float(rng.uniform(0.5, 1.5)), float(rng.uniform(1.5, 3.0))
    got = scalar(student.kto_loss(torch.as_tensor(pi), torch.as_tensor(ref), torch.as_tensor(des), z0, beta,
                                  w_desirable=wd, w_undesirable=wu))
    expect_close(torch.tensor(got), _by_hand(pi, ref, des, z0, beta, wd, wu), "the loss", rtol=1e-5)
    got = scalar(student.kto_loss(torch.as_tensor(pi), torch.as_tensor(ref), torch.as_tensor(des), z0, beta))
    expect_close(torch.tensor(got), _by_hand(pi, ref, des, z0, beta, 1.0, 1.0), "the loss with default weights", rtol=1e-5)


@stub("kto_loss", points=2, hint="Treat z0 as a constant (detach it); d loss / d pi = -w beta s (1 - s) / N for a "
                                "desirable completion, +w beta s (1 - s) / N for an undesirable one.")
def test_gradient_and_detached_reference_point(student, rng):
    """Gradient with respect to pi by the closed form; no gradient reaches z0 given as a tensor"""
    pi, ref, des, z0 = _inputs(rng, n=8)
    beta = float(rng.uniform(0.2, 1.0))
    args = [torch.as_tensor(pi), torch.as_tensor(ref), torch.as_tensor(des), torch.tensor(z0, dtype=torch.float64), beta]
    grads = student.helpers.grad("kto_loss", args, dict(w_desirable=1.0, w_undesirable=2.0), wrt=[0, 3])
    r = pi - ref
    s = _sigmoid(beta * np.where(des, r - z0, z0 - r))
    w = np.where(des, 1.0, 2.0)
    want = np.where(des, -1.0, 1.0) * w * beta * s * (1 - s) / len(pi)
    expect_close(grads[0], want, "d loss / d pi", rtol=1e-5, atol=1e-9)
    assert grads[1] is None or float(torch.as_tensor(grads[1]).abs().sum()) == 0.0, \
        "gradient flowed into the reference point z0: detach it"


@stub("kto_loss", points=1, hint=HINT)
def test_at_the_reference(student, rng):
    """pi = ref and z0 = 0: each completion costs half its weight; a float and a tensor z0 agree"""
    _, ref, des, z0 = _inputs(rng)
    wd, wu = float(rng.uniform(0.5, 1.5)), float(rng.uniform(1.5, 3.0))
    got = scalar(student.kto_loss(torch.as_tensor(ref), torch.as_tensor(ref), torch.as_tensor(des), 0.0, 0.5,
                                  w_desirable=wd, w_undesirable=wu))
    expect_close(torch.tensor(got), float(np.mean(np.where(des, wd, wu)) / 2), "the loss at pi = ref, z0 = 0", rtol=1e-5)
    pi = ref + rng.normal(size=len(ref))
    a = scalar(student.kto_loss(torch.as_tensor(pi), torch.as_tensor(ref), torch.as_tensor(des), z0, 0.5))
    b = scalar(student.kto_loss(torch.as_tensor(pi), torch.as_tensor(ref), torch.as_tensor(des), torch.tensor(z0), 0.5))
    assert np.isclose(a, b, rtol=1e-5), "z0 given as a float and as a 0-dim tensor should give the same loss"
    expect_close(torch.tensor(a), _by_hand(pi, ref, des, z0, 0.5, 1.0, 1.0), "the loss", rtol=1e-5)
