"""Hidden tests of hw2b's `policy_reward`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import expect_close, raised, sigmoid, softplus

HINT = "gail: -log(1 - D) = softplus(l); logd: log D = -softplus(-l); airl: l itself."


@stub("policy_reward", points=2, hint=HINT)
def test_values(student, rng):
    """Each kind on random (3, 4) logits"""
    logits = torch.as_tensor(rng.normal(scale=4.0, size=(3, 4)))
    d = sigmoid(logits.numpy())
    for kind, want in (("gail", -np.log(1 - d)), ("logd", np.log(d)), ("airl", logits.numpy())):
        expect_close(student.policy_reward(logits, kind), want, f"the {kind!r} reward", rtol=1e-6)


@stub("policy_reward", points=1, hint="Use softplus on the logits: log(sigmoid(l)) and log(1 - sigmoid(l)) underflow.")
def test_large_logits(student):
    """Logits of +-1000 and +-40"""
    logits = torch.tensor([-1000.0, -40.0, 40.0, 1000.0], dtype=torch.float64)
    x = logits.numpy()
    for kind, want in (("gail", softplus(x)), ("logd", -softplus(-x)), ("airl", x)):
        expect_close(student.policy_reward(logits, kind), want, f"the {kind!r} reward for large logits",
                     rtol=1e-9, atol=1e-300)


@stub("policy_reward", points=1, hint="d softplus(l) / dl = sigmoid(l); d(-softplus(-l)) / dl = sigmoid(-l).")
def test_gradient(student, rng):
    """Gradients of the summed rewards with respect to the logits"""
    logits = rng.normal(scale=2.0, size=5)
    for kind, want in (("gail", sigmoid(logits)), ("logd", sigmoid(-logits)), ("airl", np.ones(5))):
        (grad,) = student.helpers.grad("policy_reward", [torch.as_tensor(logits), kind], wrt=[0], grad_outputs=np.ones(5))
        assert grad is not None, f"the {kind!r} reward must be differentiable in the logits"
        expect_close(grad, want, f"d {kind!r} reward / d logits", rtol=1e-6)


@stub("policy_reward", points=1, hint="Only 'gail', 'logd' and 'airl' are kinds: raise ValueError for anything else.")
def test_unknown_kind(student, rng):
    """An unknown kind raises ValueError; the known ones do not"""
    logits = torch.as_tensor(rng.normal(size=3))
    for kind in ("wgan", "GAIL", ""):
        outcome = raised(student.policy_reward, logits, kind)
        assert outcome == "ValueError", f"kind {kind!r} should raise ValueError, got {outcome}"
    expect_close(student.policy_reward(logits, "airl"), logits.numpy(), "the 'airl' reward")
