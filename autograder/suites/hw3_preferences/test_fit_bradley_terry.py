"""Hidden tests of hw3's Bradley–Terry fits (gradient descent and Hunter's MM)."""
import numpy as np
from scipy.special import expit
from scipy.stats import spearmanr

from autograder.suite import check_array, stub
from rlcourse.preferences import load_items, sample_labels

GD_HINT = ("Gradient descent on the mean loss from u = 0 with step n_items; stop when max |grad| < tol; "
           "return the utilities minus their mean.")
MM_HINT = ("pi_k <- W_k / sum_l N_kl / (pi_k + pi_l), with W_k = wins + ties / 2; renormalise every step and return "
           "log(pi) centred to mean zero.")


def _random_instance(rng, n_items=15, m=1500):
    u = rng.normal(size=n_items)
    u -= u.mean()
    i = rng.integers(0, n_items, m)
    j = (i + rng.integers(1, n_items, m)) % n_items
    return u, i, j, sample_labels(u[i] - u[j], 0.3, rng)


def _shipped_recovery(fit):
    d = load_items()
    got = fit(d["n_items"], d["i"], d["j"], d["mu"])
    assert isinstance(got, np.ndarray) and got.shape == (d["n_items"],), \
        f"expected {d['n_items']} utilities, got {type(got).__name__} of shape {np.shape(got)}"
    assert abs(got.mean()) < 1e-8, f"the utilities should have mean zero, got mean {got.mean():.3g}"
    rho = spearmanr(got, d["utilities"]).statistic
    assert rho >= 0.95, f"Spearman correlation with the hidden utilities is {rho:.3f}, expected at least 0.95"
    return got, d


def _gd_steps(n_items, i, j, mu, lr, n_steps):
    """``n_steps`` steps of gradient descent on the mean loss from u = 0 (computed here), centred."""
    u, mu = np.zeros(n_items), np.asarray(mu, dtype=float)
    for _ in range(n_steps):
        g = (expit(u[i] - u[j]) - mu) / len(i)
        u = u - lr * (np.bincount(i, g, minlength=n_items) - np.bincount(j, g, minlength=n_items))
    return u - u.mean()


def _check_gradient_descent(student, n_items, i, j, mu):
    """The maximum-likelihood utilities alone are reached by any optimiser (scipy's, or the MM fit called from here):
    the fit must also be the documented descent, which two steps of a given size from zero show."""
    check_array(student.fit_bradley_terry(n_items, i, j, mu, lr=2.5, n_steps=2), _gd_steps(n_items, i, j, mu, 2.5, 2),
                rtol=1e-6, atol=1e-10, name="the utilities after n_steps = 2 steps of size lr = 2.5 (gradient descent "
                "on bt_loss from u = 0: u <- u - lr * gradient, not another optimiser)")


@stub("fit_bradley_terry", points=2, hint=GD_HINT)
def test_gd_recovers_shipped_utilities(student, reference):
    """On the shipped items: mean zero, Spearman >= 0.95, and the maximum-likelihood values, by gradient descent"""
    got, d = _shipped_recovery(student.fit_bradley_terry)
    check_array(got, reference.fit_bradley_terry_mm(d["n_items"], d["i"], d["j"], d["mu"]), atol=1e-4,
                name="the fitted utilities")
    _check_gradient_descent(student, d["n_items"], d["i"], d["j"], d["mu"])


@stub("fit_bradley_terry", points=1, hint=GD_HINT)
def test_gd_random_instance(student, reference, rng):
    """A random instance with ties: the maximum-likelihood utilities, and two steps of gradient descent"""
    _, i, j, mu = _random_instance(rng)
    check_array(student.fit_bradley_terry(15, i, j, mu), reference.fit_bradley_terry_mm(15, i, j, mu), atol=1e-4)
    _check_gradient_descent(student, 15, i, j, mu)


def _mm_steps(n_items, i, j, mu, n_steps):
    """``n_steps`` simultaneous MM updates from equal strengths (computed here), centred in log space."""
    mu = np.asarray(mu, dtype=float)
    wins = np.bincount(i, mu, minlength=n_items) + np.bincount(j, 1.0 - mu, minlength=n_items)
    log_pi = np.zeros(n_items)
    for _ in range(n_steps):
        inv = 1.0 / (np.exp(log_pi[i]) + np.exp(log_pi[j]))
        log_pi = np.log(wins) - np.log(np.bincount(i, inv, minlength=n_items) + np.bincount(j, inv, minlength=n_items))
        log_pi -= log_pi.mean()
    return log_pi


def _check_mm_steps(student, n_items, i, j, mu):
    """The maximum-likelihood utilities alone are reached by any optimiser (scipy's on bt_loss, or gradient
    descent): the fit must also be the documented MM iteration, which two iterations from equal strengths show."""
    check_array(student.fit_bradley_terry_mm(n_items, i, j, mu, n_iters=2), _mm_steps(n_items, i, j, mu, 2),
                rtol=1e-6, atol=1e-10, name="the utilities after n_iters = 2 MM iterations from equal strengths "
                "(every item updated at once: pi_k <- wins_k / sum over k's comparisons of 1 / (pi_k + pi_other); "
                "not another optimiser)")


@stub("fit_bradley_terry_mm", points=2, hint=MM_HINT)
def test_mm_recovers_shipped_utilities(student, reference):
    """On the shipped items: mean zero, Spearman >= 0.95, the maximum-likelihood values, and two MM iterations"""
    got, d = _shipped_recovery(student.fit_bradley_terry_mm)
    check_array(got, reference.fit_bradley_terry(d["n_items"], d["i"], d["j"], d["mu"]), atol=1e-4,
                name="the fitted utilities")
    _check_mm_steps(student, d["n_items"], d["i"], d["j"], d["mu"])


@stub("fit_bradley_terry_mm", points=1, hint=MM_HINT)
def test_mm_random_instance_with_ties(student, reference, rng):
    """A random instance where ties are frequent: ties count half a win (the fit, and two MM iterations)"""
    u, i, j, _ = _random_instance(rng, 10, 1200)
    mu = sample_labels(u[i] - u[j], 1.0, rng)           # about 45% ties
    check_array(student.fit_bradley_terry_mm(10, i, j, mu), reference.fit_bradley_terry(10, i, j, mu), atol=1e-4)
    _check_mm_steps(student, 10, i, j, mu)


@stub("fit_bradley_terry_mm", points=1, hint="Iterate until the log-strengths stop moving (tol), not a fixed few steps.")
def test_mm_reaches_a_stationary_point(student, reference, rng):
    """The MM fit of a random instance is a stationary point of the mean loss (and two MM iterations)"""
    _, i, j, mu = _random_instance(rng, 12, 1000)
    got = student.fit_bradley_terry_mm(12, i, j, mu)
    assert isinstance(got, np.ndarray) and got.shape == (12,), f"expected 12 utilities, got {np.shape(got)}"
    grad = reference.bt_gradient(got, i, j, mu)
    assert np.abs(grad).max() < 1e-7, f"the gradient of the loss at your fit is {np.abs(grad).max():.1e}, not ~0"
    _check_mm_steps(student, 12, i, j, mu)
    # Item 0's win rate (1/2) is the geometric mean of the others' (5/8, 2/5), so the first iteration leaves its
    # log-strength at 0 while the others move: only the largest move says whether the iteration has converged.
    i = np.repeat([0, 1, 0], [10, 10, 15])
    j = np.repeat([1, 2, 2], [10, 10, 15])
    mu = np.repeat([1.0, 0.0, 1.0, 0.5, 1.0, 0.5, 0.0], [5, 5, 5, 5, 5, 5, 5])
    got = student.fit_bradley_terry_mm(3, i, j, mu)
    assert isinstance(got, np.ndarray) and got.shape == (3,), f"expected 3 utilities, got {np.shape(got)}"
    grad = reference.bt_gradient(got, i, j, mu)
    assert np.abs(grad).max() < 1e-7, (f"on a 3-item instance where one item does not move in the first iteration, the "
                                       f"gradient of the loss at your fit is {np.abs(grad).max():.1e}, not ~0: stop only "
                                       "once no log-strength moves by more than tol")
