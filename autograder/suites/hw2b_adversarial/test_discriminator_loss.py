"""Hidden tests of hw2b's `discriminator_loss`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import expect_close, scalar, sigmoid, softplus

HINT = "mean over expert logits of softplus(-l) plus mean over policy logits of softplus(l): a 0-dim tensor."


def _logits(rng, n, loc=0.0):
    return torch.as_tensor(rng.normal(loc=loc, scale=3.0, size=n))


@stub("discriminator_loss", points=2, hint=HINT)
def test_by_hand(student, rng):
    """Random logits, more policy samples than expert ones"""
    for n_e, n_p in ((7, 11), (12, 5)):
        e, p = _logits(rng, n_e, 1.0), _logits(rng, n_p, -1.0)
        want = softplus(-e.numpy()).mean() + softplus(p.numpy()).mean()
        got = scalar(student.discriminator_loss(e, p))
        expect_close(torch.tensor(got), want, f"the loss with {n_e} expert and {n_p} policy samples")


@stub("discriminator_loss", points=2, hint="d loss / d l_expert = -sigmoid(-l) / N_E; d loss / d l_policy = sigmoid(l) / N_P.")
def test_gradient(student, rng):
    """Autograd gradients with respect to both sides' logits"""
    e, p = _logits(rng, 6), _logits(rng, 9)
    g_e, g_p = student.helpers.grad("discriminator_loss", [e, p], wrt=[0, 1])
    assert g_e is not None and g_p is not None, "the loss must be differentiable in both inputs (is it detached?)"
    expect_close(g_e, -sigmoid(-e.numpy()) / 6, "d loss / d expert_logits")
    expect_close(g_p, sigmoid(p.numpy()) / 9, "d loss / d policy_logits")


@stub("discriminator_loss", points=1, hint="Work from the logits with softplus: log(sigmoid(l)) is -inf for l = -1000.")
def test_large_logits(student):
    """Logits of +-1000: a confident right discriminator costs about 0, a confident wrong one 2000"""
    big = torch.tensor([1000.0, 1000.0], dtype=torch.float64)
    right = scalar(student.discriminator_loss(big, -big), "the loss of a confident, right discriminator")
    wrong = scalar(student.discriminator_loss(-big, big), "the loss of a confident, wrong discriminator")
    assert abs(right) < 1e-9, "a discriminator sure and right on every sample should cost (almost) nothing"
    assert abs(wrong - 2000.0) < 1e-6, "a discriminator sure and wrong costs about |l| per side: 1000 + 1000"
    # beside an undecided sample on each side (D = 1/2, log 2 each): max(0, -l) for softplus(-l) gave 0 here
    zero = torch.zeros(1, dtype=torch.float64)
    mixed = scalar(student.discriminator_loss(torch.cat([big[:1], zero]), torch.cat([-big[:1], zero])),
                   "the loss of a discriminator sure and right on one sample and undecided on another, on each side")
    assert abs(mixed - np.log(2)) < 1e-9, ("one sure-and-right and one undecided sample per side cost (0 + log 2) / 2 "
                                           "per side, log 2 in all: softplus(-l) = log(1 + exp(-l)), not max(0, -l)")


@stub("discriminator_loss", points=1, hint="At the optimal discriminator the loss is 2 log 2 - 2 JS(expert, policy).")
def test_optimal_discriminator(student, rng):
    """Samples of two distributions on six cells, logits log p_E - log p_pi of the empirical frequencies"""
    counts_e, counts_p = rng.integers(1, 9, size=6), rng.integers(1, 9, size=6)
    p_e, p_p = counts_e / counts_e.sum(), counts_p / counts_p.sum()
    logit = np.log(p_e) - np.log(p_p)
    e = torch.as_tensor(np.repeat(logit, counts_e))
    p = torch.as_tensor(np.repeat(logit, counts_p))
    m = (p_e + p_p) / 2
    js = 0.5 * (p_e * np.log(p_e / m)).sum() + 0.5 * (p_p * np.log(p_p / m)).sum()
    got = scalar(student.discriminator_loss(e, p))
    expect_close(torch.tensor(got), 2 * np.log(2) - 2 * js, "the loss at the optimal discriminator")
    worse = scalar(student.discriminator_loss(e + 0.3, p + 0.3))
    assert worse > got, "moving away from the optimal discriminator must raise the loss"
