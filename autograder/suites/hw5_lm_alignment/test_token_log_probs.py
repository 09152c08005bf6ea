"""Hidden tests of hw5's `token_log_probs` and `sequence_log_prob`."""
import numpy as np
import torch

from autograder.suite import check_array, check_tensor, stub


def direct_token_log_probs(logits: torch.Tensor, tokens: torch.Tensor, mask: torch.Tensor) -> np.ndarray:
    """The definition, one entry at a time (no vectorisation to share a bug with)."""
    b, t, _ = logits.shape
    out = np.zeros((b, t))
    for i in range(b):
        for j in range(1, t):
            if mask[i, j]:
                out[i, j] = float(torch.log_softmax(logits[i, j - 1], -1)[tokens[i, j]])
    return out


HINT = ("out[b, t] = log_softmax(logits[b, t - 1])[tokens[b, t]] where mask[b, t] is 1, exactly 0 elsewhere "
        "(column 0 included); use log_softmax and gather, and zero every entry outside the mask.")
SEQ_HINT = "Sum token_log_probs over the time axis: one number per sequence, shape (B,)."


def _as_np(x, name="the result"):
    assert type(x) is torch.Tensor, f"{name} should be a torch tensor, got {type(x).__name__}"
    return x.detach().numpy()


@stub("token_log_probs", points=2, hint=HINT)
def test_matches_direct_gather(student, rng, ragged_batch):
    """Random logits and ragged masks (one with mask[:, 0] = 1, treated as 0): each entry is the log-softmax picked out directly"""
    logits, tokens, mask = ragged_batch(rng)
    mask[1, 0] = 1.0                                       # column 0 predicts nothing, whatever the mask says
    got = _as_np(student.token_log_probs(logits, tokens, mask))
    want = direct_token_log_probs(logits, tokens, mask)
    assert got.shape != want.shape or got[1, 0] == 0, \
        "out[:, 0] must be exactly 0 even where mask[:, 0] is 1: no logits predict the first token (rolled logits?)"
    check_array(got, want, rtol=1e-5, atol=1e-6)


@stub("token_log_probs", points=2, hint=HINT)
def test_padding_changes_nothing(student, rng, ragged_batch):
    """Garbage logits and tokens on masked positions (prompt and padding) leave the result unchanged"""
    logits, tokens, mask = ragged_batch(rng)
    base = _as_np(student.token_log_probs(logits, tokens, mask))
    check_array(base, direct_token_log_probs(logits, tokens, mask), rtol=1e-5, atol=1e-6,
                name="the result before garbage is put on the masked positions")
    junk_logits, junk_tokens = logits.clone(), tokens.clone()
    predicts_masked = torch.cat([mask[:, 1:], torch.zeros(len(mask), 1, dtype=mask.dtype)], 1) == 0
    junk_logits[predicts_masked] = torch.as_tensor(rng.normal(scale=1e4, size=(int(predicts_masked.sum()), logits.shape[-1])))
    junk_tokens[mask == 0] = torch.as_tensor(rng.integers(0, logits.shape[-1], size=int((mask == 0).sum())))
    check_array(_as_np(student.token_log_probs(junk_logits, junk_tokens, mask)), base, rtol=1e-6, atol=1e-8,
                name="the result with garbage on masked positions")
    assert np.all(base[mask.numpy() == 0] == 0), "entries outside the mask must be exactly 0"


@stub("token_log_probs", points=1, hint=HINT)
def test_bool_mask_and_extreme_logits(student, rng, ragged_batch):
    """A boolean mask, and logits of size 1e3 (log(softmax) underflows to -inf; log_softmax does not)"""
    logits, tokens, mask = ragged_batch(rng, scale=1e3)
    got = student.token_log_probs(logits, tokens, mask.bool())
    check_array(_as_np(got), direct_token_log_probs(logits, tokens, mask), rtol=1e-5, atol=1e-6)


@stub("token_log_probs", points=1, hint="Keep everything in torch so gradients flow back to the logits.")
def test_gradient_flows_to_logits(student, reference, rng, ragged_batch):
    """The gradient of the summed result with respect to the logits matches the definition's"""
    logits, tokens, mask = ragged_batch(rng, b=3, t=6, v=5)
    ones = torch.ones(tokens.shape, dtype=logits.dtype)        # d (sum of the result) / d logits
    got, want = (ns.helpers.grad("token_log_probs", [logits, tokens, mask], wrt=[0], grad_outputs=ones)[0]
                 for ns in (student, reference))
    check_tensor(got, want, rtol=1e-5, atol=1e-7, name="the gradient")


@stub("sequence_log_prob", points=2, hint=SEQ_HINT)
def test_sequence_log_prob_is_masked_sum(student, rng, ragged_batch):
    """One number per sequence: the masked sum of the direct token log-probabilities"""
    logits, tokens, mask = ragged_batch(rng, b=5)
    mask[2, 0] = 1.0                                       # treated as 0: the first token has no prediction
    got = student.sequence_log_prob(logits, tokens, mask)
    check_array(_as_np(got), direct_token_log_probs(logits, tokens, mask).sum(1), rtol=1e-5, atol=1e-6)


@stub("sequence_log_prob", points=1, hint=SEQ_HINT + " Keep the graph to the logits (with logits that need gradients, "
      "the grader runs your own token_log_probs inside it).")
def test_sequence_log_prob_ignores_padding(student, reference, rng, ragged_batch):
    """Appending padded columns (with any logits) to every sequence changes nothing, and the result is the masked sum"""
    logits, tokens, mask = ragged_batch(rng, b=3)
    base = _as_np(student.sequence_log_prob(logits, tokens, mask))
    check_array(base, direct_token_log_probs(logits, tokens, mask).sum(1), rtol=1e-5, atol=1e-6,
                name="the log-probabilities before padding (the masked sum of the completion's token log-probabilities)")
    longer = student.sequence_log_prob(torch.cat([logits, torch.as_tensor(rng.normal(scale=50, size=(3, 4, logits.shape[-1])))], 1),
                                       torch.cat([tokens, torch.zeros(3, 4, dtype=tokens.dtype)], 1),
                                       torch.cat([mask, torch.zeros(3, 4, dtype=mask.dtype)], 1))
    check_array(_as_np(longer), base, rtol=1e-6, atol=1e-8, name="the result with 4 padded columns appended")
    ones = torch.ones(len(tokens), dtype=logits.dtype)      # d (sum over sequences) / d logits
    got, want = (ns.helpers.grad("sequence_log_prob", [logits, tokens, mask], wrt=[0], grad_outputs=ones)[0]
                 for ns in (student, reference))
    assert got is not None, "no gradient reaches the logits: keep the sum in torch, without detach or numpy"
    check_tensor(got, want, rtol=1e-5, atol=1e-7, name="d sum(log pi(completion)) / d logits")
