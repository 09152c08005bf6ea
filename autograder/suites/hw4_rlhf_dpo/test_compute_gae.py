"""Hidden tests of hw4's `compute_gae`: against a direct (non-recursive) sum, episode ends, truncations, edge cases."""
import numpy as np
import torch

from autograder.suite import check_tensor, stub

HINT = ("Backward over time: delta_t = r_t + gamma * (1 - d_t) * V_{t+1} - V_t and A_t = delta_t + gamma * lam * "
        "(1 - d_t) * A_{t+1}, with V_T = last_value; d_t cuts at the step it is set on; returns = A + V.")


def direct_gae(rewards, values, dones, last_value, gamma, lam):
    """A_t = sum_k (gamma * lam)^k delta_{t+k}, summed up to and including the first done at or after t."""
    T, N = rewards.shape
    next_values = np.vstack([values[1:], last_value[None]])
    delta = rewards + gamma * (1 - dones) * next_values - values
    adv = np.zeros((T, N))
    for i in range(N):
        for t in range(T):
            for k in range(T - t):
                adv[t, i] += (gamma * lam) ** k * delta[t + k, i]
                if dones[t + k, i]:
                    break
    return adv, adv + values


def _inputs(rng, T, N, p_done):
    r = rng.normal(size=(T, N))
    v = rng.normal(size=(T, N))
    d = (rng.random((T, N)) < p_done).astype(float)
    last = rng.normal(size=N)
    return r, v, d, last


def _t(*arrays):
    return [torch.as_tensor(a, dtype=torch.float32) for a in arrays]


def _check(student, arrays, gamma, lam, name):
    got = student.compute_gae(*_t(*arrays), gamma, lam)
    assert isinstance(got, (tuple, list)) and len(got) == 2, f"compute_gae should return (advantages, returns), got {type(got).__name__}"
    adv, ret = direct_gae(*arrays, gamma, lam)
    check_tensor(got[0], torch.as_tensor(adv, dtype=torch.float32), rtol=1e-4, atol=1e-4, name=f"the advantages ({name})")
    check_tensor(got[1], torch.as_tensor(ret, dtype=torch.float32), rtol=1e-4, atol=1e-4, name=f"the returns ({name})")


@stub("compute_gae", points=2, hint=HINT)
def test_matches_direct_sum_with_episode_ends(student, rng):
    """12 steps of 5 environments with random episode ends, against the direct sum of discounted TD errors"""
    _check(student, _inputs(rng, 12, 5, 0.15), 0.99, 0.95, "random dones")


@stub("compute_gae", points=1, hint="An episode end at step t stops both the bootstrap V_{t+1} and A_{t+1} at step t "
      "(not at t+1 or t-1).")
def test_done_cuts_at_its_own_step(student):
    """A done on the middle step: what follows it must not leak into the steps before"""
    r = np.zeros((3, 1)); v = np.zeros((3, 1)); d = np.array([[0.0], [1.0], [0.0]])
    r[2, 0], last = 100.0, np.array([1000.0])
    _check(student, (r, v, d, last), 0.9, 0.8, "a done at t = 1 with a large reward after it")
    d = np.array([[0.0], [0.0], [1.0]])
    _check(student, (np.ones((3, 1)), np.zeros((3, 1)), d, np.array([1000.0])), 0.9, 0.8,
           "a done on the last step: last_value must be ignored")


@stub("compute_gae", points=1, hint="Truncations arrive as dones whose reward already holds gamma * V(final obs): "
      "treat them like any done, and do not bootstrap from the next row (a new episode).")
def test_truncation_with_folded_bootstrap(student, rng):
    """A time-limit cut: reward + gamma * V(final), then an unrelated episode; only the folded value counts"""
    T, N, gamma, lam = 6, 3, 0.99, 0.95
    r, v, _, last = _inputs(rng, T, N, 0.0)
    d = np.zeros((T, N)); d[2, :] = 1.0
    r[2, :] += gamma * np.array([5.0, -3.0, 0.5])       # the loop folds gamma * V(s_final) into the reward
    v[3, :] = 1e3                                        # the next episode's first value: must not leak back
    _check(student, (r, v, d, last), gamma, lam, "a truncation at t = 2 in every environment")


@stub("compute_gae", points=1, hint="lam = 0 gives the TD error delta_t; gamma = lam = 1 without dones gives the "
      "sum of future rewards + last_value - V_t.")
def test_lambda_limits(student, rng):
    """lam = 0 (TD errors) and gamma = lam = 1 (Monte-Carlo), and independence of the columns"""
    arrays = _inputs(rng, 7, 4, 0.2)
    _check(student, arrays, 0.9, 0.0, "lam = 0")
    r, v, _, last = _inputs(rng, 7, 4, 0.0)
    _check(student, (r, v, np.zeros((7, 4)), last), 1.0, 1.0, "gamma = lam = 1, no dones")


@stub("compute_gae", points=1, hint=HINT)
def test_shapes_single_step_and_inputs_untouched(student, rng):
    """One step of one environment; a long rollout; the inputs are not modified in place"""
    _check(student, _inputs(rng, 1, 1, 0.5), 0.99, 0.95, "a single step")
    _check(student, _inputs(rng, 200, 2, 0.01), 0.99, 0.95, "200 steps")
    r, v, d, last = _t(*_inputs(rng, 5, 3, 0.3))
    _, after, _ = student.helpers.call_and_inputs("compute_gae", [r, v, d, last, 0.9, 0.9])
    for name, sent, back in zip(("rewards", "values", "dones", "last_value"), (r, v, d, last), after):
        assert type(back) is torch.Tensor and torch.equal(back, sent), \
            f"compute_gae changed its input `{name}` in place: write into new tensors"
