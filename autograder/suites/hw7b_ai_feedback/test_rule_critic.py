"""Hidden tests of hw7b's `rule_critic`: rules lent by the grader (integer scores from hidden tables, so that ties are
common), the verdicts recomputed here from the rules themselves."""
import numpy as np
import torch

from autograder.suite import lend, stub
from conftest import as_float_tensor

HINT = ("vote_k = sign(rule_k(a) - rule_k(b)) (0 on a tie) for each pair; "
        "p = 0.5 + 0.5 * sum_k w_k vote_k / sum_k w_k, weights all 1 when None.")


class _Rulebook:
    """Four rules, each the sum over a review's tokens of a hidden table of small integers."""

    def __init__(self, seed: int) -> None:
        self.tables = torch.as_tensor(np.random.default_rng(seed).integers(-1, 2, size=(4, 20)), dtype=torch.float64)

    def score(self, k, tokens):
        return self.tables[k][torch.as_tensor(tokens).long()].sum(1)

    def r0(self, tokens):
        return self.score(0, tokens)

    def r1(self, tokens):
        return self.score(1, tokens)

    def r2(self, tokens):
        return self.score(2, tokens)

    def r3(self, tokens):
        return self.score(3, tokens)


def _pairs(rng, n=40, t=4):
    return (torch.as_tensor(rng.integers(0, 20, size=(n, t))), torch.as_tensor(rng.integers(0, 20, size=(n, t))))


def _want(book, names, a, b, weights):
    w = np.ones(len(names)) if weights is None else np.asarray(weights, float)
    votes = np.stack([np.sign(book.score(int(n[1]), a).numpy() - book.score(int(n[1]), b).numpy()) for n in names], 1)
    return 0.5 + 0.5 * votes @ w / w.sum()


def _check(student, rng, names, weights=None):
    book = _Rulebook(int(rng.integers(0, 10_000)))
    a, b = _pairs(rng)
    got = student.helpers.run_rule_critic(lend(book, methods=["r0", "r1", "r2", "r3"]), names, a, b, weights)
    got = as_float_tensor(got, "the critic's verdicts", (len(a),))
    want = _want(book, names, a, b, weights)
    # rtol 1e-6, atol 1e-7: weights taken as torch.tensor(weights) are float32, about 3e-8 off each (the docstring
    # asks for a float64 result, not for float64 weights); a wrong vote or normalisation is off by 1 / (2 sum w) or more
    wrong = ~np.isclose(got, want, rtol=1e-6, atol=1e-7)
    if wrong.any():
        i = int(np.flatnonzero(wrong)[0])
        side = "a" if want[i] > 0.5 else "b" if want[i] < 0.5 else "neither"
        raise AssertionError(f"pair {i}: the verdict is {got[i]:.4g}, and the weighted votes favour {side} "
                             f"({int(wrong.sum())} of {len(a)} pairs wrong)")


@stub("rule_critic", points=2, hint=HINT)
def test_four_rules_equal_weights(student, rng):
    """Four integer-valued rules, weights None: the share of the votes, ties voting 0"""
    _check(student, rng, ["r0", "r1", "r2", "r3"])


@stub("rule_critic", points=2, hint=HINT)
def test_weighted_votes(student, rng):
    """Three rules with random weights, one of them 0: the weighted share"""
    w = [float(rng.uniform(0.5, 3.0)), 0.0, float(rng.uniform(0.5, 3.0))]
    _check(student, rng, ["r2", "r0", "r3"], weights=w)


@stub("rule_critic", points=1, hint=HINT)
def test_one_rule(student, rng):
    """One rule: 1 where a scores higher, 0 where lower, 0.5 on a tie"""
    _check(student, rng, ["r1"])
