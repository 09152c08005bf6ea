"""Hidden tests of hw1b's `mixture_nll`: closed forms in float64 here, gradients against the reference."""
import numpy as np
import torch
from scipy.special import logsumexp

from autograder.suite import check_tensor, stub

HINT = ("log w = log_softmax(logits); log N_m = sum_j [-(t_j - mu_mj)^2 / (2 sigma_mj^2) - log sigma_mj - 0.5 log 2 pi]; "
        "loss = -mean_i logsumexp_m (log w_im + log N_im); a 0-d tensor that keeps its graph.")


def _instance(rng, n, m, d, spread=1.0):
    logits = rng.normal(size=(n, m)) * 1.5
    means = rng.normal(size=(n, m, d)) * 2.0
    log_stds = rng.uniform(-1.0, 0.7, size=(n, m, d))
    targets = rng.normal(size=(n, d)) * 2.0 * spread
    return logits, means, log_stds, targets


def _closed_form(logits, means, log_stds, targets):
    log_w = logits - logsumexp(logits, axis=1, keepdims=True)
    z = (targets[:, None, :] - means) / np.exp(log_stds)
    log_n = (-0.5 * z**2 - log_stds - 0.5 * np.log(2 * np.pi)).sum(axis=2)
    return float(-logsumexp(log_w + log_n, axis=1).mean())


def _t(*arrays):
    return [torch.as_tensor(a, dtype=torch.float32) for a in arrays]


def _scalar(got):
    assert type(got) is torch.Tensor and got.shape == (), \
        f"mixture_nll should return a 0-dimensional torch tensor, got {type(got).__name__} of shape {getattr(got, 'shape', '?')}"


@stub("mixture_nll", points=2, hint=HINT)
def test_value_on_random_mixtures(student, rng):
    """Random mixtures of 3 components in 4 dimensions: the value equals the closed form"""
    inst = _instance(rng, 9, 3, 4)
    got = student.mixture_nll(*_t(*inst))
    _scalar(got)
    check_tensor(got, torch.tensor(_closed_form(*inst), dtype=torch.float32), rtol=1e-4, atol=1e-4, name="the loss")


@stub("mixture_nll", points=1, hint="With one component the mixture is a diagonal Gaussian: sum the log-density over dimensions.")
def test_one_component_is_a_gaussian(student, rng):
    """M = 1: the Gaussian negative log-likelihood, summed over dimensions, averaged over the batch"""
    _, means, log_stds, targets = _instance(rng, 6, 1, 3)
    want = float(np.mean(((targets - means[:, 0]) ** 2 / (2 * np.exp(2 * log_stds[:, 0])) + log_stds[:, 0]
                          + 0.5 * np.log(2 * np.pi)).sum(axis=1)))
    got = student.mixture_nll(*_t(np.zeros((6, 1)), means, log_stds, targets))
    _scalar(got)
    check_tensor(got, torch.tensor(want, dtype=torch.float32), rtol=1e-4, atol=1e-4, name="the loss of one Gaussian component")


@stub("mixture_nll", points=1, hint="The weights are softmax(logits) over the components (per row), so adding a constant to a row's logits changes nothing.")
def test_weights_are_the_softmax_of_the_logits(student, rng):
    """Unequal weights match the closed form, and shifting each row's logits leaves the loss unchanged"""
    logits, means, log_stds, targets = _instance(rng, 5, 4, 2)
    want = _closed_form(logits, means, log_stds, targets)
    shifted = logits + rng.normal(size=(5, 1)) * 5
    for name, lg in (("the loss", logits), ("the loss with each row's logits shifted by a constant", shifted)):
        check_tensor(student.mixture_nll(*_t(lg, means, log_stds, targets)), torch.tensor(want, dtype=torch.float32),
                     rtol=1e-4, atol=1e-4, name=name)


@stub("mixture_nll", points=1, hint="Average over the batch (mean over rows), do not sum.")
def test_averages_over_the_batch(student, rng):
    """A batch repeated three times has the same loss; one row alone matches its closed form"""
    inst = _instance(rng, 4, 2, 3)
    want = _closed_form(*inst)
    tripled = [np.concatenate([a] * 3) for a in inst]
    check_tensor(student.mixture_nll(*_t(*tripled)), torch.tensor(want, dtype=torch.float32), rtol=1e-4, atol=1e-4,
                 name="the loss of the batch repeated three times")
    one = [a[:1] for a in inst]
    check_tensor(student.mixture_nll(*_t(*one)), torch.tensor(_closed_form(*one), dtype=torch.float32), rtol=1e-4,
                 atol=1e-4, name="the loss of a single row")


@stub("mixture_nll", points=1, hint="Use log_softmax and logsumexp: log(sum(exp(.))) underflows to log(0) = -inf far from every component.")
def test_stable_far_from_every_component(student, rng):
    """Targets hundreds of standard deviations from every component: finite and exact"""
    logits, means, log_stds, _ = _instance(rng, 4, 3, 2)
    targets = means[:, 0, :] + rng.choice([-1, 1], size=(4, 2)) * 400.0
    want = _closed_form(logits, means, log_stds, targets)
    got = student.mixture_nll(*_t(logits, means, log_stds, targets))
    _scalar(got)
    check_tensor(got, torch.tensor(want, dtype=torch.float32), rtol=1e-3, name="the loss far from every component")


@stub("mixture_nll", points=1, hint="Keep everything in torch (no .item(), .detach() or numpy) so gradients reach logits, means and log_stds.")
def test_gradients_match_the_reference(student, reference, rng):
    """The gradients with respect to logits, means and log_stds equal the reference's"""
    inst = _t(*_instance(rng, 7, 3, 2))
    got, want = (ns.helpers.grad("mixture_nll", list(inst), wrt=[0, 1, 2]) for ns in (student, reference))
    assert isinstance(got, list) and len(got) == 3, "could not differentiate the loss with respect to its three inputs"
    for name, g, w in zip(("logits", "means", "log_stds"), got, want):
        assert g is not None, f"no gradient reaches {name}: keep everything in torch"
        check_tensor(g, w, rtol=1e-4, atol=1e-6, name=f"the gradient with respect to {name}")
