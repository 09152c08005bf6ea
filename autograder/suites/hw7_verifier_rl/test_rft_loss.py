"""Hidden tests of hw7's `rft_loss`: value and gradient against a direct computation on random ragged masks."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array, expect_close, scalar

HINT = "-(sum of logp over the masked entries) / (number of masked entries), masked-out entries selected away."


# Compared at rtol 1e-6: the docstring fixes no dtype, and the same mean computed in float32 is off by about 1e-7;
# a mean per row, a sum, or junk let through is off by far more.


def _case(rng, b=5, t=7):
    lp = -rng.exponential(size=(b, t))
    mask = (rng.random((b, t)) < 0.5).astype(float)
    mask[np.arange(b), rng.integers(t, size=b)] = 1.0
    mask[0], mask[1] = 1.0, np.eye(t)[rng.integers(t)]   # rows of t tokens and of 1: a mean per row differs
    return lp, mask


@stub("rft_loss", points=2, hint=HINT)
def test_value_and_gradient_on_ragged_masks(student, rng):
    """A (5, 7) batch with a random mask: the value and d loss / d logp"""
    lp, mask = _case(rng)
    x, m = torch.as_tensor(lp), torch.as_tensor(mask)
    value = scalar(student.rft_loss(x, m))
    assert np.isclose(value, -(lp * mask).sum() / mask.sum(), rtol=1e-6), \
        "the loss is not the mean of -logp over ALL masked tokens of the batch (per row first? the mask ignored?)"
    grad = student.helpers.grad("rft_loss", [x, m], {}, wrt=[0])[0]
    expect_close(grad, -mask / mask.sum(), "d loss / d logp", rtol=1e-6, atol=1e-9)


@stub("rft_loss", points=1, hint="Where mask is 0, logp may be -inf or NaN: torch.where(mask > 0, logp, 0), "
                                 "not logp * mask (0 * inf is NaN, in the value and the gradient).")
def test_masked_entries_may_be_anything(student, rng):
    """-inf and NaN where the mask is 0 change neither value nor gradient"""
    lp, mask = _case(rng, b=4, t=6)
    dirty = np.where(mask > 0, lp, np.where(rng.random(lp.shape) < 0.5, -np.inf, np.nan))
    x, m = torch.as_tensor(dirty), torch.as_tensor(mask)
    value = scalar(student.rft_loss(x, m))
    assert np.isclose(value, -(lp * mask).sum() / mask.sum(), rtol=1e-6), "the loss changed with the masked-out entries"
    grad = as_array(student.helpers.grad("rft_loss", [x, m], {}, wrt=[0])[0], "d loss / d logp")
    assert np.allclose(grad, -mask / mask.sum(), rtol=1e-6, atol=1e-9), "the gradient changed with the masked-out entries"


@stub("rft_loss", points=1, hint="A mean over tokens (not over rows, not a sum): doubling the batch leaves the loss unchanged.")
def test_a_token_mean_not_a_sum(student, rng):
    """The batch twice over gives the same loss; float32 in gives float32 out"""
    lp, mask = _case(rng, b=3, t=5)
    one = scalar(student.rft_loss(torch.as_tensor(lp), torch.as_tensor(mask)))
    two = scalar(student.rft_loss(torch.as_tensor(np.vstack([lp, lp])), torch.as_tensor(np.vstack([mask, mask]))))
    assert np.isclose(one, two, rtol=1e-6), "the loss doubled with the batch: divide by the number of masked tokens"
    assert np.isclose(one, -(lp * mask).sum() / mask.sum(), rtol=1e-6), "the loss is not the mean of -logp over the masked tokens"
    out = student.rft_loss(torch.as_tensor(lp).float(), torch.as_tensor(mask).float())
    assert type(out) is torch.Tensor and out.dtype == torch.float32, "float32 log-probabilities should give a float32 loss"
