"""Hidden tests of hw1's `bc_loss`: value against the reference, batch mean, action sum, gradients.

Every policy here is ``sandbox_helpers.bc_policy``: a GaussianPolicy whose ``log_prob`` and ``distribution``
raise, since ``-policy.log_prob(obs, actions).mean()`` (the library's density, which the public check
compares with) would answer the stub without the formula the notebook asks for.
"""
import numpy as np
import torch

from autograder.suite import check_array, check_tensor, stub
from rlcourse.nets import GaussianPolicy

HINT = ("-log pi(a|s) = sum_j [ (a_j - mu_j)^2 / (2 sigma_j^2) + log sigma_j + 0.5 log(2 pi) ]; "
        "sum over action dimensions, average over the batch, return a 0-d tensor that keeps its graph.")


def _policy(ns, seed, obs_dim, act_dim, log_std):
    """A seeded policy with the given log_std, built the same way on both sides (a handle)."""
    return ns.helpers.bc_policy(seed, obs_dim, act_dim, np.asarray(log_std, dtype=np.float32))


def _data(rng, n, obs_dim, act_dim, scale=1.0):
    return (torch.as_tensor(rng.normal(size=(n, obs_dim)), dtype=torch.float32),
            torch.as_tensor(scale * rng.normal(size=(n, act_dim)), dtype=torch.float32))


def _loss(ns, seed, obs, act, log_std):
    return ns.bc_loss(_policy(ns, seed, obs.shape[1], act.shape[1], log_std), obs, act)


def _scalar_tensor(got, what="bc_loss"):
    assert type(got) is torch.Tensor and got.shape == (), \
        f"{what} should return a 0-dimensional torch tensor, got {type(got).__name__} of shape {getattr(got, 'shape', '?')}"


@stub("bc_loss", points=2, hint=HINT)
def test_matches_reference_on_fixed_data(student, reference, rng):
    """A random policy and batch: the value equals the reference's"""
    obs, act = _data(rng, 32, 5, 3)
    log_std = rng.uniform(-1.5, 0.5, size=3)
    got = _loss(student, 1, obs, act, log_std)
    _scalar_tensor(got)
    check_tensor(got, _loss(reference, 1, obs, act, log_std), rtol=1e-5, atol=1e-5, name="the loss")


@stub("bc_loss", points=1, hint="Average over the batch (mean over rows), not a sum: the loss must not grow with N.")
def test_averages_over_the_batch(student, reference, rng):
    """Repeating the batch leaves the loss unchanged; a single pair matches the reference"""
    obs, act = _data(rng, 6, 4, 2)
    once = _loss(student, 2, obs, act, [0.2, -0.4])
    thrice = _loss(student, 2, obs.repeat(3, 1), act.repeat(3, 1), [0.2, -0.4])
    _scalar_tensor(once)
    check_tensor(thrice, once, rtol=1e-5, name="the loss of the batch repeated three times")
    check_tensor(_loss(student, 2, obs[:1], act[:1], [0.2, -0.4]), _loss(reference, 2, obs[:1], act[:1], [0.2, -0.4]),
                 rtol=1e-5, name="the loss of one pair")


@stub("bc_loss", points=1, hint="The log-density of a diagonal Gaussian is a SUM over action dimensions (then average over the batch).")
def test_sums_over_action_dimensions(student, reference, rng):
    """One and four action dimensions, with the log(2 pi) constant, match the reference"""
    for act_dim in (1, 4):
        obs, act = _data(rng, 10, 3, act_dim)
        log_std = rng.uniform(-1, 0.5, size=act_dim)
        check_tensor(_loss(student, 3, obs, act, log_std), _loss(reference, 3, obs, act, log_std), rtol=1e-5,
                     atol=1e-5, name=f"the loss with {act_dim} action dimension(s)")


@stub("bc_loss", points=2, hint="Keep the computation in torch (no .item(), .detach() or numpy) so autograd reaches every parameter.")
def test_gradient_matches_finite_differences(student, rng):
    """d loss / d log_std and d loss / d mean bias equal central finite differences of the loss itself"""
    obs, act = _data(rng, 40, 4, 3)
    log_std = np.array([-0.6, 0.1, -0.2], dtype=np.float32)
    _, grads = student.helpers.parameter_grads("bc_loss", [_policy(student, 4, 4, 3, log_std), obs, act],
                                               names=["log_std", "mean.bias"])
    assert isinstance(grads, dict) and set(grads) == {"log_std", "mean.bias"}, "could not differentiate the loss"
    for name in ("log_std", "mean.bias"):
        assert grads[name] is not None, f"the loss does not depend on `{name}`: no gradient reaches it"
        assert type(grads[name]) is torch.Tensor and grads[name].shape == (3,), f"could not differentiate the loss by `{name}`"
    eps = 1e-2
    fd_log_std, fd_bias = [], []
    for j in range(3):
        step = np.eye(3, dtype=np.float32)[j] * eps
        plus, minus = _loss(student, 4, obs, act, log_std + step), _loss(student, 4, obs, act, log_std - step)
        fd_log_std.append((float(plus) - float(minus)) / (2 * eps))
        plus, minus = (student.bc_loss(student.helpers.bc_policy(4, 4, 3, log_std, bias_shift=d), obs, act)
                       for d in (step, -step))
        fd_bias.append((float(plus) - float(minus)) / (2 * eps))
    check_array(grads["log_std"].numpy().astype(float), np.array(fd_log_std), rtol=2e-2, atol=2e-3,
                name="the gradient with respect to log_std")
    check_array(grads["mean.bias"].numpy().astype(float), np.array(fd_bias), rtol=2e-2, atol=2e-3,
                name="the gradient with respect to the mean's bias")
    with torch.random.fork_rng():       # the same policy on the grader's side
        torch.manual_seed(4)
        mean = GaussianPolicy(4, 3, hidden=(16, 16))(obs).detach()
    sigma = torch.exp(torch.as_tensor(log_std))
    z = (act - mean) / sigma
    check_array(grads["log_std"].numpy().astype(float), (1 - z**2).mean(0).numpy().astype(float), rtol=1e-3, atol=1e-4,
                name="the gradient with respect to log_std (each entry is the batch mean of 1 - z^2, z = (a - mu) / sigma)")
    check_array(grads["mean.bias"].numpy().astype(float), (-z / sigma).mean(0).numpy().astype(float), rtol=1e-3,
                atol=1e-4, name="the gradient with respect to the mean's bias (each entry is the batch mean of -z / sigma)")


@stub("bc_loss", points=1, hint="Gradients must reach the network's weights through the mean: do not detach policy(obs).")
def test_gradients_reach_every_parameter(student, reference, rng):
    """The gradients of all parameters equal the reference's"""
    obs, act = _data(rng, 16, 5, 2)
    got, want = (ns.helpers.parameter_grads("bc_loss", [_policy(ns, 5, 5, 2, [-0.3, 0.4]), obs, act])[1]
                 for ns in (student, reference))
    assert isinstance(got, dict) and set(got) == set(want), "could not differentiate the loss"
    for i, name in enumerate(want):
        assert got[name] is not None, f"parameter {i} (`{name}`) gets no gradient: the loss does not depend on it"
        check_tensor(got[name], want[name], rtol=1e-4, atol=1e-6, name=f"the gradient of parameter {i} (`{name}`)")


@stub("bc_loss", points=1, hint="Use log_std directly (it is log sigma); avoid log(exp(.)) and dividing by tiny variances in a way that overflows.")
def test_extreme_values(student, reference, rng):
    """Tiny and large standard deviations, actions far from the mean: finite and exact"""
    obs, act = _data(rng, 8, 3, 2, scale=30.0)
    for log_std in ([-8.0, -6.0], [3.0, 2.5]):
        got = _loss(student, 6, obs, act, log_std)
        _scalar_tensor(got)
        check_tensor(got, _loss(reference, 6, obs, act, log_std), rtol=1e-4, name=f"the loss with log_std {log_std}")
