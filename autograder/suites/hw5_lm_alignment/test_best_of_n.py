"""Hidden tests of hw5's `best_of_n`: a fake generator and reward model lent by the grader, which keeps its own
record of every candidate generated (the stub's word about what it generated is never asked for)."""
import numpy as np
import torch

from autograder.suite import lend, stub

HINT = ("Repeat each prompt n times (repeat_interleave), generate once, score once, reshape the scores to (B, n), "
        "take the argmax per prompt and return those sequences, each after its own prompt.")


class _Models:
    """generate: appends L random tokens to each prompt (and records every candidate); reward: a fixed function of
    the last L tokens."""

    def __init__(self, length: int, seed: int) -> None:
        self.length, self.rng, self.candidates = length, np.random.default_rng(seed), []

    def generate(self, prompts):
        prompts = torch.as_tensor(prompts)
        new = torch.as_tensor(self.rng.integers(3, 40, size=(prompts.shape[0], self.length)), dtype=prompts.dtype)
        out = torch.cat([prompts, new], 1)
        self.candidates.append(out)
        return out

    def reward(self, sequences):
        return self.score(torch.as_tensor(sequences))

    def score(self, sequences):
        return ((sequences[:, -self.length:] * torch.arange(self.length)).sum(1).float() % 17.0)


def _run(student, prompts, n, length):
    models = _Models(length, seed=int(n * 7 + length))
    best = student.helpers.run_best_of_n(lend(models, methods=["generate", "reward"]), prompts, n)
    assert type(best) is torch.Tensor, f"return a torch tensor, got {type(best).__name__}"
    assert models.candidates, "generate was never called"
    candidates = torch.cat(models.candidates)
    return best, candidates, models.score(candidates).numpy()


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
