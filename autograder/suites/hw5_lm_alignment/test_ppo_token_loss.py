"""Hidden tests of hw5's `ppo_token_loss`."""
import numpy as np
import torch

from autograder.suite import check_scalar, check_tensor, stub

HINT = ("Per token: max(-ratio * A, -clip(ratio, 1 - eps, 1 + eps) * A) with ratio = exp(logp - logp_old); "
        "plus value_coef * (V - G)^2; both averaged over ALL masked tokens of the batch (sum / mask.sum()).")


def _args(lp, lp_old, adv, v, ret, mask, eps, c):
    """The stub's arguments: positional, then keyword."""
    return [lp, lp_old, adv, v, ret, mask], dict(clip_eps=eps, value_coef=c)


def _loss(ns, **kw):
    args, kwargs = _args(**kw)
    return ns.ppo_token_loss(*args, **kwargs)


def _grad(ns, **kw):
    """d loss / d logp, by autograd through that side's ppo_token_loss (a raw tensor, judged here)."""
    args, kwargs = _args(**kw)
    return ns.helpers.grad("ppo_token_loss", args, kwargs, wrt=[0])[0]


def _one_token(student, ratio, adv, eps=0.2):
    """Loss and d loss / d logp of a single masked token."""
    kw = dict(lp_old=torch.zeros(1, 2), adv=torch.tensor([[0.0, adv]]), v=torch.zeros(1, 2), ret=torch.zeros(1, 2),
              mask=torch.tensor([[0.0, 1.0]]), eps=eps, c=0.5)
    lp0 = torch.tensor([[0.0, float(np.log(ratio))]])
    loss = _loss(student, lp=lp0, **kw)
    grad = _grad(student, lp=lp0, **kw)
    assert type(loss) is torch.Tensor and loss.dim() == 0, "return a 0-dim torch tensor"
    assert type(grad) is torch.Tensor, "no gradient reaches logp: keep the loss in torch"
    return float(loss), grad.detach().numpy()[0, 1]


@stub("ppo_token_loss", points=2, hint=HINT)
def test_clipping_positive_advantage(student):
    """A > 0: ratio 1.5 is clipped at 1.2 (no gradient); ratio 0.5 is not clipped (gradient -ratio * A)"""
    loss, grad = _one_token(student, 1.5, 2.0)
    check_scalar(loss, -1.2 * 2.0, name="the loss at ratio 1.5, A = 2")
    check_scalar(grad, 0.0, atol=1e-9, name="the gradient at ratio 1.5, A = 2 (clipped)")
    loss, grad = _one_token(student, 0.5, 2.0)
    check_scalar(loss, -0.5 * 2.0, name="the loss at ratio 0.5, A = 2")
    check_scalar(grad, -0.5 * 2.0, name="the gradient at ratio 0.5, A = 2 (unclipped)")


@stub("ppo_token_loss", points=2, hint=HINT)
def test_clipping_negative_advantage(student):
    """A < 0: ratio 0.5 is clipped at 0.8 (no gradient); ratio 1.5 is not clipped"""
    loss, grad = _one_token(student, 0.5, -2.0)
    check_scalar(loss, 0.8 * 2.0, name="the loss at ratio 0.5, A = -2")
    check_scalar(grad, 0.0, atol=1e-9, name="the gradient at ratio 0.5, A = -2 (clipped)")
    loss, grad = _one_token(student, 1.5, -2.0)
    check_scalar(loss, 1.5 * 2.0, name="the loss at ratio 1.5, A = -2")
    check_scalar(grad, 1.5 * 2.0, name="the gradient at ratio 1.5, A = -2 (unclipped)")


@stub("ppo_token_loss", points=1, hint=HINT)
def test_other_clip_range(student):
    """eps = 0.1 clips at 1.1"""
    loss, _ = _one_token(student, 1.5, 1.0, eps=0.1)
    check_scalar(loss, -1.1, name="the loss at ratio 1.5, A = 1, eps = 0.1")


@stub("ppo_token_loss", points=2, hint=HINT)
def test_ragged_batch_matches_reference(student, reference, rng):
    """Random batch with ragged masks and extreme values on masked tokens: a token-level masked mean"""
    b, t = 4, 7
    mask = (np.arange(t)[None] >= rng.integers(1, 3, size=(b, 1))) & (np.arange(t)[None] < rng.integers(3, 8, size=(b, 1)))
    mask[0], mask[1] = np.arange(t) >= 1, np.arange(t) == 2   # rows of 6 and 1 tokens: a mean per sequence differs
    kw = {k: torch.as_tensor(rng.normal(scale=0.3, size=(b, t))) for k in ("lp", "lp_old", "adv", "v", "ret")}
    for k in kw:
        kw[k][~torch.as_tensor(mask)] = 1e3 * (1 if k != "lp" else -1)   # junk where masked
    kw.update(mask=torch.as_tensor(mask.astype(np.float64)), eps=0.2, c=0.7)
    want = _loss(reference, **kw)
    got = _loss(student, **kw)
    check_tensor(got, want, rtol=1e-6, atol=1e-9, name="the loss")


@stub("ppo_token_loss", points=1, hint="value_coef times the masked mean of (values - returns)^2, with its gradient "
      "reaching the values.")
def test_value_term(student):
    """Zero advantages: the loss is value_coef times the masked mean squared value error"""
    mask = torch.tensor([[0.0, 1.0, 1.0], [0.0, 1.0, 0.0]])
    v, ret = torch.tensor([[9.0, 1.0, 2.0], [9.0, 3.0, 9.0]]), torch.zeros(2, 3)
    got = _loss(student, lp=torch.zeros(2, 3), lp_old=torch.zeros(2, 3), adv=torch.zeros(2, 3), v=v, ret=ret,
                mask=mask, eps=0.2, c=0.25)
    check_scalar(float(got), 0.25 * (1 + 4 + 9) / 3, name="the value loss")
    args, kwargs = _args(lp=torch.zeros(2, 3), lp_old=torch.zeros(2, 3), adv=torch.zeros(2, 3), v=v, ret=ret, mask=mask,
                         eps=0.2, c=0.25)
    grad = student.helpers.grad("ppo_token_loss", args, kwargs, wrt=[3])[0]
    assert type(grad) is torch.Tensor, "no gradient reaches the values: the value head must be trained by this loss (no detach)"
    check_tensor(grad, 0.25 * 2 * (v - ret) * mask / 3, rtol=1e-6, atol=1e-9,
                 name="d loss / d values (value_coef * 2 (V - G) / number of masked tokens, 0 off the mask)")
