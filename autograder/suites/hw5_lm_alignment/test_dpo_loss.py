"""Hidden tests of hw5's `dpo_loss`."""
import numpy as np
import torch

from autograder.suite import check_scalar, check_tensor, stub

HINT = "mean over pairs of -F.logsigmoid(beta * ((pi_c - ref_c) - (pi_r - ref_r))); a 0-dim tensor."


def _inputs(rng, n=12):
    return [torch.as_tensor(rng.normal(loc=-20, scale=4, size=n)) for _ in range(4)]


def _by_hand(pc, pr, rc, rr, beta):
    z = beta * ((pc - rc) - (pr - rr)).numpy()
    return float(np.mean(np.logaddexp(0.0, -z)))


def _value(x):
    assert type(x) is torch.Tensor and x.dim() == 0, f"return a 0-dim torch tensor, got {x!r:.60}"
    return float(x)


@stub("dpo_loss", points=2, hint=HINT)
def test_by_hand(student, rng):
    """Random log-probabilities, beta = 0.1 and beta = 2"""
    pc, pr, rc, rr = _inputs(rng)
    for beta in (0.1, 2.0):
        check_scalar(_value(student.dpo_loss(pc, pr, rc, rr, beta)), _by_hand(pc, pr, rc, rr, beta), rtol=1e-6,
                     name=f"the loss at beta = {beta}")


@stub("dpo_loss", points=1, hint=HINT)
def test_log2_at_reference(student, rng):
    """pi = pi_ref gives log 2 whatever the log-probabilities and beta; moved away from it, the loss moves"""
    pc, pr, rc, rr = _inputs(rng)
    check_scalar(_value(student.dpo_loss(pc, pr, pc.clone(), pr.clone(), 0.7)), np.log(2.0),
                 name="the loss when the policy equals the reference (every margin 0: log 2)")
    got = _value(student.dpo_loss(pc, pr, rc, rr, 0.7))
    assert abs(got - np.log(2.0)) > 1e-6, "the loss is log 2 even though the policy differs from the reference"
    check_scalar(got, _by_hand(pc, pr, rc, rr, 0.7), rtol=1e-6, name="the loss when the policy differs from the reference")


@stub("dpo_loss", points=2, hint=HINT)
def test_gradient_by_finite_difference(student, rng):
    """Autograd gradients with respect to pi_chosen and pi_rejected match central finite differences of the DPO loss"""
    # differences of the loss written out here, not of the submission's own value: a linear "loss" of the margin is
    # consistent with its own gradient and has the right signs
    pc, pr, rc, rr = (x[:5] for x in _inputs(rng))
    beta, h = 0.5, 1e-4
    g_c, g_r = student.helpers.grad("dpo_loss", [pc, pr, rc, rr, beta], wrt=[0, 1])
    assert g_c is not None and g_r is not None, "no gradient reaches the policy's log-probabilities: keep the graph"
    fd_c, fd_r = np.zeros(5), np.zeros(5)
    for i in range(5):
        e = torch.zeros(5, dtype=pc.dtype)
        e[i] = h
        fd_c[i] = (_by_hand(pc + e, pr, rc, rr, beta) - _by_hand(pc - e, pr, rc, rr, beta)) / (2 * h)
        fd_r[i] = (_by_hand(pc, pr + e, rc, rr, beta) - _by_hand(pc, pr - e, rc, rr, beta)) / (2 * h)
    check_tensor(g_c, torch.as_tensor(fd_c), rtol=1e-4, atol=1e-6,
                 name="d loss / d pi_chosen (it should be -beta * sigmoid(-beta * margin) / N)")
    check_tensor(g_r, torch.as_tensor(fd_r), rtol=1e-4, atol=1e-6, name="d loss / d pi_rejected")
    assert (g_c.numpy() < 0).all() and (g_r.numpy() > 0).all(), \
        "the loss should fall as pi_chosen rises and rise with pi_rejected"


@stub("dpo_loss", points=1, hint=HINT)
def test_direction_and_extremes(student):
    """Favouring the chosen completion lowers the loss; margins of +-1000 stay finite"""
    z = torch.zeros(1)
    up = _value(student.dpo_loss(torch.tensor([1.0]), z, z, z, 1.0))
    down = _value(student.dpo_loss(z, torch.tensor([1.0]), z, z, 1.0))
    assert up < np.log(2) < down, ("raising pi_chosen above the reference must lower the loss below log 2: the margin "
                                   "is (pi_chosen - ref_chosen) - (pi_rejected - ref_rejected), chosen minus rejected")
    check_scalar(up, float(np.log1p(np.exp(-1.0))), rtol=1e-6,
                 name="the loss at margin +1, beta = 1 (-log sigmoid(1), not a linear or hinge function of the margin)")
    extreme = _value(student.dpo_loss(torch.tensor([-1000.0]), z, z, z, 1.0))
    assert np.isfinite(extreme), "the loss at margin -1000 is not finite: use F.logsigmoid, not log(sigmoid(.))"
    check_scalar(extreme, 1000.0, rtol=1e-6, name="the loss at margin -1000")
