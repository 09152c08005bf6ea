"""Hidden tests of hw4's `sequence_log_prob`."""
import torch

from autograder.suite import check_tensor, stub

HINT = "policy.log_prob(obs, actions) gives log pi(a_t|s_t) per step, shape (..., L); sum it over the last (time) axis."


def _policy(ns, s, sq, ls):
    """A seeded GaussianPolicy(11, 3), built from the release on that side (a handle)."""
    return ns.helpers.build("rlcourse.nets.GaussianPolicy", 11, 3, hidden=(16, 16), squash=sq, log_std_init=ls,
                            torch_seed=s)


def _seg(rng, *shape):
    return (torch.as_tensor(rng.normal(size=shape + (11,)), dtype=torch.float32),
            torch.as_tensor(rng.uniform(-1, 1, size=shape + (3,)), dtype=torch.float32))


def _both(student, reference, obs, act, s=0, sq=False, ls=-0.5):
    return tuple(ns.sequence_log_prob(_policy(ns, s, sq, ls), obs, act) for ns in (student, reference))


@stub("sequence_log_prob", points=2, hint=HINT)
def test_batch_of_segments(student, reference, rng):
    """8 segments of 25 steps: one log-likelihood per segment"""
    got, want = _both(student, reference, *_seg(rng, 8, 25))
    check_tensor(got, want, rtol=1e-5, atol=1e-4, name="the log-likelihoods of 8 segments")


@stub("sequence_log_prob", points=1, hint="Sum over time (not mean); one segment (L, 11) gives a 0-dim tensor.")
def test_lengths_and_leading_shapes(student, reference, rng):
    """Segments of 1 and 7 steps, one unbatched segment, and a (2, 3) batch of segments"""
    for shape in ((4, 1), (3, 7), (9,), (2, 3, 5)):
        got, want = _both(student, reference, *_seg(rng, *shape), s=2)
        check_tensor(got, want, rtol=1e-5, atol=1e-4, name=f"the result for obs of shape {shape + (11,)}")


@stub("sequence_log_prob", points=1, hint="Always the unsquashed Gaussian's log-density (policy.log_prob), also when "
      "the policy squashes its acting mean with tanh.")
def test_squashed_policy_uses_unsquashed_density(student, reference, rng):
    """A policy with squash=True and a different log-std"""
    got, want = _both(student, reference, *_seg(rng, 5, 10), s=3, sq=True, ls=-1.5)
    check_tensor(got, want, rtol=1e-5, atol=1e-3, name="the log-likelihoods under a squashing policy")


@stub("sequence_log_prob", points=1, hint="Use torch operations on the policy's output so the gradient reaches "
      "its parameters (no numpy, no detach, no torch.no_grad).")
def test_gradient_reaches_the_policy(student, reference, rng):
    """The gradient of the summed log-likelihood with respect to the policy's log-std and its mean's bias"""
    obs, act = _seg(rng, 4, 6)
    got, want = (ns.helpers.parameter_grads("sequence_log_prob", [_policy(ns, 1, False, -0.5), obs, act],
                                            names=["log_std", "mean.bias"], grad_outputs=torch.ones(4))[1]
                 for ns in (student, reference))
    assert got["log_std"] is not None, "no gradient reaches the policy's log_std: keep the computation in torch"
    check_tensor(got["log_std"], want["log_std"], rtol=1e-4, atol=1e-4, name="d sum(log-likelihood) / d log_std")
    assert got["mean.bias"] is not None, "no gradient reaches the policy's mean: do not detach its output"
    check_tensor(got["mean.bias"], want["mean.bias"], rtol=1e-4, atol=1e-4, name="d sum(log-likelihood) / d mean.bias")
