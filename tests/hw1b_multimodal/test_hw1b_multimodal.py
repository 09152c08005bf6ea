"""The obstacle track of hw1b (rlcourse.multimodal): geometry, the batched environment, the two-sided expert,
the side each episode passed on, chunk data, the networks and the pictures."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest
import torch

matplotlib.use("Agg")

from rlcourse import multimodal as mm  # noqa: E402
from rlcourse import racetrack as rt  # noqa: E402


def drive(policy, n, seed, task=mm.CLOSED_LOOP):
    """Per-step rollout of a policy on ObstacleTracks (the notebook's chunked_rollout with k = 1, written here)."""
    env = mm.ObstacleTracks(n, seed, task)
    obs, observations, running = env.reset(), [], []
    while not env.done.all():
        observations.append(obs)
        running.append(~env.done)
        obs, _, _, _ = env.step(policy(obs))
    return np.stack(observations, axis=1), np.stack(running, axis=1)


def test_observations_round_trip_and_are_in_the_tracks_frame():
    state = mm.start_states(np.random.default_rng(0), 6)
    obs = mm.observe(state)
    assert obs.shape == (6, mm.OBS_DIM) and obs.dtype == np.float32
    back = mm.state_of(obs)
    assert np.allclose(back[:, :2], state[:, :2], atol=1e-4) and np.allclose(rt.wrap(back[:, 2] - state[:, 2]), 0, atol=1e-5)
    offset, heading_error, phi = rt.track_frame(state)
    assert np.allclose(obs[:, 0], offset, atol=1e-6) and np.allclose(obs[:, 1], heading_error, atol=1e-6)
    arc = obs[:, 2] * mm.ARC_SCALE
    assert np.all(arc < 0) and np.all(arc > -mm.START_WINDOW[0] * 12), "episodes start a few metres before the obstacle"


def test_swerve_profile_slope_is_its_derivative():
    arc, h = np.linspace(-6, 6, 121), 1e-6
    offset, slope = mm.swerve_profile(arc)
    numeric = (mm.swerve_profile(arc + h)[0] - mm.swerve_profile(arc - h)[0]) / (2 * h)
    assert np.allclose(slope, numeric, atol=1e-5)
    assert offset.max() == pytest.approx(mm.SWERVE_OFFSET) and offset[0] == 0 and offset[-1] == 0


def test_the_expert_passes_on_its_side_and_the_average_driver_crashes():
    sides = np.array([1, -1, 1, -1, -1, 1])
    obs, mask = drive(mm.ObstacleExpert(sides).act, 6, seed=3)
    assert mask.sum(axis=1).tolist() == [mm.HORIZON] * 6, "the expert succeeds on both sides"
    assert mm.passing_sides(obs, mask).tolist() == sides.tolist()
    obs, mask = drive(mm.ObstacleExpert(0.0).act, 6, seed=3)          # the two sides' average: straight on
    assert (mask.sum(axis=1) < mm.HORIZON).all() and (mm.passing_sides(obs, mask) == mm.NOT_PASSED).all()


def test_the_batched_environment_is_seeded_per_episode_and_ended_episodes_stay_put():
    a, b = mm.ObstacleTracks(3, seed=7), mm.ObstacleTracks(5, seed=7)
    assert np.array_equal(a.reset(), b.reset()[:3]), "episode i depends only on seed + i"
    steer = np.full((5, 1), 1.0, dtype=np.float32)
    for _ in range(40):
        obs, rewards, terminated, truncated = b.step(steer)
    assert terminated.all() and not truncated.any(), "hard steering leaves the track"
    frozen = b.state.copy()
    obs2, rewards2, _, _ = b.step(steer)
    assert np.array_equal(b.state, frozen) and np.all(rewards2 == 0) and np.array_equal(obs2, obs)


def test_make_chunks_takes_the_next_actions_within_each_episode():
    obs = np.arange(7, dtype=np.float32)[:, None] * np.ones((1, mm.OBS_DIM), dtype=np.float32)
    actions = np.arange(7, dtype=np.float32)[:, None]
    o, chunks = mm.make_chunks(obs, actions, np.array([4, 3]), horizon=3)
    assert o.shape == (7, mm.OBS_DIM) and chunks.shape == (7, 3, 1)
    assert chunks[:, :, 0].tolist() == [[0, 1, 2], [1, 2, 3], [2, 3, 3], [3, 3, 3], [4, 5, 6], [5, 6, 6], [6, 6, 6]]


def test_networks_shapes_standardisation_and_sampling():
    obs = torch.randn(9, mm.OBS_DIM)
    stats = {"obs_mean": np.ones(mm.OBS_DIM), "obs_std": np.full(mm.OBS_DIM, 2.0)}
    reg = mm.ChunkRegressor(horizon=4, **stats)
    assert reg(obs).shape == (9, 4, 1) and torch.allclose(reg.standardise(obs), (obs - 1) / 2)
    mix = mm.MixtureNet(horizon=3, n_components=4, **stats)
    logits, means, log_stds = mix(obs)
    assert logits.shape == (9, 4) and means.shape == log_stds.shape == (9, 4, 3)
    assert mix.sample(obs, torch.Generator().manual_seed(0)).shape == (9, 3, 1)
    vel = mm.VelocityNet(horizon=5, **stats)
    assert vel(torch.randn(9, 5, 1), torch.rand(9), obs).shape == (9, 5, 1)


def test_fit_lowers_a_regression_loss_and_is_reproducible():
    x = torch.randn(256, mm.OBS_DIM)
    y = (x[:, :1] * 2 - x[:, 1:2])[:, None, :]
    histories, threads = [], torch.get_num_threads()
    torch.set_num_threads(1)   # a tiny network: one thread is fastest, and the machine is shared
    try:
        for _ in range(2):
            torch.manual_seed(0)
            model = mm.ChunkRegressor(horizon=1, hidden=(16,))
            histories.append(mm.fit(model, lambda i, g: ((model(x[i]) - y[i]) ** 2).mean(), 256, 60, batch_size=64,
                                    lr=1e-2))
    finally:
        torch.set_num_threads(threads)
    assert histories[0] == histories[1]
    assert np.mean(histories[0][-10:]) < 0.2 * np.mean(histories[0][:10])


def test_pictures_and_frames():
    obs, mask = drive(mm.ObstacleExpert(np.array([1, -1])).act, 2, seed=0)
    paths = mm.paths(obs, mask)
    assert [p.shape for p in paths] == [(mm.HORIZON, 2)] * 2
    ax = mm.plot_scene()
    mm.plot_sided_paths(ax, paths, mm.passing_sides(obs, mask))
    frames = mm.render_frames([p[:20] for p in paths], size=100, every=5)
    assert frames.shape == (4, 100, 100, 3) and frames.dtype == np.uint8 and frames.std() > 0


def expert_chunk(state, side, task, horizon):
    """The expert's next ``horizon`` actions from ``state`` on a noise-free track (the bench's open-loop ceiling)."""
    expert, actions = mm.ObstacleExpert(side, task=task), []
    for _ in range(horizon):
        action = expert.act(mm.observe(state))
        actions.append(action)
        state, _ = rt.step_states(state, action[:, 0], np.zeros(len(state)))
    return np.stack(actions, axis=1)


def test_the_default_task_is_the_module_constants_and_commit_tasks_differ_only_as_stated():
    task = mm.CLOSED_LOOP
    assert (task.horizon, task.steer_noise, task.start_window, task.swerve_start, task.swerve_rise) == (
        mm.HORIZON, mm.STEER_NOISE, mm.START_WINDOW, mm.SWERVE_START, mm.SWERVE_RISE)
    rises = [t.swerve_rise for t in mm.COMMIT_TASKS.values()]
    assert list(mm.COMMIT_TASKS) == ["sharp", "medium", "gentle"] and rises == sorted(rises) and len(set(rises)) == 3
    others = {(t.start_window, t.steer_noise, t.horizon, t.swerve_start, t.swerve_offset) for t in mm.COMMIT_TASKS.values()}
    assert len(others) == 1, "the three settings differ only in the swerve's rise"
    a, b = mm.ObstacleTracks(4, 3), mm.ObstacleTracks(4, 3, mm.CLOSED_LOOP)
    assert np.array_equal(a.reset(), b.reset())


@pytest.mark.parametrize("name", list(mm.COMMIT_TASKS))
def test_on_the_commit_tasks_the_split_is_at_the_first_state_and_the_mean_chunk_hits_the_obstacle(name):
    task = mm.COMMIT_TASKS[name]
    state = mm.start_states(np.random.default_rng(1), 50, task)
    obs = mm.observe(state)
    arc = obs[:, 2] * mm.ARC_SCALE
    assert np.all(arc >= task.swerve_start - 0.05), "episodes start where the demonstrators have begun to swerve"
    assert np.all(mm.open_loop_offsets(obs, np.zeros((50, 0, 1))) == pytest.approx(obs[:, 0], abs=1e-5))
    left, right = expert_chunk(state, 1.0, task, 8), expert_chunk(state, -1.0, task, 8)
    assert np.all((left - right)[:, :2, 0].mean(axis=1) > 0.2), "the two sides' first actions already differ"
    assert np.all(mm.open_loop_offsets(obs, left) > mm.OBSTACLE_RADIUS)
    assert np.all(mm.open_loop_offsets(obs, right) < -mm.OBSTACLE_RADIUS)
    mean = mm.open_loop_offsets(obs, (left + right) / 2)
    assert np.all(np.abs(mean) < mm.OBSTACLE_RADIUS), "the average of the two chunks leads into the obstacle's width"
    sides = np.random.default_rng(2).choice([1, -1], size=20)
    obs, mask = drive(mm.ObstacleExpert(sides, task=task).act, 20, 5, task)
    assert mask.sum(axis=1).tolist() == [task.horizon] * 20 and mm.passing_sides(obs, mask).tolist() == sides.tolist()


def test_the_averaging_results_are_recorded_per_seed_for_every_setting():
    import json
    from pathlib import Path

    record = json.loads((Path(__file__).resolve().parents[2] / "bench" / "results" / "hw1b_multimodal.json").read_text())
    assert {"policies", "budgets"} <= set(record), "the main table's entries are kept"
    entry = record["averaging"]
    assert [s["name"] for s in entry["settings"]] == list(mm.COMMIT_TASKS)
    assert {"commit", "date", "load", "machine"} <= set(entry["meta"])
    for setting in entry["settings"]:
        for key in ("expert", "expert_chunks", "l2", "flow", "flow_left", "mixture", "l2_one_step"):
            values = setting[key]
            assert len(values) == len(entry["protocol"]["seeds"]) == 5
            assert all(v is None or 0.0 <= v <= 1.0 for v in values), (setting["name"], key)
