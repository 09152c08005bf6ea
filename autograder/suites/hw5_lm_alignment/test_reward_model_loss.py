"""Hidden tests of hw5's `reward_model_loss`."""
import numpy as np
import torch

from autograder.suite import check_scalar, check_tensor, stub

HINT = "mean over pairs of -F.logsigmoid(chosen - rejected); a 0-dim tensor."


def _value(x):
    assert type(x) is torch.Tensor and x.dim() == 0, f"return a 0-dim torch tensor, got {x!r:.60}"
    return float(x)


@stub("reward_model_loss", points=2, hint=HINT)
def test_by_hand(student, rng):
    """Random scores: the mean Bradley-Terry negative log-likelihood"""
    c, r = rng.normal(scale=2, size=17), rng.normal(scale=2, size=17)
    want = np.mean(np.log1p(np.exp(-(c - r))))
    check_scalar(_value(student.reward_model_loss(torch.as_tensor(c), torch.as_tensor(r))), want, rtol=1e-6)


@stub("reward_model_loss", points=1, hint="Chosen minus rejected, not the other way round; a mean, not a sum.")
def test_sign_and_mean(student):
    """A correctly ranked pair costs less than a misranked one; doubling the data leaves the loss unchanged"""
    good = _value(student.reward_model_loss(torch.tensor([2.0]), torch.tensor([0.0])))
    bad = _value(student.reward_model_loss(torch.tensor([0.0]), torch.tensor([2.0])))
    assert good < bad, "ranking the chosen sequence higher should give the smaller loss"
    check_scalar(good, float(np.log1p(np.exp(-2.0))), rtol=1e-6,
                 name="the loss of one pair with chosen 2, rejected 0 (-log sigmoid(2), not a hinge or linear loss)")
    check_scalar(_value(student.reward_model_loss(torch.tensor([2.0, 2.0]), torch.tensor([0.0, 0.0]))), good,
                 name="the loss of the same pair twice")


@stub("reward_model_loss", points=1, hint="Use F.logsigmoid: log(sigmoid(d)) is -inf for d below about -100.")
def test_extreme_scores(student):
    """Score gaps of +-1000 give finite losses (about 1000 and 0), beside a tied pair (log 2)"""
    got = _value(student.reward_model_loss(torch.tensor([-500.0, 500.0, 3.0]), torch.tensor([500.0, -500.0, 3.0])))
    check_scalar(got, (1000.0 + np.log(2.0)) / 3, rtol=1e-6,
                 name="the mean loss of pairs with gaps -1000, +1000 and 0 (the tied pair costs log 2)")


@stub("reward_model_loss", points=1, hint=HINT)
def test_gradient(student, rng):
    """d loss / d chosen = -(1 - sigmoid(c - r)) / N, and its opposite for the rejected scores"""
    c, r = torch.as_tensor(rng.normal(size=6)), torch.as_tensor(rng.normal(size=6))
    got, got_r = student.helpers.grad("reward_model_loss", [c, r], wrt=[0, 1])
    check_tensor(got, -(1 - torch.sigmoid(c - r)) / 6, rtol=1e-6, atol=1e-9, name="the gradient")
    assert got_r is not None, "no gradient reaches the rejected scores: both sides of the pair train the reward model"
    check_tensor(got_r, (1 - torch.sigmoid(c - r)) / 6, rtol=1e-6, atol=1e-9, name="d loss / d rejected_scores")
