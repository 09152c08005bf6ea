"""The race track of hw1: geometry, dynamics, the scripted expert, and the pictures."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from rlcourse import racetrack as rt  # noqa: E402
from rlcourse.rollouts import rollout  # noqa: E402


def test_curvature_is_the_turn_of_the_heading_per_unit_length():
    phi, h = np.linspace(-3.1, 3.1, 41), 1e-5
    numeric = rt.wrap(rt.track_heading(phi + h) - rt.track_heading(phi - h)) / (2 * h) / rt.arc_speed(phi)
    assert np.allclose(rt.curvature(phi), numeric, rtol=1e-5, atol=1e-7)
    assert rt.curvature(phi).min() < 0 < rt.curvature(phi).max(), "the track should bend both ways"
    step = np.linalg.norm(rt.centre_line(phi + h) - rt.centre_line(phi - h), axis=-1) / (2 * h)
    assert np.allclose(step, rt.arc_speed(phi), rtol=1e-6)


def test_observations_round_trip_to_states():
    state = rt.start_states(np.random.default_rng(0), 5)
    obs = rt.observe(state)
    assert obs.shape == (5, rt.OBS_DIM) and obs.dtype == np.float32
    back = rt.state_of(obs)
    assert np.allclose(back[:, :2], state[:, :2], atol=1e-4)
    assert np.allclose(rt.wrap(back[:, 2] - state[:, 2]), 0, atol=1e-5)
    offset, heading_error, _ = rt.track_frame(state)
    assert np.all(np.abs(offset) < 0.1) and np.all(np.abs(heading_error) < 0.1), "starts are near the centre line"


def test_expert_drives_whole_episodes_and_runs_are_reproducible():
    expert = rt.Expert()
    first = rollout(expert.act, rt.ENV_ID, 4, seed=3)
    second = rollout(expert.act, rt.ENV_ID, 4, seed=3)
    assert np.array_equal(first.obs, second.obs)
    assert np.all(first.lengths == rt.HORIZON) and not first.terminated.any()
    assert np.allclose(first.rewards[first.mask], 1.0, atol=0.25), "reward is about one per step on the track"
    offsets = rt.track_frame(rt.state_of(first.obs[first.mask]))[0]
    assert np.abs(offsets).max() < 0.5


def test_without_feedback_the_car_leaves_the_track():
    open_loop = rt.Expert(heading_gain=0.0, offset_gain=0.0)
    episodes = rollout(open_loop.act, rt.ENV_ID, 4, seed=3)
    assert episodes.terminated.all() and episodes.lengths.max() < rt.HORIZON


def test_leaving_the_track_terminates_the_episode():
    env = rt.RaceTrackEnv()
    env.reset(seed=0)
    for t in range(100):
        _, _, terminated, truncated, _ = env.step(np.array([1.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and not truncated and abs(rt.track_frame(env.state)[0][0]) > 1.0


@pytest.mark.parametrize("shape", [(4,), (3, 4), (2, 5, 4)])
def test_expert_actions_have_the_right_shape_and_range(shape):
    obs = np.random.default_rng(1).normal(size=shape).astype(np.float32)
    actions = rt.Expert().act(obs)
    assert actions.shape == shape[:-1] + (1,) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)


def test_drive_paths_match_the_rollouts_and_draw():
    expert = rt.Expert(heading_gain=0.0, offset_gain=0.0)
    paths = rt.drive(expert.act, 3, seed=7)
    episodes = rollout(expert.act, rt.ENV_ID, 3, seed=7)
    for path, n, obs in zip(paths, episodes.lengths, episodes.obs):
        assert path.shape == (n + 1, 2)
        assert np.allclose(path[:-1], obs[:n, :2] * rt.RADIUS, atol=1e-4)
    ax = rt.plot_track()
    rt.plot_paths(ax, paths, "red", "open loop")
    assert len(ax.get_legend_handles_labels()[1]) == 1
    assert sum(len(line.get_xdata()) == 1 for line in ax.lines) == 3, "a cross where each car left the track"
