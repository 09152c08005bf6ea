"""Hidden tests of hw0's `discounted_returns`."""
import numpy as np

from autograder.suite import check_array, stub

HINT = "G_t = r_t + gamma * G_{t+1} with G_T = 0, for every row separately; the result has the rewards' shape."


def _check(got, want, rtol: float = 1e-6, name: str = "the result") -> None:
    """check_array at ``rtol`` for a float64 result. The docstring asks for a float array, so a float32 one is compared
    at float32's own precision: its rounding alone is 6e-8 of each value, and a sum in float32 drifts by about 1e-7 of
    the largest return over a dozen steps and 1e-6 over a thousand (so 1e-5, relative and of the largest return)."""
    want = np.asarray(want)
    if isinstance(got, np.ndarray) and got.dtype == np.float32:
        check_array(got, want, rtol=max(rtol, 1e-5), atol=1e-5 * (float(np.abs(want).max(initial=0.0)) + 1e-3), name=name)
    else:
        check_array(got, want, rtol=rtol, name=name)


@stub("discounted_returns", points=1, hint=HINT)
def test_random_batch_matches_reference(student, reference, rng):
    """Random rewards, several episodes: matches the definition"""
    rewards = rng.normal(size=(5, 13))
    _check(student.discounted_returns(rewards, 0.9), reference.discounted_returns(rewards, 0.9), rtol=1e-8)


@stub("discounted_returns", points=1, hint="Discount the future, not the past: the last step's return is its reward.")
def test_last_step_is_its_reward(student, rng):
    """The return-to-go at the final step is the final reward alone, the step before adds gamma times it"""
    rewards = rng.normal(size=(3, 6))
    got = student.discounted_returns(rewards, 0.7)
    _check(got[:, -1] if isinstance(got, np.ndarray) and got.shape == (3, 6) else got, rewards[:, -1],
           name="the returns at the final step")
    _check(got[:, -2], rewards[:, -2] + 0.7 * rewards[:, -1],
           name="the returns at the step before the last (r_{T-2} + gamma * r_{T-1})")


@stub("discounted_returns", points=1, hint="Each episode (row) is independent: never sum across rows.")
def test_rows_are_independent(student, reference, rng):
    """Episodes do not leak into each other (the time axis is the last one)"""
    rewards = np.zeros((4, 9))
    rewards[2, 3] = 1.0
    _check(student.discounted_returns(rewards, 0.5), reference.discounted_returns(rewards, 0.5))


@stub("discounted_returns", points=1, hint="gamma = 0 keeps only r_t; gamma = 1 sums everything from t on.")
def test_edge_discounts(student, reference, rng):
    """Discounts 0 and 1, and a single-step episode"""
    rewards = rng.normal(size=(2, 7))
    for gamma in (0.0, 1.0):
        _check(student.discounted_returns(rewards, gamma), reference.discounted_returns(rewards, gamma),
               name=f"the result for gamma = {gamma}")
    one = rng.normal(size=(3, 1))
    _check(student.discounted_returns(one, 0.9), one, name="the result for one-step episodes")


@stub("discounted_returns", points=1, hint="Long episodes: avoid computing gamma**T for huge T in a way that overflows.")
def test_long_episode_is_finite_and_exact(student, reference, rng):
    """A 1,000-step episode with gamma = 0.99 stays finite and exact"""
    rewards = rng.uniform(0, 1, size=(1, 1000))
    _check(student.discounted_returns(rewards, 0.99), reference.discounted_returns(rewards, 0.99), rtol=1e-7)
