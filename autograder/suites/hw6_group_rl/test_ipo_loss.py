"""Hidden tests of hw6's `ipo_loss`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import expect_close, scalar

HINT = "mean over pairs of (h - 1 / (2 beta))^2, h = (pi_c - ref_c) - (pi_r - ref_r); a 0-dim tensor."


def _inputs(rng, n=10):
    return [torch.as_tensor(rng.normal(loc=-20, scale=3, size=n)) for _ in range(4)]


def _by_hand(pc, pr, rc, rr, beta):
    h = ((pc - rc) - (pr - rr)).numpy()
    return float(np.mean((h - 1 / (2 * beta)) ** 2))


@stub("ipo_loss", points=2, hint=HINT)
def test_by_hand(student, rng):
    """Random log-probabilities at two values of beta"""
    pc, pr, rc, rr = _inputs(rng)
    for beta in (float(rng.uniform(0.05, 0.2)), float(rng.uniform(0.5, 2.0))):
        got = scalar(student.ipo_loss(pc, pr, rc, rr, beta))
        expect_close(torch.tensor(got), _by_hand(pc, pr, rc, rr, beta), f"the loss at beta = {beta:.3f}", rtol=1e-6)


@stub("ipo_loss", points=2, hint="d loss / d pi_chosen = 2 (h - 1/(2 beta)) / N; the rejected side has the opposite sign.")
def test_gradient(student, rng):
    """Autograd gradients with respect to pi_chosen and pi_rejected: 2 (h - 1/(2 beta)) / N and its negative"""
    pc, pr, rc, rr = _inputs(rng, n=6)
    beta = float(rng.uniform(0.1, 1.0))
    g_c, g_r = student.helpers.grad("ipo_loss", [pc, pr, rc, rr, beta], wrt=[0, 1])
    h = ((pc - rc) - (pr - rr)).numpy()
    want = 2 * (h - 1 / (2 * beta)) / len(h)
    # rtol 1e-4, atol 1e-5: h - 1/(2 beta) cancels log-probabilities of size 20, so a loss computed in float32 (the
    # docstring fixes no dtype) is off by about 1e-6 in each entry; every mistake in the formula is off by far more
    expect_close(g_c, want, "d loss / d pi_chosen", rtol=1e-4, atol=1e-5)
    expect_close(g_r, -want, "d loss / d pi_rejected", rtol=1e-4, atol=1e-5)


@stub("ipo_loss", points=1, hint="The target margin is 1 / (2 beta): the loss is zero there, (1 / (2 beta))^2 at pi = pi_ref.")
def test_target_margin(student, rng):
    """Zero at the margin 1/(2 beta) exactly, (1/(2 beta))^2 at pi = pi_ref"""
    beta = float(rng.uniform(0.1, 1.0))
    rc, rr = (torch.as_tensor(rng.normal(loc=-10, size=5)) for _ in range(2))
    pr = rr + torch.as_tensor(rng.normal(size=5))
    pc = rc + (pr - rr) + 1 / (2 * beta)
    assert abs(scalar(student.ipo_loss(pc, pr, rc, rr, beta))) < 1e-9, "a margin of exactly 1/(2 beta) should cost 0"
    at_ref = scalar(student.ipo_loss(rc, rr, rc.clone(), rr.clone(), beta))
    expect_close(torch.tensor(at_ref), (1 / (2 * beta)) ** 2, "the loss at pi = pi_ref", rtol=1e-6)
    half = torch.as_tensor(np.arange(5) < 2)               # two pairs at the target margin, three at the reference
    mixed = scalar(student.ipo_loss(torch.where(half, pc, rc), torch.where(half, pr, rr), rc, rr, beta))
    expect_close(torch.tensor(mixed), 3 / 5 * (1 / (2 * beta)) ** 2,
                 "the loss with 2 of 5 pairs at the target margin and 3 at margin 0 (a mean of squares, not the square "
                 "of the mean margin's distance)", rtol=1e-6)
