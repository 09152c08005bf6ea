"""Hidden tests of hw5's `kl_penalised_rewards`."""
import numpy as np
import torch

from autograder.suite import check_array, stub


HINT = ("rewards = -beta * (logp - logp_ref) on masked tokens, 0 elsewhere, plus score[b] at the LAST position "
        "where mask[b] is 1 (which may be the last column).")


def _by_hand(score, logp, logp_ref, mask, beta):
    out = -beta * (logp - logp_ref) * mask
    for b in range(len(score)):
        out[b, np.flatnonzero(mask[b])[-1]] += score[b]
    return out


def _call(student, rng, ragged_batch, beta, bool_mask=False):
    _, _, mask = ragged_batch(rng, b=5, t=8)
    logp, logp_ref = -rng.exponential(size=(5, 8)), -rng.exponential(size=(5, 8))   # junk outside the mask too
    score = rng.normal(size=5)
    got = student.kl_penalised_rewards(torch.as_tensor(score), torch.as_tensor(logp), torch.as_tensor(logp_ref),
                                       mask.bool() if bool_mask else mask, beta)
    assert type(got) is torch.Tensor, f"return a torch tensor, got {type(got).__name__}"
    return got.detach().numpy(), _by_hand(score, logp, logp_ref, mask.numpy(), beta)


@stub("kl_penalised_rewards", points=2, hint=HINT)
def test_by_hand_ragged_rows(student, rng, ragged_batch):
    """Five rows of different lengths (one running to the last column), beta = 0.3"""
    got, want = _call(student, rng, ragged_batch, 0.3)
    check_array(got, want, rtol=1e-6, atol=1e-9)


@stub("kl_penalised_rewards", points=1, hint="The KL term is -beta * (logp - logp_ref): a policy above the reference pays.")
def test_sign_and_beta(student, rng, ragged_batch):
    """beta = 0 leaves only the score on the last token; beta = 2 scales the penalty"""
    for beta in (0.0, 2.0):
        got, want = _call(student, rng, ragged_batch, beta)
        check_array(got, want, rtol=1e-6, atol=1e-9, name=f"the rewards for beta = {beta}")


@stub("kl_penalised_rewards", points=1, hint=HINT)
def test_boolean_mask_and_zeros_outside(student, rng, ragged_batch):
    """A boolean mask works the same, and every entry outside the mask is exactly zero"""
    got, want = _call(student, rng, ragged_batch, 0.5, bool_mask=True)
    check_array(got, want, rtol=1e-6, atol=1e-9)


@stub("kl_penalised_rewards", points=1, hint=HINT)
def test_one_token_completions(student):
    """Completions of a single token: that token gets the score and its own penalty"""
    mask = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    got = student.kl_penalised_rewards(torch.tensor([5.0, -1.0]), torch.tensor([[0.0, -1.0, 0.0], [0.0, 0.0, -2.0]]),
                                       torch.tensor([[0.0, -3.0, 0.0], [0.0, 0.0, -1.0]]), mask, 0.5)
    check_array(got.detach().numpy(), np.array([[0.0, 5.0 - 1.0, 0.0], [0.0, 0.0, -1.0 + 0.5]]))
