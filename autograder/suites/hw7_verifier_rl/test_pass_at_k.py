"""Hidden tests of hw7's `pass_at_k`: against exact rational arithmetic and simulation."""
from fractions import Fraction
from math import comb

import numpy as np

from autograder.suite import stub
from conftest import raised

HINT = "1 - C(n - c, k) / C(n, k) = 1 - prod_{i = n - c + 1}^{n} (1 - k / i); exactly 1 when n - c < k."


def _exact(n, c, k):
    return float(1 - Fraction(comb(n - c, k), comb(n, k)))


def _array(got, shape, name="pass_at_k"):
    assert type(got) is np.ndarray, f"{name} should return a numpy array, got {type(got).__name__}"
    assert got.dtype == np.float64, f"{name} should return float64, got {got.dtype}"
    assert got.shape == shape, f"{name} returned shape {got.shape}, expected {shape}"
    assert np.isfinite(got).all(), f"{name} returned NaN or inf (overflowing binomial coefficients?)"
    return got


@stub("pass_at_k", points=2, hint=HINT)
def test_exact_values_on_arrays(student, rng):
    """Forty problems with n = 50 samples and random c, for k = 1, 3, 10, 50 (exact rationals)"""
    c = rng.integers(0, 51, size=40)
    c[:3] = [0, 50, 49]
    for k in (1, 3, 10, 50):
        got = _array(student.pass_at_k(np.full(40, 50), c, k), (40,))
        want = np.array([_exact(50, int(ci), k) for ci in c])
        wrong = ~np.isclose(got, want, rtol=1e-9, atol=1e-12)
        assert not wrong.any(), f"k = {k}: {int(wrong.sum())} of 40 estimates are wrong, e.g. n = 50, c = {int(c[wrong][0])}"


@stub("pass_at_k", points=1, hint="k = 1 is the fraction c / n; c = 0 gives 0; n - c < k gives exactly 1.")
def test_limits_and_scalars(student, rng):
    """k = 1 is c/n; c = 0 gives 0; n - c < k gives 1; scalars give 0-dim arrays; a 2-D shape is kept"""
    n, c = rng.integers(5, 40, size=(3, 4)), None
    c = (rng.random((3, 4)) * n).astype(int)
    got = _array(student.pass_at_k(n, c, 1), (3, 4))
    assert np.allclose(got, c / n, rtol=1e-12), "k = 1: the estimate is c / n"
    got = _array(student.pass_at_k(17, 0, 5), ())
    assert got == 0.0, "no correct sample: the estimate is 0"
    got = _array(student.pass_at_k(17, 13, 5), ())
    assert got == 1.0, "n - c = 4 < k = 5: every 5-subset holds a correct sample, the estimate is exactly 1"
    got = _array(student.pass_at_k(17, 12, 5), ())
    assert np.isclose(got, _exact(17, 12, 5), rtol=1e-12), "n - c = k: one subset in C(17, 5) has no correct sample"


@stub("pass_at_k", points=2, hint="No factorials or math.comb of large numbers: multiply the c factors (1 - k / i).")
def test_large_n_is_stable(student, rng):
    """n up to 60,000 (C(n, k) overflows a float), mixed n per problem"""
    n = np.array([60000, 60000, 30000, 1000, 1000])
    c = np.array([3, 20000, 1, 999, 10])              # the last two: n - c < k, exactly 1
    k = 1000
    got = _array(student.pass_at_k(n, c, k), (5,))
    want = np.array([1.0 if ni - ci < k else 1 - np.exp(np.sum(np.log1p(-k / np.arange(ni - ci + 1, ni + 1))))
                     for ni, ci in zip(n, c)])
    assert np.allclose(got, want, rtol=1e-7, atol=1e-12), \
        f"{int((~np.isclose(got, want, rtol=1e-7, atol=1e-12)).sum())} of 5 estimates with n in the thousands are wrong"


@stub("pass_at_k", points=1, hint="Unbiased: averaged over Binomial(n, p) counts it equals 1 - (1 - p)^k exactly.")
def test_unbiased_over_binomial_counts(student, rng):
    """E over c ~ Binomial(n, p) of the estimate equals 1 - (1 - p)^k (the plug-in would not)"""
    n = 24
    cs = np.arange(n + 1)
    for p, k in ((0.03, 8), (0.3, 4), (0.7, 20)):
        w = np.array([comb(n, int(c)) * p ** c * (1 - p) ** (n - c) for c in cs])
        got = _array(student.pass_at_k(np.full(n + 1, n), cs, k), (n + 1,))
        assert np.isclose((w * got).sum(), 1 - (1 - p) ** k, rtol=1e-9), \
            f"p = {p}, k = {k}: the expectation over Binomial({n}, p) counts is not pass@k: biased"


@stub("pass_at_k", points=1, hint="k must satisfy 1 <= k <= n for every problem: raise ValueError otherwise.")
def test_bad_k_raises(student):
    """k = 0 and k > some n raise ValueError, and only they: k = n of the smallest n does not"""
    for n, k in ((np.array([10, 4]), 5), (np.array([10, 12]), 0)):
        outcome = raised(student.pass_at_k, n, np.zeros(2, dtype=int), k)
        assert outcome == "ValueError", f"k = {k} with n = {n.tolist()} should raise ValueError, got {outcome}"
    outcome = raised(student.pass_at_k, np.array([10, 4]), np.array([3, 1]), 4)  # a stub that always raises earns nothing
    assert outcome == "no error", f"k = 4 with n = [10, 4] is allowed (1 <= k <= n), but it raised {outcome}"
    got = _array(student.pass_at_k(np.array([10, 4]), np.array([3, 1]), 4), (2,))  # nor one that checks k and no more
    assert np.allclose(got, [_exact(10, 3, 4), 1.0], rtol=1e-9, atol=1e-12), \
        "k = 4 with n = [10, 4], c = [3, 1]: the estimates are wrong (the second has n - c < k: exactly 1)"
