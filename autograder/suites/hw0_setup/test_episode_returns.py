"""Hidden tests of hw0's `episode_returns`."""
import numpy as np

from autograder.suite import check_array, stub

HINT = "An episode ends at a step with done=True (that step belongs to it); the unfinished tail is dropped."


def _stream(rng, n_episodes, tail):
    lengths = rng.integers(1, 8, size=n_episodes)
    dones = np.concatenate([np.arange(n) == n - 1 for n in lengths] + [np.zeros(tail, dtype=bool)])
    return rng.normal(size=dones.size), dones


@stub("episode_returns", points=1, hint=HINT)
def test_random_stream_matches_reference(student, reference, rng):
    """A random stream with an unfinished tail"""
    rewards, dones = _stream(rng, 6, tail=3)
    check_array(student.episode_returns(rewards, dones), reference.episode_returns(rewards, dones))


@stub("episode_returns", points=1, hint="The step where done is True is the episode's last step: include its reward.")
def test_done_step_belongs_to_its_episode(student):
    """The reward on the done step counts towards the episode it ends"""
    got = student.episode_returns(np.array([0.0, 10.0, 1.0, 100.0]), np.array([False, True, False, True]))
    check_array(got, np.array([10.0, 101.0]))


@stub("episode_returns", points=1, hint=HINT)
def test_edge_cases(student, reference):
    """No complete episode, one-step episodes, and a stream that ends exactly on a done"""
    empty = student.episode_returns(np.ones(5), np.zeros(5, dtype=bool))
    check_array(empty, np.zeros(0), name="the result with no done flag")
    check_array(student.episode_returns(np.arange(4.0), np.ones(4, dtype=bool)), np.arange(4.0),
                name="the result for one-step episodes")
    check_array(student.episode_returns(np.array([2.0, 3.0]), np.array([False, True])), np.array([5.0]),
                name="the result for a stream ending on done")
