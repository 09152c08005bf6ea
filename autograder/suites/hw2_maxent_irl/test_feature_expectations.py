"""Hidden tests of feature_expectations."""
import numpy as np

from autograder.suite import check_array, stub

HINT = "features[states] has shape (N, T, F): sum over time (axis 1), then average over trajectories (axis 0)."


@stub("feature_expectations", points=2, hint=HINT)
def test_matches_reference(student, reference, rng):
    """Random states (N = 7, T = 5) and features (S = 9, F = 3)"""
    states, phi = rng.integers(0, 9, size=(7, 5)), rng.normal(size=(9, 3))
    check_array(student.feature_expectations(states, phi), reference.feature_expectations(states, phi))


@stub("feature_expectations", points=1, hint=HINT)
def test_sum_over_time_mean_over_trajectories(student):
    """A constant feature of 1 gives T whatever N is; one trajectory of one step gives phi(s_0)"""
    got = student.feature_expectations(np.zeros((40, 6), dtype=np.int64), np.ones((3, 1)))
    check_array(got, np.array([6.0]), name="mu_D for a constant feature (T = 6, N = 40)")
    phi = np.array([[1.0, 2.0], [3.0, 4.0]])
    check_array(student.feature_expectations(np.array([[1]]), phi), phi[1], name="mu_D of one one-step trajectory")


@stub("feature_expectations", points=1, hint=HINT)
def test_rectangular_not_square(student, reference, rng):
    """N != T and F = 1 (catches swapped axes)"""
    states, phi = rng.integers(0, 4, size=(3, 11)), rng.normal(size=(4, 1))
    check_array(student.feature_expectations(states, phi), reference.feature_expectations(states, phi))
