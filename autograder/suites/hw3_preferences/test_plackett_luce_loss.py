"""Hidden tests of hw3's plackett_luce_loss."""
import numpy as np

from autograder.suite import check_scalar, stub

HINT = ("Gather scores in ranked order (best first); the loss of a row is sum_k [logsumexp(s_k..s_K) - s_k]; "
        "average over rows; use np.logaddexp.accumulate on the reversed row for the suffix log-sum-exps.")


def _rankings(rng, b, k):
    return np.argsort(rng.random((b, k)), axis=1)


@stub("plackett_luce_loss", points=2, hint=HINT)
def test_random_rankings_match_reference(student, reference, rng):
    """B = 7 groups of K = 5 candidates with random rankings"""
    scores, ranks = rng.normal(scale=2, size=(7, 5)), _rankings(rng, 7, 5)
    check_scalar(student.plackett_luce_loss(scores, ranks), reference.plackett_luce_loss(scores, ranks), rtol=1e-9)


@stub("plackett_luce_loss", points=1, hint="At K = 2, -log P(ranking) = -log sigmoid(s_best - s_other).")
def test_two_candidates_equal_bradley_terry(student, reference, rng):
    """K = 2 equals the Bradley–Terry loss of the preferred candidate"""
    scores, ranks = rng.normal(size=(9, 2)), _rankings(rng, 9, 2)
    rows = 2 * np.arange(9)
    want = reference.bt_loss(scores.ravel(), rows + ranks[:, 0], rows + ranks[:, 1], np.ones(9))
    check_scalar(student.plackett_luce_loss(scores, ranks), want, rtol=1e-9)


@stub("plackett_luce_loss", points=1, hint="The ranking lists candidates best first; the last choice has probability 1.")
def test_order_and_single_candidate(student, rng):
    """The best-first order matters, and K = 1 costs nothing"""
    scores = np.array([[4.0, 0.0, -3.0]])
    best_first = float(np.log1p(np.exp(-4) + np.exp(-7)) + np.log1p(np.exp(-3)))
    check_scalar(student.plackett_luce_loss(scores, np.array([[0, 1, 2]])), best_first, rtol=1e-9,
                 name="the loss of the ranking that agrees with the scores")
    check_scalar(student.plackett_luce_loss(rng.normal(size=(3, 1)), np.zeros((3, 1), dtype=int)), 0.0, atol=1e-12,
                 name="the loss with a single candidate per group")


@stub("plackett_luce_loss", points=1, hint=HINT)
def test_huge_scores_stay_finite(student, reference):
    """Scores of +-3000: finite and exact"""
    scores = np.array([[3000.0, -3000.0, 0.0], [0.0, 1.0, 3000.0]])
    ranks = np.array([[1, 2, 0], [0, 1, 2]])
    check_scalar(student.plackett_luce_loss(scores, ranks), reference.plackett_luce_loss(scores, ranks), rtol=1e-9)
