"""Hidden tests of hw7's `rft_select`: against a brute-force filter written from the contract."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array

HINT = ("Group by consecutive blocks of `group` rows; in each, walk the rows in order and keep a passing row unless an "
        "identical row of the same group was kept or max_per_prompt rows are already kept.")


def _trusted(tokens: np.ndarray, correct: np.ndarray, group: int, cap: int) -> list[int]:
    out = []
    for g in range(len(tokens) // group):
        kept = []
        for i in range(g * group, (g + 1) * group):
            if correct[i] > 0.5 and len(kept) < cap and all(tuple(tokens[i]) != tuple(tokens[j]) for j in kept):
                kept.append(i)
        out += kept
    return out


def _case(rng, n_groups=6, group=5, t=4, vocab=3):
    tokens = rng.integers(0, vocab, size=(n_groups * group, t))       # few distinct rows: duplicates are common
    # The verdicts of a checker: a function of the row, so identical rows pass or fail together. (Verdicts drawn
    # row by row gave identical rows different verdicts, on which skipping every row seen before, passing or not,
    # differs from the docstring's rule; no checker does that, and the two then agree.)
    passes = rng.random(vocab ** t) < 0.6
    # With 81 kinds of rows many draws had no passing duplicate at all (a filter without the duplicate check scored
    # 3/4 on two of four draws tried): group 0 opens with a passing row twice, and group 1 opens with it again.
    tokens[1] = tokens[group] = tokens[0]
    code = tokens @ vocab ** np.arange(t)
    passes[code[0]] = True
    correct = passes[code].astype(float)
    return tokens, correct


def _indices(got, name="the kept indices"):
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    assert got.dtype == torch.int64, f"{name} should be int64, got {got.dtype}"
    assert got.dim() == 1, f"{name} should be 1-D, got shape {tuple(got.shape)}"
    return got.tolist()


@stub("rft_select", points=2, hint=HINT)
def test_against_a_brute_force_filter(student, rng):
    """Six groups of five with many duplicate rows, caps 1, 2 and 5"""
    tokens, correct = _case(rng)
    for cap in (1, 2, 5):
        got = _indices(student.rft_select(torch.as_tensor(tokens), torch.as_tensor(correct), 5, cap))
        want = _trusted(tokens, correct, 5, cap)
        assert len(got) == len(want), f"max_per_prompt = {cap}: kept {len(got)} rows, expected {len(want)}"
        assert got == want, f"max_per_prompt = {cap}: the right number of rows but not the right ones (or not in order)"


@stub("rft_select", points=1, hint="Duplicates are compared within a group only: the same answer to another prompt "
                                   "is a different sample. Compare whole rows (all T tokens).")
def test_duplicates_are_per_group_and_whole_rows(student):
    """The same row in two groups is kept twice; rows equal except in their last token are both kept"""
    tokens = torch.tensor([[1, 2, 3], [1, 2, 3], [1, 2, 4], [1, 2, 3], [1, 2, 3], [9, 9, 9]])
    got = _indices(student.rft_select(tokens, torch.ones(6), 3, 3))
    assert got == [0, 2, 3, 5], "groups [0, 1, 2] and [3, 4, 5]: keep 0 and 2 (1 repeats 0), 3 and 5 (4 repeats 3)"


@stub("rft_select", points=1, hint="`correct` may be float (1.0 / 0.0) or bool; an all-fail batch gives an empty int64 tensor.")
def test_bool_verdicts_and_nothing_passed(student, rng):
    """Bool verdicts give the same rows as floats; nothing passed gives an empty int64 tensor; input left alone"""
    tokens, correct = _case(rng, n_groups=4, group=4)
    t, c = torch.as_tensor(tokens), torch.as_tensor(correct)
    want = _trusted(tokens, correct, 4, 2)
    assert _indices(student.rft_select(t, c.bool(), 4, 2)) == want, "bool verdicts should give the rows float verdicts give"
    assert _indices(student.rft_select(t, torch.zeros(16), 4, 2)) == [], "nothing passed: nothing kept"
    out, args, _ = student.helpers.call_and_inputs("rft_select", [t, c, 4, 2])
    assert _indices(out) == want, "float verdicts: the wrong rows"
    assert np.array_equal(as_array(args[0], "tokens"), tokens) and np.array_equal(as_array(args[1], "correct"), correct), \
        "rft_select modified its inputs"
