"""Hidden tests of hw1's `relabel_with_expert`."""
import numpy as np
import torch

from autograder.suite import check_array, stub
from rlcourse import data, racetrack
from rlcourse.nets import GaussianPolicy

HINT = ("Flatten the leading dimensions to (n, obs_dim), call expert.act once on the whole batch, and reshape the "
        "result to (..., act_dim) as float32.")


def _relabel(student, expert, obs):
    """The student's labels of ``obs`` by a released expert (``"hopper"`` or ``"race"``) loaded in the sandbox."""
    return student.relabel_with_expert(student.helpers.expert(expert), obs)


def _hopper_states(rng, shape):
    return (rng.normal(size=shape + (11,)) * np.array([0.1, 0.05, 0.1, 0.1, 0.5, 0.5, 1, 0.5, 1, 1, 3])
            + np.array([1.3] + [0] * 10)).astype(np.float32)


@stub("relabel_with_expert", points=1, hint=HINT)
def test_hopper_expert_labels(student, rng):
    """A batch of Hopper states gets the expert's (mean) actions as float32"""
    obs = _hopper_states(rng, (50,))
    got = _relabel(student, "hopper", obs)
    want = data.load_policy("experts/Hopper-v5/expert.pt").act(obs)
    check_array(got, want, rtol=1e-5, atol=1e-6, name="the labels")
    assert got.dtype == np.float32, f"return float32 labels, got {got.dtype}"


@stub("relabel_with_expert", points=1, hint=HINT)
def test_any_leading_shape(student, rng):
    """States of shape (episodes, steps, obs_dim) give labels of shape (episodes, steps, act_dim)"""
    obs = _hopper_states(rng, (3, 7))
    got = _relabel(student, "hopper", obs)
    want = data.load_policy("experts/Hopper-v5/expert.pt").act(obs.reshape(-1, 11)).reshape(3, 7, 3)
    check_array(got, want, rtol=1e-5, atol=1e-6, name="the labels of a (3, 7, 11) batch")
    race = rng.normal(size=(2, 5, racetrack.OBS_DIM)).astype(np.float32)
    check_array(_relabel(student, "race", race),
                racetrack.Expert().act(race.reshape(-1, racetrack.OBS_DIM)).reshape(2, 5, 1), rtol=1e-5, atol=1e-6,
                name="the race-track expert's labels of a (2, 5, 4) batch")


@stub("relabel_with_expert", points=1, hint="Ask for the expert's deterministic action (expert.act), never a sample from its Gaussian.")
def test_labels_are_deterministic_means(student, rng):
    """An expert with a wide Gaussian is still labelled with its mean, the same every time"""
    config = dict(hidden=(8,), log_std_init=1.0)
    expert = student.helpers.build("rlcourse.nets.GaussianPolicy", 11, 3, torch_seed=0, **config)
    with torch.random.fork_rng():       # the same expert, built on the grader's side
        torch.manual_seed(0)
        own = GaussianPolicy(11, 3, **config).eval()
    obs = _hopper_states(rng, (20,))
    first = student.relabel_with_expert(expert, obs)
    second = student.relabel_with_expert(expert, obs)
    check_array(first, own.act(obs), rtol=1e-5, atol=1e-6, name="the labels")
    check_array(second, first, rtol=0, atol=0, name="the labels of a second call")


@stub("relabel_with_expert", points=1, hint="Zero states in, an empty (0, act_dim) float32 array out.")
def test_empty_batch(student):
    """No states: an empty (0, act_dim) array"""
    got = _relabel(student, "hopper", np.zeros((0, 11), dtype=np.float32))
    check_array(got, np.zeros((0, 3), dtype=np.float32), name="the labels of an empty batch")
    got = _relabel(student, "race", np.zeros((0, racetrack.OBS_DIM), dtype=np.float32))
    check_array(got, np.zeros((0, 1), dtype=np.float32),
                name="the race-track expert's labels of an empty batch (its actions have 1 dimension, not 3)")
