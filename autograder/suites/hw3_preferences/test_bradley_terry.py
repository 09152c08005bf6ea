"""Hidden tests of hw3's Bradley–Terry stubs: bt_probability, bt_loss, bt_gradient."""
import numpy as np
from scipy.special import expit

from autograder.suite import check_array, check_scalar, stub

P_HINT = "P(i > j) = sigmoid(r_i - r_j): take the difference first (scipy.special.expit is stable), and broadcast."
L_HINT = ("Mean over comparisons of -[mu log sigmoid(d) + (1 - mu) log sigmoid(-d)], d = u[i] - u[j]; "
          "compute log sigmoid with log_expit or logaddexp so it stays finite.")
G_HINT = ("dL/du_k = mean over comparisons of (sigmoid(d) - mu) * ([k == i] - [k == j]); accumulate with np.bincount "
          "(a fancy-indexed += drops repeated indices) and return one entry per item.")


def _comparisons(rng, n_items, m):
    i = rng.integers(0, n_items, m)
    j = (i + rng.integers(1, n_items, m)) % n_items
    return i, j, rng.choice([0.0, 0.5, 1.0], m)


@stub("bt_probability", points=1, hint=P_HINT)
def test_probability_broadcasts_and_matches(student, reference, rng):
    """Random utilities of shapes (3, 1) and (4,): values and broadcast shape"""
    r_i, r_j = rng.normal(size=(3, 1)), rng.normal(size=4)
    check_array(student.bt_probability(r_i, r_j), reference.bt_probability(r_i, r_j))


@stub("bt_probability", points=1, hint=P_HINT)
def test_probability_complements_in_open_interval(student, rng):
    """P(i>j) + P(j>i) = 1 and 0 < P < 1 for moderate differences"""
    a, b = rng.normal(scale=3, size=50), rng.normal(scale=3, size=50)
    p, q = student.bt_probability(a, b), student.bt_probability(b, a)
    check_array(p + q if isinstance(p, np.ndarray) and isinstance(q, np.ndarray) else p, np.ones(50),
                name="P(i>j) + P(j>i)")
    assert np.all((p > 0) & (p < 1)), "probabilities must lie strictly between 0 and 1 for moderate differences"
    check_array(p, expit(a - b), rtol=1e-9, name="P(i > j) = sigmoid(r_i - r_j)")


@stub("bt_probability", points=1, hint=P_HINT)
def test_probability_stable_for_huge_utilities(student):
    """Utilities near 1000: only the difference matters, and nothing overflows to NaN"""
    check_array(student.bt_probability(np.array([1000.0, -1000.0, 1e3]), np.array([999.0, 0.0, -1e3])),
                np.array([expit(1.0), 0.0, 1.0]), atol=1e-12, name="P for utilities (1000 vs 999, -1000 vs 0, 1e3 vs -1e3)")


@stub("bt_loss", points=1, hint=L_HINT)
def test_loss_matches_reference(student, reference, rng):
    """Random utilities and labels with ties"""
    u = rng.normal(size=12)
    i, j, mu = _comparisons(rng, 12, 200)
    check_scalar(student.bt_loss(u, i, j, mu), reference.bt_loss(u, i, j, mu), rtol=1e-9)


@stub("bt_loss", points=1, hint=L_HINT)
def test_loss_is_a_mean_and_orientation(student, reference, rng):
    """Doubling the data leaves the mean loss unchanged; a confident right answer costs little"""
    u = rng.normal(size=5)
    i, j, mu = _comparisons(rng, 5, 30)
    check_scalar(student.bt_loss(u, np.tile(i, 2), np.tile(j, 2), np.tile(mu, 2)), reference.bt_loss(u, i, j, mu),
                 rtol=1e-9, name="the loss of the data repeated twice")
    check_scalar(student.bt_loss(np.array([5.0, 0.0]), np.array([0]), np.array([1]), np.array([1.0])),
                 float(np.log1p(np.exp(-5.0))), rtol=1e-9, name="the loss of item 0 (utility 5) beating item 1 (utility 0)")


@stub("bt_loss", points=1, hint=L_HINT)
def test_loss_ties_count_half(student):
    """A tie costs -[log sigmoid(d) + log sigmoid(-d)] / 2"""
    d = 1.7
    want = -0.5 * (np.log(expit(d)) + np.log(expit(-d)))
    check_scalar(student.bt_loss(np.array([d, 0.0]), np.array([0]), np.array([1]), np.array([0.5])), want, rtol=1e-9)


@stub("bt_loss", points=1, hint=L_HINT)
def test_loss_finite_for_huge_differences(student):
    """Differences of 1000 against the label: loss 1000, not inf"""
    check_scalar(student.bt_loss(np.array([1000.0, 0.0, -1000.0]), np.array([0, 2]), np.array([1, 1]),
                                 np.array([0.0, 1.0])), 1000.0, rtol=1e-9)


@stub("bt_gradient", points=2, hint=G_HINT)
def test_gradient_equals_finite_difference(student, reference, rng):
    """Every coordinate is the derivative of the loss: its closed form, which central finite differences confirm"""
    u = rng.normal(size=8)
    i, j, mu = _comparisons(rng, 8, 60)
    eps = 1e-6
    fd = np.array([(reference.bt_loss(u + eps * e, i, j, mu) - reference.bt_loss(u - eps * e, i, j, mu)) / (2 * eps)
                   for e in np.eye(8)])
    g = (expit(u[i] - u[j]) - mu) / len(i)
    exact = np.bincount(i, g, minlength=8) - np.bincount(j, g, minlength=8)
    assert np.allclose(exact, fd, rtol=1e-4, atol=1e-7), "suite error: the closed form disagrees with finite differences"
    # Compared with the closed form, not the finite differences themselves: a stub that returns finite differences of
    # bt_loss (no derivative worked out) agreed with them at 1e-4 and earned these 2 points; it is off by 1e-10 to 1e-8 of
    # each entry, where a derived gradient, however it sums, is within 1e-14.
    got = student.bt_gradient(u, i, j, mu)
    check_array(got, exact, rtol=1e-11, atol=1e-14,
                name="the gradient (exact to rounding: derive it, do not difference the loss numerically)")


@stub("bt_gradient", points=1, hint=G_HINT)
def test_gradient_repeated_indices_and_unused_items(student, reference, rng):
    """The same pair many times, and items that appear in no comparison (zero gradient, still present)"""
    u = rng.normal(size=6)
    i, j, mu = np.array([0, 0, 0, 2, 2]), np.array([1, 1, 1, 0, 0]), np.array([1.0, 0.0, 1.0, 0.5, 1.0])
    check_array(student.bt_gradient(u, i, j, mu), reference.bt_gradient(u, i, j, mu), rtol=1e-11, atol=1e-14)
