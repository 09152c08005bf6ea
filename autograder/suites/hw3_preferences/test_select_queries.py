"""Hidden tests of hw3's select_queries.

The docstring fixes the ranking (highest variance first) but not the order of equal variances, and random candidate
pools repeat pairs (random_pairs draws with repetition), so a selection is judged by the variances of the pairs it
picks, computed here, not by the reference's indices: ``np.argsort(var)[::-1]``, ``torch.topk`` or a stable sort of
``-var`` order a repeated pair differently, and each is right (on these pools the index comparison refused the
reversed argsort on a fifth to two fifths of the draws).
"""
import numpy as np
import torch

from autograder.suite import stub
from rlcourse.preferences import RewardEnsemble, random_pairs

HINT = ("For each candidate (a, b): p_k = sigmoid(R_k[a] - R_k[b]) for every member k; rank candidates by the variance "
        "of p over members, largest first; return their row indices (k of them).")
ENSEMBLE = "rlcourse.preferences.RewardEnsemble"


def _pool(rng, n, length, scale=1.0):
    obs = torch.as_tensor(scale * rng.normal(size=(n, length, 11)), dtype=torch.float32)
    act = torch.as_tensor(rng.uniform(-1, 1, size=(n, length, 3)), dtype=torch.float32)
    return obs, act


def _variances(seed, obs, act, cand):
    """Each candidate's variance over the members of sigmoid(R_k[a] - R_k[b]), from the grader's own copy of the
    ensemble the sandbox builds (``RewardEnsemble(11, 3, n_members=5, seed=seed)``), in float64."""
    with torch.random.fork_rng():
        ensemble = RewardEnsemble(11, 3, n_members=5, seed=seed)
    with torch.no_grad():
        R = ensemble(obs, act).sum(-1).double()
    p = torch.sigmoid(R[:, cand[:, 0]] - R[:, cand[:, 1]])
    return p.var(dim=0).numpy()


def _check_selection(got, var, k, what):
    """``got`` holds k distinct candidate indices whose variances are the k largest, largest first (ties in any order)."""
    assert isinstance(got, np.ndarray) and got.dtype.kind in "iu", \
        f"{what}: return a numpy array of integer indices, got {type(got).__name__} {getattr(got, 'dtype', '')}"
    assert got.shape == (k,), f"{what}: expected shape ({k},), got {got.shape}"
    assert got.min() >= 0 and got.max() < len(var), f"{what}: indices should be rows of candidates, 0 to {len(var) - 1}"
    assert len(set(got.tolist())) == k, f"{what}: a candidate was selected twice"
    picked, best = var[got], np.sort(var)[::-1][:k]
    wrong = ~np.isclose(picked, best, rtol=1e-4, atol=1e-9)
    if wrong.any():
        r = int(np.flatnonzero(wrong)[0])
        assert False, (f"{what}: entry {r} is not the candidate of the {r + 1}-th highest variance of the members' "
                       f"probabilities sigmoid(R_k[a] - R_k[b]) (its variance is {'too small' if picked[r] < best[r] else 'too large'})")


def _selected(student, seed, obs, act, cand, k):
    return student.helpers.run_select_queries(student.helpers.build(ENSEMBLE, 11, 3, n_members=5, seed=seed), obs, act,
                                              cand, k)


@stub("select_queries", points=2, hint=HINT)
def test_top_k_match_reference(student, rng):
    """60 candidates among 30 segments, k = 8: the same pairs, highest variance first"""
    obs, act = _pool(rng, 30, 10)
    cand = random_pairs(np.arange(30), 60, rng)
    _check_selection(_selected(student, 3, obs, act, cand, 8), _variances(3, obs, act, cand), 8, "the selected indices")


@stub("select_queries", points=1, hint=HINT)
def test_variance_of_probabilities_not_returns(student, rng):
    """Large returns saturate the sigmoid: rank by disagreement in probability, not in return"""
    obs, act = _pool(rng, 20, 25, scale=6.0)
    cand = random_pairs(np.arange(20), 40, rng)
    _check_selection(_selected(student, 4, obs, act, cand, 5), _variances(4, obs, act, cand), 5, "the selected indices")


@stub("select_queries", points=1, hint=HINT)
def test_all_candidates_sorted(student, rng):
    """k equal to the number of candidates: a full ordering"""
    obs, act = _pool(rng, 12, 5)
    cand = random_pairs(np.arange(12), 15, rng)
    _check_selection(_selected(student, 8, obs, act, cand, 15), _variances(8, obs, act, cand), 15,
                     "the ordering of all candidates")
