"""Hidden tests of hw5's `best_of_n`: fake generators and reward models defined inside the sandbox."""
import numpy as np
import torch

from autograder.suite import stub

HINT = ("Repeat each prompt n times (repeat_interleave), generate once, score once, reshape the scores to (B, n), "
        "take the argmax per prompt and return those sequences, each after its own prompt.")
# generate: appends L random tokens and records every candidate; reward: a fixed random weight per token id.
RUN = ("(lambda log: (best_of_n(lambda p: log.append(torch.cat([p, torch.randint(3, 40, (p.shape[0], L))], 1)) or log[-1], "
       "lambda s: (s[:, -L:] * torch.arange(L)).sum(1).float() % 17.0, prompts, n), log))([])")


def _run(student, prompts, n, length):
    out = student.eval(f"(torch.manual_seed(seed), {RUN})[1]", prompts=prompts, n=n, L=length, seed=int(n * 7 + length))
    best, log = out
    assert type(best) is torch.Tensor, f"return a torch tensor, got {type(best).__name__}"
    candidates = torch.cat(list(log))
    scores = ((candidates[:, -length:] * torch.arange(length)).sum(1).float() % 17.0).numpy()
    return best, candidates, scores


def _check(best, candidates, scores, prompts, n):
    b, p = prompts.shape
    assert best.dim() == 2 and best.shape[0] == b, \
        f"expected one sequence per prompt ({b} rows), got shape {tuple(best.shape)}"
    assert len(candidates) == b * n, f"generate should produce B * n = {b * n} candidates in all, got {len(candidates)}"
    for i in range(b):
        own = (candidates[:, :p] == prompts[i]).all(1).numpy()
        assert own.sum() == n, f"prompt {i} should get exactly n = {n} candidates, got {own.sum()}"
        assert torch.equal(best[i, :p], prompts[i]), f"row {i} does not continue its own prompt"
        match = (candidates == best[i]).all(1).numpy() & own
        assert match.any(), f"row {i} is not one of its prompt's candidates"
        assert np.isclose(scores[match].max(), scores[own].max()), \
            f"row {i} has reward {scores[match].max():.1f}, but its best candidate had {scores[own].max():.1f}"


@stub("best_of_n", points=3, hint=HINT)
def test_picks_the_argmax(student, rng):
    """Five distinct prompts, n = 6: each row is its own prompt's highest-scoring candidate"""
    prompts = torch.as_tensor(np.c_[np.ones(5, dtype=np.int64), np.arange(5) + 50, rng.integers(50, 60, size=5)])
    best, candidates, scores = _run(student, prompts, 6, 5)
    _check(best, candidates, scores, prompts, 6)


@stub("best_of_n", points=1, hint=HINT)
def test_n_one_and_large_n(student):
    """n = 1 returns the single sample; n = 64 on two prompts still picks each prompt's best"""
    prompts = torch.tensor([[1, 50], [1, 51]])
    for n in (1, 64):
        best, candidates, scores = _run(student, prompts, n, 4)
        _check(best, candidates, scores, prompts, n)
