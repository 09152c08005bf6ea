"""Hidden tests say what is wrong without handing over the hidden expected value.

The hidden inputs are the same at every submission and students may resubmit, so a message that printed
the expected value (or the difference it follows from) would let a student collect the answers.
"""
from __future__ import annotations

import numpy as np
import pytest

from autograder.suite import check_array, check_scalar, check_tensor, how_far, number


def _renderings(x: float) -> set[str]:
    return {f"{x:.{d}g}" for d in range(3, 9)} | {repr(float(x)), str(x)}


@pytest.mark.parametrize("seed", range(20))
def test_no_expected_value_or_difference_in_the_message(seed):
    rng = np.random.default_rng(seed)
    want = rng.normal(size=(3, 4)) * 10.0 ** rng.integers(-3, 4)
    got = want.copy()
    i = tuple(int(rng.integers(0, n)) for n in want.shape)
    got[i] = want[i] * rng.choice([-1.0, 1.02, 3.0, 1e3, 0.0])
    with pytest.raises(AssertionError) as failure:
        check_array(got, want)
    message = str(failure.value)
    assert str(i) in message, "the message names the entry"
    leaked = [r for r in _renderings(want[i]) | _renderings(got[i] - want[i]) | _renderings(want[i] - got[i])
              if len(r.strip("-0.")) >= 3 and r in message.replace(number(got[i]), "")]  # its own value may show
    assert not leaked, f"{message!r} holds {leaked}"
    assert "np." not in message and "array(" not in message, "plain numbers only"
    with pytest.raises(AssertionError) as failure:
        check_scalar(float(got[i]), float(want[i]))
    assert not [r for r in _renderings(want[i]) if len(r.strip("-0.")) >= 3 and r in str(failure.value)]


def test_the_message_says_how_far_to_an_order_of_magnitude():
    assert how_far(-2.0, 2.0) == "it has the wrong sign"
    assert how_far(20.0, 2.0) == "it is about 10^1 times too large"
    assert how_far(1.0, 2.0) == "it is about twice too small"
    assert how_far(2.002, 2.0) == "it is off by about 10^-3 of its size"
    assert how_far(0.0, 2.0) == "it is zero, and should not be"
    assert how_far(1.0, 0.0) == "it should be zero"
    assert number(np.float64(0.25)) == "0.25" and number(np.int64(312)) == "312" and number(np.bool_(True)) == "True"


def test_tensors_and_scalars_use_the_same_messages():
    import torch

    with pytest.raises(AssertionError, match=r"at index \(1,\) it is -3: it has the wrong sign"):
        check_tensor(torch.tensor([1.0, -3.0]), torch.tensor([1.0, 3.0]))
    with pytest.raises(AssertionError, match=r"the loss is 0.5: it is about 10\^1 times too small"):
        check_scalar(0.5, 5.25, name="the loss")
