"""Hidden tests of hw1b's `mode_coverage`: closed forms computed here, random labels from the test's rng."""
import numpy as np

from autograder.suite import check_scalar, stub
from conftest import raised

HINT = ("left/right/not_passed are fractions of the policy's n episodes; coverage = (min(p_left, q_left) + "
        "min(p_right, q_right)) / (q_left + q_right) with q the expert's fractions of its own m episodes.")


def _labels(rng, n, p):
    return rng.choice(np.array([1, -1, 0]), size=n, p=p)


def _want(sides, expert):
    p = {s: np.mean(sides == s) for s in (1, -1, 0)}
    q = {s: np.mean(expert == s) for s in (1, -1, 0)}
    return p, (min(p[1], q[1]) + min(p[-1], q[-1])) / (q[1] + q[-1])


def _call(student, sides, expert):
    got = student.mode_coverage(sides, expert)
    assert isinstance(got, dict) and {"left", "right", "not_passed", "coverage"} <= set(got), \
        f"return a dict with 'left', 'right', 'not_passed' and 'coverage', got {type(got).__name__}"
    return got


@stub("mode_coverage", points=2, hint=HINT)
def test_fractions_and_coverage_on_random_labels(student, rng):
    """Random policy and expert labels of different sizes: the three fractions and the coverage"""
    for _ in range(3):
        sides = _labels(rng, int(rng.integers(20, 60)), rng.dirichlet(np.ones(3)))
        expert = _labels(rng, int(rng.integers(10, 40)), rng.dirichlet(np.ones(3)) * 0.8 + np.array([0.1, 0.1, 0.0]))
        if not (expert != 0).any():   # about 1 draw in 2,000: an expert that never passed has no coverage (the stub
            expert[rng.integers(len(expert))] = rng.choice([1, -1])   # must raise), so one of its episodes passes
        p, coverage = _want(sides, expert)
        got = _call(student, sides, expert)
        for key, side in (("left", 1), ("right", -1), ("not_passed", 0)):
            check_scalar(got[key], p[side], rtol=1e-9, name=f"'{key}' (a fraction of all the policy's episodes)")
        check_scalar(got["coverage"], coverage, rtol=1e-9, name="'coverage'")


@stub("mode_coverage", points=1, hint="Divide by the expert's passing fraction q_left + q_right, not by 1 or by the policy's.")
def test_coverage_is_relative_to_the_experts_passes(student, rng):
    """An expert that crashes often: a policy matching its passes covers 1, one side alone less"""
    q_pass = float(rng.uniform(0.3, 0.6))
    m = 40
    n_left = int(round(q_pass * m / 2))
    expert = np.array([1] * n_left + [-1] * n_left + [0] * (m - 2 * n_left))
    rng.shuffle(expert)
    check_scalar(_call(student, expert.copy(), expert)["coverage"], 1.0, rtol=1e-9,
                 name="the coverage of a policy with the expert's own labels")
    one_side = np.ones(30, dtype=np.int64)
    check_scalar(_call(student, one_side, expert)["coverage"], 0.5, rtol=1e-9,
                 name="the coverage of a policy that always passes left (half the expert's passing modes)")


@stub("mode_coverage", points=1, hint="Return Python floats (float(...)), not numpy scalars or arrays.")
def test_returns_python_floats(student, rng):
    """Every value is a Python float, and the fractions sum to one"""
    sides = _labels(rng, 25, [0.5, 0.3, 0.2])
    got = _call(student, sides, _labels(rng, 25, [0.5, 0.5, 0.0]))
    assert all(type(got[k]) is float for k in ("left", "right", "not_passed", "coverage")), \
        f"values should be Python floats, got {[type(got[k]).__name__ for k in ('left', 'right', 'not_passed', 'coverage')]}"
    check_scalar(got["left"] + got["right"] + got["not_passed"], 1.0, rtol=1e-9, name="left + right + not_passed")
    check_scalar(got["left"], float(np.mean(sides == 1)), rtol=1e-9, name="'left'")


@stub("mode_coverage", points=1, hint="Raise ValueError for empty arrays, values other than -1, 0, 1, or an expert that never passed.")
def test_refuses_bad_input(student, rng):
    """Empty input, a label of 2 and an expert that never passed raise ValueError"""
    cases = {"an empty policy array": (np.array([], dtype=np.int64), _labels(rng, 5, [0.5, 0.5, 0.0])),
             "a label of 2": (np.array([1, 2, -1]), _labels(rng, 5, [0.5, 0.5, 0.0])),
             "an expert that never passed": (_labels(rng, 6, [0.5, 0.5, 0.0]), np.zeros(4, dtype=np.int64))}
    for what, (sides, expert) in cases.items():
        outcome = raised(student.mode_coverage, sides, expert)
        assert outcome == "ValueError", f"{what} should raise ValueError, got {outcome}"
    sides, expert = _labels(rng, 12, [0.4, 0.4, 0.2]), _labels(rng, 9, [0.5, 0.3, 0.2])
    p, coverage = _want(sides, expert)
    got = _call(student, sides, expert)
    check_scalar(got["left"], p[1], rtol=1e-9, name="'left' on valid labels (which should not raise)")
    check_scalar(got["coverage"], coverage, rtol=1e-9, name="'coverage' on valid labels (which should not raise)")
