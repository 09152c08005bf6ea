"""Hidden tests of hw3's select_queries."""
import numpy as np
import torch

from autograder.suite import check_array, stub
from rlcourse.preferences import random_pairs

HINT = ("For each candidate (a, b): p_k = sigmoid(R_k[a] - R_k[b]) for every member k; rank candidates by the variance "
        "of p over members, largest first; return their row indices (k of them).")
ENSEMBLE = "rlcourse.preferences.RewardEnsemble"


def _pool(rng, n, length, scale=1.0):
    obs = torch.as_tensor(scale * rng.normal(size=(n, length, 11)), dtype=torch.float32)
    act = torch.as_tensor(rng.uniform(-1, 1, size=(n, length, 3)), dtype=torch.float32)
    return obs, act


def _both(student, reference, seed, obs, act, cand, k):
    return tuple(ns.select_queries(ns.helpers.build(ENSEMBLE, 11, 3, n_members=5, seed=seed), obs, act, cand, k)
                 for ns in (student, reference))


@stub("select_queries", points=2, hint=HINT)
def test_top_k_match_reference(student, reference, rng):
    """60 candidates among 30 segments, k = 8: the same pairs, highest variance first"""
    obs, act = _pool(rng, 30, 10)
    got, want = _both(student, reference, 3, obs, act, random_pairs(np.arange(30), 60, rng), 8)
    check_array(got, want, name="the selected indices")


@stub("select_queries", points=1, hint=HINT)
def test_variance_of_probabilities_not_returns(student, reference, rng):
    """Large returns saturate the sigmoid: rank by disagreement in probability, not in return"""
    obs, act = _pool(rng, 20, 25, scale=6.0)
    got, want = _both(student, reference, 4, obs, act, random_pairs(np.arange(20), 40, rng), 5)
    check_array(got, want, name="the selected indices")


@stub("select_queries", points=1, hint=HINT)
def test_all_candidates_sorted(student, reference, rng):
    """k equal to the number of candidates: a full ordering"""
    obs, act = _pool(rng, 12, 5)
    got, want = _both(student, reference, 8, obs, act, random_pairs(np.arange(12), 15, rng), 15)
    check_array(got, want, name="the ordering of all candidates")
