"""Hidden tests of hw7's `verifier_reward`: judged against the grader's own checker on sequences built here."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import DIGIT0, EOS, SEMI, as_array, number_tokens, rows, trusted_check

HINT = ("Read a and b from the prompt (tokens 1-3 and 5-7, digit d is token 3 + d); the answer is what comes before the "
        "FIRST <eos> (2) after the 9 prompt tokens: 1 to 4 digit tokens, no leading zero unless it is the only digit.")


def _check_judged(student, tokens, what):
    out = student.verifier_reward(tokens)
    assert isinstance(out, tuple) and len(out) == 2, "return a tuple (format_ok, correct)"
    fmt, cor = out
    for x, name in ((fmt, "format_ok"), (cor, "correct")):
        assert type(x) is torch.Tensor and x.dtype == torch.float32, f"{name} should be a float32 torch tensor"
        assert tuple(x.shape) == (len(tokens),), f"{name} has shape {tuple(x.shape)}, expected ({len(tokens)},): one per row"
    want_f, want_c = trusted_check(tokens)
    got_f, got_c = as_array(fmt, "format_ok"), as_array(cor, "correct")
    bad = np.flatnonzero(got_f != want_f)
    assert not len(bad), f"{what}: format_ok is wrong on {len(bad)} of {len(tokens)} rows, e.g. a row whose answer part " \
                         f"is {describe_completion(tokens[bad[0]])}"
    bad = np.flatnonzero(got_c != want_c)
    assert not len(bad), f"{what}: correct is wrong on {len(bad)} of {len(tokens)} rows, e.g. a row whose answer part " \
                         f"is {describe_completion(tokens[bad[0]])}"


def describe_completion(row) -> str:
    names = {0: "<pad>", 1: "<bos>", 2: "<eos>", 13: "+", 14: "=", 15: ";"}
    return "'" + " ".join(names.get(int(t), str(int(t) - DIGIT0)) for t in row[9:]) + "'"


@stub("verifier_reward", points=2, hint=HINT)
def test_random_answers_of_every_kind(student, rng, random_answers):
    """Right, wrong, unstopped, leading-zero, garbage-after-<eos> and random completions"""
    _check_judged(student, random_answers(rng, n=60), "60 random completions")


@stub("verifier_reward", points=2, hint=HINT)
def test_sums_are_read_from_each_prompt(student, rng):
    """Every row gives the right sum of a different problem; the same answers under shuffled prompts are mostly wrong"""
    a, b = rng.integers(0, 1000, size=30), rng.integers(0, 1000, size=30)
    good = rows([(int(x), int(y), number_tokens(int(x + y)) + [EOS]) for x, y in zip(a, b)])
    _check_judged(student, good, "30 right answers")
    perm = np.roll(np.arange(30), 7)
    swapped = rows([(int(a[j]), int(b[j]), number_tokens(int(a[i] + b[i])) + [EOS]) for i, j in enumerate(perm)])
    _check_judged(student, swapped, "30 answers to other prompts")


@stub("verifier_reward", points=2, hint="Leading zeros: '0' alone is a well-formed answer (0 + 0), '05' is not; "
                                        "an answer has at most four digits; an empty answer ('<eos>' first) is ill-formed.")
def test_edge_cases_of_the_format(student):
    """0 + 0, leading zeros, five digits, empty answer, a non-digit before <eos>, no <eos> at all, 999 + 999"""
    items = [(0, 0, [DIGIT0, EOS]), (0, 0, [DIGIT0, DIGIT0, EOS]), (2, 3, [DIGIT0, DIGIT0 + 5, EOS]),
             (999, 999, number_tokens(1998) + [EOS]), (999, 999, number_tokens(1998)),
             (500, 500, number_tokens(1000) + [EOS]), (500, 500, [DIGIT0] + number_tokens(1000) + [EOS]),
             (500, 500, number_tokens(10000) + [EOS]), (999, 1, number_tokens(10000) + [EOS]),
             (12, 34, [EOS]), (12, 34, number_tokens(46) + [SEMI, EOS]), (12, 34, number_tokens(46) + [EOS, SEMI, 5]),
             (12, 34, number_tokens(46) + [0, EOS]), (12, 34, number_tokens(46) + [13, EOS]),
             (1, 2, number_tokens(3) + [EOS, EOS]), (10, 5, number_tokens(15) + [EOS])]
    _check_judged(student, rows(items, width=16), "hand-made edge cases")


@stub("verifier_reward", points=1, hint="The completion starts right after the 9 prompt tokens; any row length T > 9.")
def test_other_widths_and_input_left_alone(student, rng, random_answers):
    """Rows of 11 and of 24 tokens; the input tensor is not modified"""
    for width in (11, 24):
        x = random_answers(rng, n=20, width=width)
        _check_judged(student, x, f"rows of {width} tokens")
        _, args, _ = student.helpers.call_and_inputs("verifier_reward", [x])
        assert np.array_equal(as_array(args[0], "the tokens"), x.numpy()), "verifier_reward modified its input"
