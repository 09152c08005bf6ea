"""Numerical checks of chapter 4's ratings model (`lectures/04_feedback_spectrum.md`, § the ratings model),
which hw3's section C.3 simulates (`rlcourse.feedback_spectrum`).

Each test compares the lecture's statement with an independent computation (Monte Carlo frequencies against
closed forms, a direct implementation of the latent rating against the module's draws).
"""
from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
from scipy.special import expit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_links import checks  # noqa: E402
from lecture_math import plackett_luce_prob  # noqa: E402

from rlcourse import feedback_spectrum as F  # noqa: E402


def _returns(rng, n=400):
    return rng.normal(60.0, 20.0, n)


@checks("eq-rating-model", "e118f4da")
def test_ratings_follow_the_model_offset_scale_and_drift():
    rng = np.random.default_rng(0)
    R = _returns(rng)
    spread = F.rating_spread(R, 2.0)
    segments = np.tile(np.arange(len(R)), 5)
    # the same seed draws the same annotators, noise and walk; only the offset's size differs
    base = F.simulate_ratings(R, segments, F.Panel(4, 0.0, 0.0, 0.0), np.random.default_rng(1), spread)
    shifted = F.simulate_ratings(R, segments, F.Panel(4, 1.0, 0.0, 0.0), np.random.default_rng(1), spread)
    z = np.random.default_rng(1).normal(0.0, 1.0, 4)                    # the offsets b_k the panel drew
    assert base["rating"].min() >= 1 and base["rating"].max() <= 10 and base["rating"].dtype.kind == "i"
    mid = (base["rating"] > 2) & (base["rating"] < 9)                   # away from the clip at 1 and 10
    for k in range(4):
        mine = mid & (base["annotator"] == k)
        diff = (shifted["rating"] - base["rating"])[mine].mean()        # rounding is unbiased on average
        assert abs(diff - z[k]) < 0.08, (k, diff, z[k])
    # without offset, scale or drift the expected rating is c + kappa (R / T - m): compare per segment
    m, kappa = spread
    want = np.clip(F.RATING_CENTRE + kappa * (R / 2.0 - m), 1, 10)
    got = np.bincount(base["segment"], base["rating"]) / np.bincount(base["segment"])
    inside = (want > 2) & (want < 9)
    assert np.abs(got - want)[inside].mean() < 0.3
    # the drift: Var[delta(t) - delta(t')] = lambda^2 |t - t'| / t0, t in seconds of rating
    lam, n_ann, n = 2.0, 400, 200
    _, offset, _ = F._turns(n_ann * n, F.Panel(n_ann, 0.0, 0.0, lam), F.SECONDS_PER_LABEL["rating"],
                            np.random.default_rng(2))
    walk = offset.reshape(n, n_ann)                                     # label m is annotator m % n_ann's
    for lag in (1, 10, 100):
        var = np.var(walk[lag:] - walk[:-lag])
        want = lam ** 2 * lag * F.SECONDS_PER_LABEL["rating"] / F.DRIFT_SECONDS
        assert abs(var / want - 1) < 0.1, (lag, var, want)


@checks("eq-within-cancel", "c64c13fe")
def test_side_by_side_comparisons_cancel_offset_scale_and_drift():
    rng = np.random.default_rng(3)
    # the algebra: shared a_k, b_k, delta_k(t) leave only the sign of v1 - v2
    v = rng.normal(size=(10000, 2)) * 3
    a, b, d = np.exp(rng.normal(size=(10000, 1))), rng.normal(size=(10000, 1)) * 4, rng.normal(size=(10000, 1)) * 4
    y = 5.5 + a * 0.4 * (v - 1.0) + b + d
    assert np.array_equal(y[:, 0] > y[:, 1], v[:, 0] > v[:, 1])
    # centred Gumbel differences are logistic: P(R1 - R2 > T (g2 - g1)) = sigmoid((R1 - R2) / T)
    g = rng.gumbel(size=(400000, 2))
    for delta in (-3.0, -0.5, 0.0, 1.0, 4.0):
        assert abs(np.mean(delta > g[:, 1] - g[:, 0]) - expit(delta)) < 0.004, delta
    # the module's comparisons do not see the panel's offsets, scales or drift (same seed, same labels)
    R = _returns(rng)
    pairs = rng.integers(0, len(R), (500, 2))
    calm = F.simulate_comparisons(R, pairs, F.Panel(), np.random.default_rng(4))
    wild = F.simulate_comparisons(R, pairs, F.Panel(5, 3.0, 1.0, 8.0), np.random.default_rng(4))
    assert np.array_equal(calm, wild)
    # and sorting by v is a Plackett-Luce ranking with utilities R / T
    u = np.array([1.0, 0.0, -0.7])
    groups = np.tile(np.arange(3), (200000, 1))
    order = F.simulate_rankings(u * 2.0, groups, F.Panel(temperature=2.0), np.random.default_rng(5))
    codes = order @ np.array([9, 3, 1])
    for perm in itertools.permutations(range(3)):
        freq = np.mean(codes == np.array(perm) @ np.array([9, 3, 1]))
        assert abs(freq - plackett_luce_prob(u, np.array(perm))) < 0.004, perm


@checks("eq-drift-residual", "ab98a826")
def test_ratings_of_one_annotator_keep_only_the_drift_between_them():
    rng = np.random.default_rng(6)
    lam, n_ann, n = 3.0, 300, 120
    panel = F.Panel(n_ann, 2.0, 0.0, lam)
    who, offset, _ = F._turns(n_ann * n, panel, F.SECONDS_PER_LABEL["rating"], rng)
    b_plus_delta = offset.reshape(n, n_ann)
    for lag in (1, 5, 40):
        within = b_plus_delta[lag:] - b_plus_delta[:-lag]               # same annotator: b_k cancels
        want = lam ** 2 * lag * F.SECONDS_PER_LABEL["rating"] / F.DRIFT_SECONDS
        assert abs(np.var(within) / want - 1) < 0.1, (lag, np.var(within), want)
        across = b_plus_delta[lag:, 1:] - b_plus_delta[:-lag, :-1]     # two annotators: b_k - b_k' stays
        assert np.var(across) > np.var(within) + 2 * 2.0 ** 2 * 0.8
