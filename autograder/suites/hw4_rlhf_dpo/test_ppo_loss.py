"""Hidden tests of hw4's `ppo_loss`: every term, the clip at both signs of the advantage, the KL penalty."""
import numpy as np
import torch

from autograder.suite import check_scalar, check_tensor, stub

HINT = ("loss = -mean(min(rho * A, clip(rho, 1 - eps, 1 + eps) * A)) + vf_coef * 0.5 * mean((V - R)^2) "
        "- ent_coef * mean(entropy) + kl_coef * mean(kl_to_ref), with rho = exp(new_log_prob - old_log_prob).")
KEYS = ("policy_loss", "value_loss", "entropy", "kl_ref", "approx_kl", "clip_frac")
ARGS = ("new_log_prob", "old_log_prob", "advantages", "new_values", "returns", "entropy", "kl_to_ref")


def _loss_grads(student, batch, wrt, clip=0.2, vf=0.5, ent=0.0, kl=0.0):
    """d loss / d each input named in ``wrt``, by autograd through the student's ppo_loss in the sandbox."""
    args = [batch[key] for key in ARGS] + [clip, vf, ent, kl]
    return student.helpers.grad("ppo_loss", args, wrt=[ARGS.index(key) for key in wrt], output=0)


def _batch(rng, b=32):
    t = lambda a: torch.as_tensor(a, dtype=torch.float64)
    return dict(new_log_prob=t(rng.normal(scale=0.3, size=b)), old_log_prob=t(rng.normal(scale=0.3, size=b)),
                advantages=t(rng.normal(size=b)), new_values=t(rng.normal(size=b)), returns=t(rng.normal(size=b)),
                entropy=t(rng.uniform(0, 2, size=b)), kl_to_ref=t(rng.uniform(0, 0.5, size=b)))


def _call(side, batch, clip=0.2, vf=0.5, ent=0.01, kl=0.1):
    out = side.ppo_loss(*batch.values(), clip, vf, ent, kl)
    assert isinstance(out, (tuple, list)) and len(out) == 2, "ppo_loss should return (loss, terms)"
    return out


@stub("ppo_loss", points=2, hint=HINT)
def test_matches_reference_loss_and_terms(student, reference, rng):
    """Random minibatch of 32 with every coefficient non-zero: the loss and each logged term"""
    batch = _batch(rng)
    (loss, terms), (want, want_terms) = _call(student, batch), _call(reference, batch)
    check_tensor(loss, want, rtol=1e-5, atol=1e-6, name="the loss")
    assert isinstance(terms, dict), f"the second result should be a dict of terms, got {type(terms).__name__}"
    for key in KEYS:
        assert key in terms, f"the terms dict misses {key!r} (has {sorted(terms)})"
        got = terms[key]
        got = float(got) if isinstance(got, torch.Tensor) and got.numel() == 1 else got
        check_scalar(got, float(want_terms[key]), rtol=1e-4, atol=1e-6, name=f"terms[{key!r}]")


def _grad(student, new, adv, old=None):
    n = len(new)
    t = lambda a: torch.as_tensor(np.asarray(a, dtype=float))
    batch = dict(new_log_prob=t(new), old_log_prob=t(np.zeros(n) if old is None else old), advantages=t(adv),
                 new_values=t(np.zeros(n)), returns=t(np.zeros(n)), entropy=t(np.zeros(n)), kl_to_ref=t(np.zeros(n)))
    return _loss_grads(student, batch, ["new_log_prob"])[0]


@stub("ppo_loss", points=1, hint="Positive advantage: the ratio is capped at 1 + eps (no gradient beyond it) but "
      "never floored (a ratio below 1 - eps is still pushed up).")
def test_clip_positive_advantage(student):
    """A > 0: gradient zero above 1 + eps, the unclipped gradient -A * rho / B below 1 - eps and inside"""
    new = np.log([1.5, 0.5, 1.1])
    got = _grad(student, new, [1.0, 1.0, 1.0])
    check_tensor(got, torch.tensor([0.0, -0.5 / 3, -1.1 / 3], dtype=torch.float64), rtol=1e-5, atol=1e-7,
                 name="d loss / d new_log_prob for ratios 1.5, 0.5, 1.1 with A = +1, eps = 0.2")


@stub("ppo_loss", points=1, hint="Negative advantage: the ratio is floored at 1 - eps (no gradient below it) but "
      "never capped (a ratio above 1 + eps is still pushed down).")
def test_clip_negative_advantage(student):
    """A < 0: gradient zero below 1 - eps, the unclipped gradient above 1 + eps and inside"""
    new = np.log([0.5, 1.5, 0.9])
    got = _grad(student, new, [-2.0, -2.0, -2.0])
    check_tensor(got, torch.tensor([0.0, 2.0 * 1.5 / 3, 2.0 * 0.9 / 3], dtype=torch.float64), rtol=1e-5, atol=1e-7,
                 name="d loss / d new_log_prob for ratios 0.5, 1.5, 0.9 with A = -2, eps = 0.2")


@stub("ppo_loss", points=1, hint="The KL penalty adds + kl_coef * mean(kl_to_ref) to the loss, with its gradient.")
def test_kl_penalty(student, rng):
    """The loss grows by kl_coef * mean(KL), and d loss / d KL = kl_coef / B"""
    batch = _batch(rng, 8)
    base = float(_call(student, batch, kl=0.0)[0])
    with_kl = float(_call(student, batch, kl=0.7)[0])
    check_scalar(with_kl - base, 0.7 * float(batch["kl_to_ref"].mean()), rtol=1e-5, atol=1e-7,
                 name="loss(kl_coef = 0.7) - loss(kl_coef = 0)")
    got = _loss_grads(student, batch, ["kl_to_ref"], kl=0.7)[0]
    check_tensor(got, torch.full((8,), 0.7 / 8, dtype=torch.float64), rtol=1e-5, name="d loss / d kl_to_ref")


@stub("ppo_loss", points=1, hint="Value loss 0.5 * mean((V - R)^2) weighted by vf_coef (gradient vf_coef * (V - R) / B); "
      "the entropy is a bonus: - ent_coef * mean(entropy).")
def test_value_and_entropy_terms(student, rng):
    """Gradients with respect to the values and to the entropy"""
    batch = _batch(rng, 6)
    got = _loss_grads(student, batch, ["new_values", "entropy"], ent=0.03)
    check_tensor(got[0], 0.5 * (batch["new_values"] - batch["returns"]) / 6, rtol=1e-5, atol=1e-8, name="d loss / d values")
    check_tensor(got[1], torch.full((6,), -0.03 / 6, dtype=torch.float64), rtol=1e-5, name="d loss / d entropy")


@stub("ppo_loss", points=1, hint="approx_kl = mean((rho - 1) - log rho); clip_frac = mean(|rho - 1| > eps); "
      "terms are detached numbers, the loss keeps its graph.")
def test_diagnostics(student):
    """approx_kl and clip_frac on known ratios; the terms carry no graph and the loss does"""
    ratios = np.array([1.0, 1.3, 0.7, 1.1])
    z = torch.zeros(4, dtype=torch.float64)
    loss, terms = student.ppo_loss(torch.as_tensor(np.log(ratios)), z, torch.ones(4, dtype=torch.float64), z, z, z, z,
                                   0.2, 0.5, 0.0, 0.0)
    check_scalar(float(terms["approx_kl"]), float(np.mean(ratios - 1 - np.log(ratios))), rtol=1e-5, name="approx_kl")
    check_scalar(float(terms["clip_frac"]), 0.5, name="clip_frac for ratios 1, 1.3, 0.7, 1.1 and eps 0.2")
    z, leaf = torch.zeros(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64)
    batch = dict(new_log_prob=leaf, old_log_prob=z, advantages=torch.ones(3, dtype=torch.float64), new_values=leaf,
                 returns=z, entropy=leaf, kl_to_ref=leaf)
    wrt = ["new_log_prob", "new_values", "entropy", "kl_to_ref"]
    grads = _loss_grads(student, batch, wrt, ent=0.01, kl=0.1)    # at ratio 1, A = 1, V = R = 0
    assert all(g is not None for g in grads), \
        "the loss has no autograd graph to some of its inputs: compute it with torch operations on the inputs"
    check_tensor(grads[0], torch.full((3,), -1 / 3, dtype=torch.float64), rtol=1e-5, name="d loss / d new_log_prob")
    check_tensor(grads[2], torch.full((3,), -0.01 / 3, dtype=torch.float64), rtol=1e-5, name="d loss / d entropy")
    check_tensor(grads[3], torch.full((3,), 0.1 / 3, dtype=torch.float64), rtol=1e-5, name="d loss / d kl_to_ref")
    args = [batch[key] for key in ARGS] + [0.2, 0.5, 0.01, 0.1]
    for key in KEYS:
        through = student.helpers.grad("ppo_loss", args, wrt=[ARGS.index(k) for k in wrt], output=[1, key])
        assert all(g is None for g in through), \
            f"terms[{key!r}] still carries the autograd graph: detach every value in the terms dict"
