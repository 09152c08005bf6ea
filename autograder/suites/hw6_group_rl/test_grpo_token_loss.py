"""Hidden tests of hw6's `grpo_token_loss`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array, expect_close, scalar

HINT = ("Per token: max(-ratio * A_b, -clip(ratio, 1 - eps, 1 + eps) * A_b) + beta * (exp(ref - logp) - (ref - logp) - 1), "
        "ratio = exp(logp - logp_old), A_b the row's advantage; length_norm=True: mean over each row's masked tokens, "
        "then over rows; False: masked sum / (B * T).")


# Losses and gradients are compared at rtol 1e-5: the docstring fixes no dtype, and the same loss computed in
# float32 (the models are float32) is off by about 1e-6; every mistake in a formula is off by far more.


def _args(lp, lp_old, lp_ref, adv, mask, eps, beta, norm):
    """The stub's arguments: positional, then keyword."""
    return [lp, lp_old, lp_ref, adv, mask], dict(clip_eps=eps, beta=beta, length_norm=norm)


def _loss(student, lp, **kw):
    """The student's loss."""
    args, kwargs = _args(lp, **kw)
    return student.grpo_token_loss(*args, **kwargs)


def _grad(student, lp, **kw):
    """The student's d loss / d logp, by autograd in the sandbox (a raw tensor, judged here)."""
    args, kwargs = _args(lp, **kw)
    return student.helpers.grad("grpo_token_loss", args, kwargs, wrt=[0])[0]


def _numpy_loss(lp, lp_old, lp_ref, adv, mask, eps, beta, norm):
    m = mask > 0
    lp, lp_old, lp_ref = (np.where(m, x, 0.0) for x in (lp, lp_old, lp_ref))
    ratio = np.exp(lp - lp_old)
    a = adv[:, None]
    per = np.maximum(-ratio * a, -np.clip(ratio, 1 - eps, 1 + eps) * a) + beta * (np.exp(lp_ref - lp) - (lp_ref - lp) - 1)
    per = np.where(m, per, 0.0)
    return float((per.sum(1) / m.sum(1)).mean()) if norm else float(per.sum() / m.size)


def _one_token(student, ratio, adv, eps=0.2):
    """Loss and d loss / d logp of a single masked token (beta = 0), in a row of two."""
    kw = dict(lp_old=torch.zeros(1, 2, dtype=torch.float64), lp_ref=torch.zeros(1, 2, dtype=torch.float64),
              adv=torch.tensor([adv], dtype=torch.float64), mask=torch.tensor([[0.0, 1.0]], dtype=torch.float64),
              eps=eps, beta=0.0, norm=True)
    lp0 = torch.tensor([[0.0, float(np.log(ratio))]], dtype=torch.float64)
    loss = scalar(_loss(student, lp0, **kw))
    grad = as_array(_grad(student, lp0, **kw), "the gradient")
    return loss, grad[0, 1]


@stub("grpo_token_loss", points=2, hint=HINT)
def test_clipping_positive_advantage(student):
    """A > 0: ratio 1.5 is clipped (no gradient); ratio 0.5 is not (gradient -ratio * A)"""
    loss, grad = _one_token(student, 1.5, 2.0)
    assert np.isclose(loss, -1.2 * 2.0), "A > 0, ratio 1.5 > 1 + eps: the loss should use the clipped ratio"
    assert abs(grad) < 1e-9, "A > 0, ratio above 1 + eps: the clipped token should have no gradient"
    loss, grad = _one_token(student, 0.5, 2.0)
    assert np.isclose(loss, -0.5 * 2.0) and np.isclose(grad, -0.5 * 2.0), \
        "A > 0, ratio 0.5: the unclipped term -ratio * A (and its gradient -ratio * A) applies"
    loss, grad = _one_token(student, 1.15, 2.0, eps=0.1)
    assert np.isclose(loss, -1.1 * 2.0) and abs(grad) < 1e-9, \
        "A > 0, ratio 1.15 with clip_eps = 0.1: clip at 1 + clip_eps (use the argument, not a fixed 0.2)"


@stub("grpo_token_loss", points=2, hint=HINT)
def test_clipping_negative_advantage(student):
    """A < 0: ratio 0.5 is clipped (no gradient); ratio 1.5 is not"""
    loss, grad = _one_token(student, 0.5, -2.0)
    assert np.isclose(loss, 0.8 * 2.0), "A < 0, ratio 0.5 < 1 - eps: the loss should use the clipped ratio"
    assert abs(grad) < 1e-9, "A < 0, ratio below 1 - eps: the clipped token should have no gradient"
    loss, grad = _one_token(student, 1.5, -2.0, eps=0.1)
    assert np.isclose(loss, 1.5 * 2.0) and np.isclose(grad, 1.5 * 2.0), \
        "A < 0, ratio 1.5: the unclipped term -ratio * A applies (whatever eps)"


@stub("grpo_token_loss", points=2, hint="k3 = exp(logp_ref - logp) - (logp_ref - logp) - 1 per token, times beta, "
                                       "averaged like the surrogate.")
def test_k3_penalty_value_and_gradient(student, rng):
    """Zero advantages: beta times the masked mean of k3, and its gradient beta * (1 - exp(ref - logp)) / n"""
    b, t = 3, 5
    mask = np.zeros((b, t))
    for i, n in enumerate(rng.permutation([2, 3, 4])):
        mask[i, 1:1 + n] = 1
    lp, lp_ref = -rng.exponential(size=(b, t)), -rng.exponential(size=(b, t))
    beta = float(rng.uniform(0.05, 0.5))
    kw = dict(lp_old=torch.as_tensor(lp), lp_ref=torch.as_tensor(lp_ref), adv=torch.zeros(b, dtype=torch.float64),
              mask=torch.as_tensor(mask), eps=0.2, beta=beta, norm=True)
    got = scalar(_loss(student, torch.as_tensor(lp), **kw))
    want = _numpy_loss(lp, lp, lp_ref, np.zeros(b), mask, 0.2, beta, True)
    expect_close(torch.tensor(got), want, "the k3 penalty", rtol=1e-5)
    grad = _grad(student, torch.as_tensor(lp), **kw)
    want_grad = beta * (1 - np.exp(lp_ref - lp)) * mask / mask.sum(1, keepdims=True) / b
    expect_close(grad, want_grad, "d loss / d logp of the k3 penalty", rtol=1e-5, atol=1e-8)


def _ragged(rng, b=4, t=7, junk=True):
    start = rng.integers(1, 3, size=(b, 1))
    end = start + rng.integers(1, t - 2, size=(b, 1))
    end[0] = t
    mask = ((np.arange(t)[None] >= start) & (np.arange(t)[None] < end)).astype(np.float64)
    lp_old = -rng.exponential(size=(b, t))
    lp = lp_old + rng.normal(scale=0.3, size=(b, t))
    lp_ref = lp_old + rng.normal(scale=0.3, size=(b, t))
    adv = rng.normal(size=b)
    if junk:   # extreme finite values where the mask is 0
        for x, v in ((lp, -1e3), (lp_old, 1e3), (lp_ref, 1e3)):
            x[mask == 0] = v
    return lp, lp_old, lp_ref, adv, mask


@stub("grpo_token_loss", points=2, hint=HINT)
def test_ragged_batch_grpo_normalisation(student, rng):
    """Ragged rows, junk on masked tokens, length_norm=True: each row's token mean, then the mean over rows"""
    lp, lp_old, lp_ref, adv, mask = _ragged(rng)
    beta = float(rng.uniform(0.02, 0.2))
    kw = dict(lp_old=torch.as_tensor(lp_old), lp_ref=torch.as_tensor(lp_ref), adv=torch.as_tensor(adv),
              mask=torch.as_tensor(mask), eps=0.2, beta=beta, norm=True)
    got = scalar(_loss(student, torch.as_tensor(lp), **kw))
    expect_close(torch.tensor(got), _numpy_loss(lp, lp_old, lp_ref, adv, mask, 0.2, beta, True),
                 "the loss with length_norm=True", rtol=1e-5)
    grad = as_array(_grad(student, torch.as_tensor(lp), **kw), "the gradient")
    assert np.all(grad[mask == 0] == 0), "masked tokens must get exactly zero gradient"


@stub("grpo_token_loss", points=2, hint=HINT)
def test_ragged_batch_dr_grpo_normalisation(student, rng):
    """Ragged rows, junk on masked tokens, length_norm=False: the masked sum divided by B * T"""
    lp, lp_old, lp_ref, adv, mask = _ragged(rng)
    beta = float(rng.uniform(0.02, 0.2))
    kw = dict(lp_old=torch.as_tensor(lp_old), lp_ref=torch.as_tensor(lp_ref), adv=torch.as_tensor(adv),
              mask=torch.as_tensor(mask), eps=0.2, beta=beta, norm=False)
    got = scalar(_loss(student, torch.as_tensor(lp), **kw))
    expect_close(torch.tensor(got), _numpy_loss(lp, lp_old, lp_ref, adv, mask, 0.2, beta, False),
                 "the loss with length_norm=False", rtol=1e-5)


@stub("grpo_token_loss", points=1, hint="advantages[b] belongs to row b: broadcast it as advantages[:, None].")
def test_each_row_has_its_own_advantage(student, rng):
    """A square batch (B = T): row b's tokens use advantages[b], not advantages[t]"""
    lp, lp_old, lp_ref, adv, mask = _ragged(rng, b=6, t=6, junk=False)
    mask[:] = 0
    mask[:, 1:] = 1
    kw = dict(lp_old=torch.as_tensor(lp_old), lp_ref=torch.as_tensor(lp_ref), adv=torch.as_tensor(adv),
              mask=torch.as_tensor(mask), eps=0.2, beta=0.0, norm=True)
    got = scalar(_loss(student, torch.as_tensor(lp), **kw))
    expect_close(torch.tensor(got), _numpy_loss(lp, lp_old, lp_ref, adv, mask, 0.2, 0.0, True),
                 "the loss of a square batch", rtol=1e-5)
