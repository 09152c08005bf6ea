"""Hidden tests of hw7b's `position_swap`: a position-biased judge lent by the grader, which records every question;
the combined probability and the consistency are recomputed here from the judge's own answers."""
import numpy as np
import torch

from autograder.suite import lend, stub
from conftest import as_float_tensor, same_rows

HINT = ("p = (judge(a, b) + 1 - judge(b, a)) / 2; consistent = (judge(a, b) > 0.5 and judge(b, a) < 0.5) or "
        "(judge(a, b) < 0.5 and judge(b, a) > 0.5), an answer of exactly 0.5 picking neither.")


class _Judge:
    """sigmoid(f(x) - f(y) + offset), f a hidden integer table summed over tokens; with offset 1 the pairs with
    f(x) - f(y) = -1 get exactly 0.5. Records every call."""

    def __init__(self, seed: int, offset: float) -> None:
        self.table = torch.as_tensor(np.random.default_rng(seed).integers(-1, 2, size=20), dtype=torch.float64)
        self.offset, self.calls = offset, []

    def answer(self, x, y):
        return torch.sigmoid(self.table[x.long()].sum(1) - self.table[y.long()].sum(1) + self.offset)

    def ask(self, x, y):
        x, y = torch.as_tensor(x), torch.as_tensor(y)
        self.calls.append((x.clone(), y.clone()))
        return self.answer(x, y)


def _run(student, rng, offset):
    judge = _Judge(int(rng.integers(0, 10_000)), offset)
    a, b = (torch.as_tensor(rng.integers(0, 20, size=(60, 3))) for _ in range(2))
    out = student.helpers.run_position_swap(lend(judge, methods=["ask"]), a, b)
    assert isinstance(out, tuple) and len(out) == 2, "position_swap should return a tuple (p, consistent)"
    assert len(judge.calls) == 2, f"the judge should be asked twice (both orders), it was asked {len(judge.calls)} times"
    orders = sorted(judge.calls, key=lambda c: not torch.equal(c[0], a))
    same_rows(orders[0][0], a, "the first call's first argument (judge(a, b))")
    same_rows(orders[0][1], b, "the first call's second argument (judge(a, b))")
    same_rows(orders[1][0], b, "the swapped call's first argument (judge(b, a))")
    same_rows(orders[1][1], a, "the swapped call's second argument (judge(b, a))")
    p_ab, p_ba = judge.answer(a, b).numpy(), judge.answer(b, a).numpy()
    return out, p_ab, p_ba


@stub("position_swap", points=2, hint=HINT)
def test_averaged_probability(student, rng):
    """A judge with a position offset of 1.3: p is the average of J(a, b) and 1 - J(b, a)"""
    (p, _), p_ab, p_ba = _run(student, rng, 1.3)
    got = as_float_tensor(p, "p", (60,))
    want = (p_ab + 1 - p_ba) / 2
    wrong = ~np.isclose(got, want, rtol=1e-9, atol=1e-12)
    assert not wrong.any(), (f"p is wrong on {int(wrong.sum())} of 60 pairs (first: pair {int(np.flatnonzero(wrong)[0])}); "
                             "it should be (J(a, b) + 1 - J(b, a)) / 2")


@stub("position_swap", points=2, hint=HINT)
def test_consistent_verdicts_with_exact_ties(student, rng):
    """Offsets 1 and -1 on integer scores: some answers are exactly 0.5 (no pick), in either order; consistent where
    both orders pick the same response"""
    for offset in (1.0, -1.0):
        _check_consistency(student, rng, offset)


def _check_consistency(student, rng, offset):
    (p, consistent), p_ab, p_ba = _run(student, rng, offset)
    assert type(consistent) is torch.Tensor and consistent.dtype == torch.bool and tuple(consistent.shape) == (60,), \
        "consistent should be an (N,) torch bool tensor"
    want = ((p_ab > 0.5) & (p_ba < 0.5)) | ((p_ab < 0.5) & (p_ba > 0.5))
    got = consistent.numpy()
    wrong = np.flatnonzero(got != want)
    if len(wrong):
        i = int(wrong[0])
        tie = " (one of its answers is exactly 0.5, which picks neither)" if 0.5 in (p_ab[i], p_ba[i]) else ""
        raise AssertionError(f"consistent is wrong on {len(wrong)} of 60 pairs, e.g. pair {i}{tie}")
    as_float_tensor(p, "p", (60,))
    assert np.allclose(p.double().numpy(), (p_ab + 1 - p_ba) / 2, rtol=1e-9, atol=1e-12), "p is wrong"
