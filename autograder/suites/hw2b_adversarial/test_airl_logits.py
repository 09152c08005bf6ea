"""Hidden tests of hw2b's `airl_logits`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import expect_close

HINT = "f = g + gamma * (1 - done) * h_next - h, and the logit is f - log_pi."


def _tensors(rng, shape, n=4):
    return [torch.as_tensor(rng.normal(size=shape)) for _ in range(n)]


def _by_hand(g, h, h_next, log_pi, gamma, done):
    return (g + gamma * (1 - done) * h_next - h - log_pi).numpy()


@stub("airl_logits", points=2, hint=HINT)
def test_by_hand(student, rng):
    """A (4, 6) batch with random done flags and discount"""
    g, h, h_next, log_pi = _tensors(rng, (4, 6))
    log_pi = -log_pi.abs()
    done = torch.as_tensor((rng.random((4, 6)) < 0.4).astype(float))
    gamma = float(rng.uniform(0.5, 0.99))
    got = student.airl_logits(g, h, h_next, log_pi, gamma, done)
    expect_close(got, _by_hand(g, h, h_next, log_pi, gamma, done), "the logits")


@stub("airl_logits", points=2, hint=HINT + " Broadcast the arguments; gradients flow into all four tensors.")
def test_broadcast_and_gradient(student, rng):
    """g and h of shape (S, 1), h_next and log_pi (S, A), done (1, A); gradients of the summed logits"""
    g, h = (torch.as_tensor(rng.normal(size=(3, 1))) for _ in range(2))
    h_next, log_pi = (torch.as_tensor(rng.normal(size=(3, 5))) for _ in range(2))
    done = torch.tensor([[0.0, 1.0, 0.0, 0.0, 1.0]], dtype=torch.float64)
    gamma = float(rng.uniform(0.5, 0.99))
    out, grads = student.helpers.value_and_grad("airl_logits", [g, h, h_next, log_pi, gamma, done], wrt=[0, 1, 2, 3],
                                                grad_outputs=np.ones((3, 5)))
    expect_close(out, _by_hand(g, h, h_next, log_pi, gamma, done), "the broadcast logits")
    names = ("g", "h", "h_next", "log_pi")
    assert all(x is not None for x in grads), \
        f"no gradient flows into {[n for n, x in zip(names, grads) if x is None]}"
    expect_close(grads[0], np.full((3, 1), 5.0), "d sum(logits) / d g")
    expect_close(grads[1], np.full((3, 1), -5.0), "d sum(logits) / d h")
    expect_close(grads[2], np.broadcast_to(gamma * (1 - done.numpy()), (3, 5)), "d sum(logits) / d h_next")
    expect_close(grads[3], -np.ones((3, 5)), "d sum(logits) / d log_pi")


@stub("airl_logits", points=1, hint="With gamma = 1 and done on the last step, the shaping adds up to -h(s_0).")
def test_shaping_telescopes(student, rng):
    """Along one trajectory with gamma = 1 the shaping sums to -h(s_0); D = exp f / (exp f + pi)"""
    h_states = rng.normal(size=8)                      # h(s_0) .. h(s_7): 7 transitions, the last one done
    g = torch.as_tensor(rng.normal(size=7))
    done = torch.zeros(7, dtype=torch.float64)
    done[-1] = 1.0
    f = student.airl_logits(g, torch.as_tensor(h_states[:-1]), torch.as_tensor(h_states[1:]),
                            torch.zeros(7, dtype=torch.float64), 1.0, done)
    expect_close(f.sum(), float(g.sum()) - h_states[0], "the sum of f along the trajectory (log_pi = 0)")
    pi = rng.uniform(0.05, 0.9, size=7)
    logit = student.airl_logits(g, torch.zeros(7, dtype=torch.float64), torch.zeros(7, dtype=torch.float64),
                                torch.as_tensor(np.log(pi)), 0.9, done)
    d = 1 / (1 + np.exp(-logit.detach().numpy()))
    expect_close(torch.as_tensor(d), np.exp(g.numpy()) / (np.exp(g.numpy()) + pi), "sigmoid(logits), which should be D")
