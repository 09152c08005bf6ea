"""Hidden tests of hw7's `binary_group_advantages`: against the per-sample formulas on the written-out 0/1 rewards."""
import numpy as np
import torch

from autograder.suite import stub
from conftest import as_array, expect_close, raised

# Tables are compared at rtol 1e-6: the docstring fixes the returned dtype (float64), not the arithmetic, and a
# group written out with torch.ones / torch.zeros (float32) and cast at the end is off by about 1e-8 of each entry;
# every mistake in a formula (population std, eps inside the root, the group mean for RLOO) is off by 1e-4 or more.
HINT = ("Write the group's G rewards out (k ones, G - k zeros): GRPO (r - mean) / (std + eps) with Bessel's std, "
        "Dr. GRPO r - mean, RLOO r - mean of the other G - 1; column 0 a pass, column 1 a fail; k = 0 or G: zeros.")


def _table(k: np.ndarray, g: int, kind: str, eps: float = 1e-4) -> np.ndarray:
    """Per-sample advantages computed from the explicit reward vectors (never the closed form)."""
    out = np.zeros((len(k), 2))
    for b, kb in enumerate(k):
        r = np.r_[np.ones(kb), np.zeros(g - kb)]
        if kind == "grpo":
            a = (r - r.mean()) / (r.std(ddof=1) + eps)
        elif kind == "dr_grpo":
            a = r - r.mean()
        else:
            a = r - (r.sum() - r) / (g - 1)
        if 0 < kb < g:
            out[b] = a[0], a[-1]
    return out


def _call(student, k, g, kind, **kw):
    got = student.binary_group_advantages(torch.as_tensor(k), g, kind, **kw)
    assert type(got) is torch.Tensor and got.dtype == torch.float64, \
        f"kind={kind!r}: return a float64 torch tensor, got {type(got).__name__} {getattr(got, 'dtype', '')}"
    return got


@stub("binary_group_advantages", points=2, hint=HINT)
def test_grpo_for_every_count(student):
    """G = 8, 5 and 2, every k from 0 to G"""
    for g in (8, 5, 2):
        k = np.arange(g + 1)
        expect_close(_call(student, k, g, "grpo"), _table(k, g, "grpo"), f"the GRPO table for G = {g}", rtol=1e-6)


@stub("binary_group_advantages", points=2, hint=HINT)
def test_dr_grpo_and_rloo(student, rng):
    """Random counts in groups of 2, 6 and 16"""
    for g in (2, 6, 16):
        k = rng.integers(1, g, size=9)
        for kind in ("dr_grpo", "rloo"):
            expect_close(_call(student, k, g, kind), _table(k, g, kind), f"the {kind} table for G = {g}", rtol=1e-6)


@stub("binary_group_advantages", points=1, hint="A group of all passes or all fails teaches nothing: both entries 0, "
                                                "for every kind (no advantage for a sample the group does not have).")
def test_all_equal_groups_are_zero(student, rng):
    """k = 0 and k = G rows are zeros for all three kinds, among other rows"""
    g = 7
    k = np.array([0, 3, 7, 1, 0, 7, 6])
    for kind in ("grpo", "dr_grpo", "rloo"):
        got = as_array(_call(student, k, g, kind), f"the {kind} table")
        assert got.shape == (7, 2), f"kind={kind!r}: shape {got.shape}, expected (7, 2): one row per group, two columns"
        assert np.all(got[[0, 2, 4, 5]] == 0), f"kind={kind!r}: rows with k = 0 or k = G must be exactly zero"
        expect_close(torch.as_tensor(got), _table(k, g, kind), f"the {kind} table", rtol=1e-6)


@stub("binary_group_advantages", points=1, hint="eps is added to the standard deviation (not the variance); "
                                                "the default kind is 'grpo'.")
def test_eps_default_kind_and_errors(student):
    """A given eps; the default kind; an unknown kind and G = 1 raise ValueError"""
    k = np.array([1, 4, 2])
    expect_close(_call(student, k, 5, "grpo", eps=0.3), _table(k, 5, "grpo", eps=0.3), "the GRPO table with eps = 0.3", rtol=1e-6)
    got = student.binary_group_advantages(torch.as_tensor(k), 5)
    expect_close(got, _table(k, 5, "grpo"), "the table with the default kind", rtol=1e-6)
    for args in ((torch.tensor([1]), 4, "ppo"), (torch.tensor([0]), 1, "grpo")):
        outcome = raised(student.binary_group_advantages, *args)
        assert outcome == "ValueError", f"group = {args[1]}, kind = {args[2]!r} should raise ValueError, got {outcome}"


@stub("binary_group_advantages", points=1, hint="RLOO's baseline leaves the sample out: the expected update is the "
                                                "true gradient p(1 - p) exactly, for every G.")
def test_rloo_is_unbiased_on_a_coin(student):
    """A one-logit policy passing with p = sigmoid(theta): E over k ~ Binomial(G, p) of the RLOO update is p(1 - p)"""
    from math import comb
    for g, p in ((4, 0.2), (8, 0.65)):
        k = np.arange(g + 1)
        table = as_array(_call(student, k, g, "rloo"), "the RLOO table")
        # Unbiasedness alone passes no baseline at all (the raw reward, 1 for a pass and 0 for a fail, is plain
        # REINFORCE): leave-one-out advantages also sum to zero over each group.
        assert table.shape == (g + 1, 2), f"the RLOO table has shape {table.shape}, expected {(g + 1, 2)}"
        assert np.allclose(k * table[:, 0] + (g - k) * table[:, 1], 0, atol=1e-6), \
            f"G = {g}: a group's leave-one-out advantages (k passes, G - k fails) should sum to zero; these do not: " \
            "is a baseline subtracted at all?"
        w = np.array([comb(g, int(x)) * p ** x * (1 - p) ** (g - x) for x in k])
        # d log pi / d theta is (1 - p) for a pass and -p for a fail; the update averages over the G samples
        update = (w * (k * table[:, 0] * (1 - p) + (g - k) * table[:, 1] * (-p)) / g).sum()
        assert np.isclose(update, p * (1 - p), rtol=1e-6), f"G = {g}: the expected RLOO update is not p(1 - p)"
