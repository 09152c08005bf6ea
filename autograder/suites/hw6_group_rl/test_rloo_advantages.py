"""Hidden tests of hw6's `rloo_advantages`."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array, expect_close

HINT = "A_i = r_i - (sum of the row - r_i) / (G - 1): the baseline is the mean of the OTHER rewards of the same row."


def _rloo(r):
    g = r.shape[1]
    return r - (r.sum(1, keepdims=True) - r) / (g - 1)


@stub("rloo_advantages", points=2, hint=HINT)
def test_by_hand(student, rng, groups):
    """Five groups of six rewards"""
    r = groups(rng)
    got = student.rloo_advantages(torch.as_tensor(r))
    assert type(got) is not torch.Tensor or got.dtype == torch.float64, \
        f"float64 rewards should give float64 advantages, got {got.dtype}: keep the input's dtype"
    expect_close(got, _rloo(r), "the leave-one-out advantages")


@stub("rloo_advantages", points=1, hint=HINT)
def test_pairs_and_equal_groups(student, rng, groups):
    """G = 2 gives r_0 - r_1 and r_1 - r_0; groups of equal rewards (B != G) give zeros"""
    r = groups(rng, b=4, g=2)
    expect_close(student.rloo_advantages(torch.as_tensor(r)), np.stack([r[:, 0] - r[:, 1], r[:, 1] - r[:, 0]], 1),
                 "the advantages of groups of two")
    r = groups(rng, b=6, g=4)
    r[[1, 4]] = rng.normal(size=(2, 1)) * np.ones((1, 4))
    got = as_array(student.rloo_advantages(torch.as_tensor(r)), "the advantages")
    assert got.shape == (6, 4), f"the advantages have shape {got.shape}, expected (6, 4)"
    assert np.allclose(got[[1, 4]], 0.0, atol=1e-9), "a group of equal rewards must get zero advantages (the row axis?)"
    expect_close(torch.as_tensor(got), _rloo(r), "the advantages")


@stub("rloo_advantages", points=2, hint="The baseline must not depend on the completion it is subtracted from: "
                                       "leave r_i out of its own baseline.")
def test_unbiased_by_enumeration(student, rng):
    """The expected policy gradient over all groups of a 3-answer softmax policy equals the true gradient"""
    k, g = 3, 3
    theta, r = rng.normal(size=k), rng.uniform(-1, 1, size=k)
    p = np.exp(theta - theta.max())
    p /= p.sum()
    all_groups = np.array(np.meshgrid(*[np.arange(k)] * g, indexing="ij")).reshape(g, -1).T     # (K^G, G)
    adv = as_array(student.rloo_advantages(torch.as_tensor(r[all_groups])), "the advantages")
    assert adv.shape == all_groups.shape, f"the advantages have shape {adv.shape}, expected {all_groups.shape}"
    # Unbiasedness alone passes no baseline at all (plain REINFORCE is unbiased too): leave-one-out advantages
    # also sum to zero over each group.
    assert np.allclose(adv.sum(axis=1), 0, atol=1e-9), \
        "a group's leave-one-out advantages should sum to zero; these do not: is a baseline subtracted at all?"
    weight = p[all_groups].prod(axis=1)
    score = np.eye(k)[all_groups] - p                                                         # grad log pi, (K^G, G, K)
    expected = (weight[:, None] * (adv[..., None] * score).mean(axis=1)).sum(axis=0)
    true = p * (r - p @ r)
    cos = expected @ true / (np.linalg.norm(expected) * np.linalg.norm(true) + 1e-300)
    assert cos > 0.999, "the expected gradient points away from the true gradient (sign or baseline wrong)"
    assert np.allclose(expected, true, rtol=1e-6, atol=1e-12), \
        "the expected gradient has the right direction but the wrong scale: a biased baseline (the group mean " \
        "includes r_i and shrinks it by (G - 1) / G)"
    # Unbiased and zero-sum still passes other baselines (the next reward of the group, say): the values too.
    expect_close(torch.as_tensor(adv), _rloo(r[all_groups]),
                 "the advantages of every group (unbiased, but is the baseline the mean of ALL the other rewards?)")
