"""Hidden tests of hw6's `group_advantages` (GRPO and Dr. GRPO)."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array, expect_close

HINT = ("Statistics over each ROW (dim=1, the group): (r - mean) / (std + eps), std = rewards.std(dim=1, keepdim=True) "
        "(Bessel's correction); scale=False returns r - mean only.")


def _grpo(r, eps=1e-4):
    return (r - r.mean(1, keepdims=True)) / (r.std(1, ddof=1, keepdims=True) + eps)


@stub("group_advantages", points=2, hint=HINT)
def test_grpo_by_hand(student, rng, groups):
    """Five groups of six rewards with different means and spreads"""
    r = groups(rng)
    expect_close(student.group_advantages(torch.as_tensor(r)), _grpo(r), "the GRPO advantages")


@stub("group_advantages", points=1, hint="scale=False (Dr. GRPO): r minus the mean of its row, no division.")
def test_dr_grpo_by_hand(student, rng, groups):
    """scale=False: rewards minus their group's mean"""
    r = groups(rng, b=4, g=5)
    expect_close(student.group_advantages(torch.as_tensor(r), scale=False), r - r.mean(1, keepdims=True),
                 "the Dr. GRPO advantages (scale=False)")


@stub("group_advantages", points=2, hint=HINT)
def test_equal_groups_and_the_group_axis(student, rng, groups):
    """Seven groups of three (some with all rewards equal): zeros there, the closed form elsewhere"""
    r = groups(rng, b=7, g=3)
    constant = rng.permutation(7)[:3]
    r[constant] = rng.normal(size=(3, 1)) * np.ones((1, 3))
    for scale in (True, False):
        got = as_array(student.group_advantages(torch.as_tensor(r), scale=scale), "the advantages")
        assert got.shape == (7, 3), f"the advantages have shape {got.shape}, expected (7, 3): one per reward"
        assert np.allclose(got[constant], 0.0, atol=1e-9), \
            f"scale={scale}: a group whose rewards are all equal must get zero advantages (statistics over dim=1?)"
        want = _grpo(r) if scale else r - r.mean(1, keepdims=True)
        expect_close(torch.as_tensor(got), want, f"the advantages with scale={scale}")


@stub("group_advantages", points=1, hint="Divide by (std + eps), with eps added to the std, not to the variance.")
def test_eps_dtype_and_input_left_alone(student, rng):
    """A group with a tiny spread (eps matters), a given eps, float32 in gives float32 out, the input is not modified"""
    r = np.array([[0.0, 1e-4, 2e-4, 3e-4], [1.0, 2.0, 4.0, 8.0]]) + rng.normal(size=(2, 1))
    x = torch.as_tensor(r)
    out, args, _ = student.helpers.call_and_inputs("group_advantages", [x])
    expect_close(out, _grpo(r), "the advantages of a group with a tiny spread (default eps = 1e-4)", rtol=1e-5)
    expect_close(args[0], r, "the rewards after the call (modified in place?)")
    expect_close(student.group_advantages(x, eps=0.5), _grpo(r, eps=0.5), "the advantages with eps = 0.5", rtol=1e-5)
    out = student.group_advantages(x.float())
    assert type(out) is torch.Tensor and out.dtype == torch.float32, "float32 rewards should give float32 advantages"
    for scale in (True, False):
        out = student.group_advantages(x, scale=scale)
        assert type(out) is torch.Tensor and out.dtype == torch.float64, \
            f"float64 rewards should give float64 advantages (scale={scale}): keep the input's dtype"
