"""Hidden tests of hw4's `dpo_loss`: a hand computation, log 2 at the reference, a finite-difference gradient,
the logged metrics, stability, and no gradient into the reference."""
import numpy as np
import torch

from autograder.suite import check_scalar, check_tensor, stub
from rlcourse.nets import GaussianPolicy

HINT = ("r = beta * (sum_t log pi(a_t|s_t) - sum_t log pi_ref(a_t|s_t)) per segment, margin = r_chosen - r_rejected, "
        "loss = -mean(logsigmoid(margin)); reference under torch.no_grad().")
INFO = ("margin", "accuracy", "chosen_reward", "rejected_reward")


def _policy(s, ls, shift=0.0, dstd=0.0):
    torch.manual_seed(s)
    p = GaussianPolicy(11, 3, hidden=(8,), log_std_init=ls)
    p.mean.bias.data.add_(torch.as_tensor(shift, dtype=torch.float32))
    p.log_std.data.add_(torch.as_tensor(dstd, dtype=torch.float32))
    return p


def _gauss_loglik(policy, obs, act):
    """Hand-written diagonal Gaussian log-density summed over action dims and time, in float64 numpy."""
    with torch.no_grad():
        mean = policy(torch.as_tensor(obs)).double().numpy()
    log_std = policy.log_std.detach().double().numpy()
    z = (act - mean) / np.exp(log_std)
    return (-0.5 * z**2 - log_std - 0.5 * np.log(2 * np.pi)).sum(axis=(-1, -2))


def _hand_loss(pol, ref, co, ca, ro, ra, beta):
    m = beta * ((_gauss_loglik(pol, co, ca) - _gauss_loglik(ref, co, ca)) - (_gauss_loglik(pol, ro, ra) - _gauss_loglik(ref, ro, ra)))
    return np.mean(np.logaddexp(0.0, -m)), m


def _data(rng, b=10, length=6):
    f = lambda *s: rng.normal(size=s).astype(np.float32)
    return dict(co=f(b, length, 11), ca=np.clip(f(b, length, 3), -1, 1), ro=f(b, length, 11), ra=np.clip(f(b, length, 3), -1, 1))


def _args(student, d, beta, s=0, rs=0, ls=-0.5, shift=0.0, dstd=0.0):
    """dpo_loss's arguments in the sandbox: the moved policy and its reference (sandbox_helpers.dpo_policy, both
    built like :func:`_policy` here), the chosen and the rejected segments, beta."""
    d = {k: torch.as_tensor(v) for k, v in d.items()}
    return [student.helpers.dpo_policy(s, ls, shift, dstd), student.helpers.dpo_policy(rs, ls), (d["co"], d["ca"]),
            (d["ro"], d["ra"]), beta]


def _student_call(student, d, beta, **policies):
    out = student.dpo_loss(*_args(student, d, beta, **policies))
    assert isinstance(out, (tuple, list)) and len(out) == 2, "dpo_loss should return (loss, info)"
    return out


@stub("dpo_loss", points=2, hint=HINT)
def test_matches_hand_computation(student, rng):
    """A moved policy against its reference, beta 0.3: the loss from a hand-written Gaussian log-density"""
    d = _data(rng)
    loss, _ = _student_call(student, d, 0.3, shift=0.2, dstd=0.1)
    want, _ = _hand_loss(_policy(0, -0.5, 0.2, 0.1), _policy(0, -0.5), d["co"], d["ca"], d["ro"], d["ra"], 0.3)
    assert isinstance(loss, torch.Tensor) and loss.dim() == 0, f"the loss should be a 0-dim tensor, got {loss!r}"
    check_scalar(float(loss), want, rtol=1e-4, atol=1e-5, name="the DPO loss")


@stub("dpo_loss", points=1, hint="With policy == reference every log-ratio is 0, the margin is 0, and the loss is log 2.")
def test_log2_at_the_reference(student, rng):
    """policy == reference (same weights) for several betas: loss log 2, margin 0, accuracy 0; moved away, not log 2"""
    d = _data(rng, 7, 25)
    for beta in (0.01, 0.5, 5.0):
        loss, info = _student_call(student, d, beta, s=4, rs=4)
        check_scalar(float(loss), np.log(2), rtol=1e-5, name=f"the loss at policy == reference (beta {beta})")
        check_scalar(float(info["margin"]), 0.0, atol=1e-5, name="info['margin'] at policy == reference")
        check_scalar(float(info["accuracy"]), 0.0, name="info['accuracy'] at policy == reference (no margin is > 0)")
    loss, _ = _student_call(student, d, 0.5, s=4, rs=4, shift=0.4)
    want, _ = _hand_loss(_policy(4, -0.5, 0.4), _policy(4, -0.5), d["co"], d["ca"], d["ro"], d["ra"], 0.5)
    assert abs(float(loss) - np.log(2)) > 1e-4, "the loss is log 2 even when the policy has moved away from the reference"
    check_scalar(float(loss), want, rtol=1e-4, atol=1e-5, name="the loss once the policy's mean has moved")


@stub("dpo_loss", points=2, hint="The gradient must flow through the policy's log-likelihoods (keep the graph) and "
      "have the sign of -d logsigmoid(margin): compare with a finite difference of the loss.")
def test_gradient_matches_finite_difference(student, rng):
    """Autograd gradient in the policy's mean bias and log-std, against central differences of the hand loss"""
    d = _data(rng, 8, 5)
    beta, shift, dstd = 0.5, 0.1, -0.1
    _, grads = student.helpers.parameter_grads("dpo_loss", _args(student, d, beta, shift=shift, dstd=dstd), output=0,
                                               names=["mean.bias", "log_std"])
    assert grads["mean.bias"] is not None and grads["log_std"] is not None, \
        "no gradient reaches the policy: keep the graph through its log-likelihoods"
    got = [grads["mean.bias"], grads["log_std"]]
    ref, h = _policy(0, -0.5), 1e-3
    for which, name in ((0, "mean.bias"), (1, "log_std")):
        fd = np.zeros(3)
        for k in range(3):
            e = np.zeros(3); e[k] = h
            plus = _policy(0, -0.5, shift + (e if which == 0 else 0), dstd + (e if which == 1 else 0))
            minus = _policy(0, -0.5, shift - (e if which == 0 else 0), dstd - (e if which == 1 else 0))
            lp = _hand_loss(plus, ref, d["co"], d["ca"], d["ro"], d["ra"], beta)[0]
            lm = _hand_loss(minus, ref, d["co"], d["ca"], d["ro"], d["ra"], beta)[0]
            fd[k] = (lp - lm) / (2 * h)
        check_tensor(got[which].double(), torch.as_tensor(fd), rtol=2e-2, atol=2e-4, name=f"d loss / d policy.{name}")


@stub("dpo_loss", points=1, hint="info: margin = mean(r_chosen - r_rejected), accuracy = mean(margin > 0) (strict), "
      "chosen_reward = mean(r_chosen), rejected_reward = mean(r_rejected), with r = beta * log-ratio.")
def test_logged_metrics(student, rng):
    """margin, accuracy (with some exact-zero margins), chosen and rejected implied rewards"""
    d = _data(rng, 12, 4)
    d["ro"][:4], d["ra"][:4] = d["co"][:4], d["ca"][:4]  # four pairs with identical segments: margin exactly 0
    beta = 0.7
    _, info = _student_call(student, d, beta, shift=0.3, dstd=0.2)
    pol, ref = _policy(0, -0.5, 0.3, 0.2), _policy(0, -0.5)
    rc = beta * (_gauss_loglik(pol, d["co"], d["ca"]) - _gauss_loglik(ref, d["co"], d["ca"]))
    rr = beta * (_gauss_loglik(pol, d["ro"], d["ra"]) - _gauss_loglik(ref, d["ro"], d["ra"]))
    m = rc - rr
    m[:4] = 0.0
    for key, want in (("margin", m.mean()), ("chosen_reward", rc.mean()), ("rejected_reward", rr.mean()),
                      ("accuracy", float((m > 0).mean()))):
        assert key in info, f"info misses {key!r} (has {sorted(info)})"
        check_scalar(float(info[key]), float(want), rtol=1e-4, atol=1e-4, name=f"info[{key!r}]")
    args = _args(student, d, beta, shift=0.3, dstd=0.2)
    for key in INFO:
        _, through = student.helpers.parameter_grads("dpo_loss", args, output=[1, key])
        assert all(g is None for g in through.values()), f"info[{key!r}] still carries the autograd graph: detach the logged metrics"


@stub("dpo_loss", points=1, hint=HINT)
def test_large_margins_are_stable(student, rng):
    """A policy far from its reference with a large beta: finite loss equal to softplus(-margin)"""
    d = _data(rng, 6, 25)
    loss, _ = _student_call(student, d, 50.0, rs=9, shift=0.8, dstd=-0.8)
    want, m = _hand_loss(_policy(0, -0.5, 0.8, -0.8), _policy(9, -0.5), d["co"], d["ca"], d["ro"], d["ra"], 50.0)
    assert np.abs(m).max() > 200, "test set-up: margins should be large"
    assert np.isfinite(float(loss)), ("the loss is not finite when margins are in the hundreds: use "
                                      "F.logsigmoid(margin), not log(sigmoid(margin)) (a margin of -1000 gives 1000)")
    check_scalar(float(loss), want, rtol=1e-3, name="the loss with margins in the hundreds")


@stub("dpo_loss", points=1, hint="Compute the reference's log-likelihoods under torch.no_grad() (or detach them).")
def test_no_gradient_into_the_reference(student, rng):
    """After backward, the policy has gradients and the reference has none"""
    d = _data(rng, 5, 5)
    args = _args(student, d, 0.5, s=0, rs=1, shift=0.1)
    _, into_policy = student.helpers.parameter_grads("dpo_loss", args, output=0, module=0, names=["mean.bias"])
    _, into_reference = student.helpers.parameter_grads("dpo_loss", args, output=0, module=1)
    policy_grad = into_policy["mean.bias"]
    assert policy_grad is not None, "the policy gets no gradient: keep the graph through its log-likelihoods"
    assert all(g is None for g in into_reference.values()), ("the reference's parameters got gradients: compute its "
                                                             "log-likelihoods under torch.no_grad() (or detach them)")
    d = {k: torch.as_tensor(v) for k, v in d.items()}
    pol, ref = _policy(0, -0.5, 0.1), _policy(1, -0.5)
    for p in ref.parameters():
        p.requires_grad_(False)
    beta = 0.5
    def seq(policy, o, a):
        return policy.log_prob(o, a).sum(-1)
    m = beta * ((seq(pol, d["co"], d["ca"]) - seq(ref, d["co"], d["ca"])) - (seq(pol, d["ro"], d["ra"]) - seq(ref, d["ro"], d["ra"])))
    (-torch.nn.functional.logsigmoid(m).mean()).backward()
    check_tensor(policy_grad, pol.mean.bias.grad, rtol=1e-4, atol=1e-6,
                 name="the gradient of the loss with respect to the policy's mean bias")
