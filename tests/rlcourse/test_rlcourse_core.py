"""rlcourse's shared pieces: policies, seeding, rollouts, plots and video."""
from __future__ import annotations

import math

import matplotlib
import numpy as np
import torch

matplotlib.use("Agg")

from rlcourse.nets import GaussianPolicy, load_policy, mlp, save_policy  # noqa: E402
from rlcourse.plots import plot_curves  # noqa: E402
from rlcourse.rollouts import evaluate, rollout  # noqa: E402
from rlcourse.seeding import seed_everything  # noqa: E402
from rlcourse.video import render_rollout, save_mp4, show_video, side_by_side  # noqa: E402


def test_gaussian_log_prob_matches_the_density_formula():
    torch.manual_seed(0)
    policy = GaussianPolicy(4, 3, hidden=(8,), log_std_init=-0.3)
    obs, act = torch.randn(5, 4), torch.randn(5, 3)
    mean, std = policy(obs), policy.log_std.exp()
    by_hand = (-0.5 * ((act - mean) / std) ** 2 - torch.log(std) - 0.5 * math.log(2 * math.pi)).sum(-1)
    assert torch.allclose(policy.log_prob(obs, act), by_hand, atol=1e-6)


def test_squashed_policies_act_in_the_unit_box_and_save_load_round_trips(tmp_path):
    policy = GaussianPolicy(3, 2, hidden=(16, 16), activation="relu", squash=True)
    with torch.no_grad():
        policy.mean.bias.fill_(50.0)
    obs = np.random.default_rng(0).normal(size=(7, 3)).astype(np.float32)
    assert np.all(np.abs(policy.act(obs)) <= 1.0)
    save_policy(policy, tmp_path / "p.pt", steps=10)
    loaded = load_policy(tmp_path / "p.pt")
    assert np.array_equal(loaded.act(obs), policy.act(obs)) and loaded.metadata == {"steps": 10}
    assert [type(m).__name__ for m in mlp([3, 4, 5], "tanh")] == ["Linear", "Tanh", "Linear"]


def test_seed_everything_reproduces_torch_and_numpy():
    a = (seed_everything(3).normal(), torch.randn(2), np.random.rand())
    b = (seed_everything(3).normal(), torch.randn(2), np.random.rand())
    assert a[0] == b[0] and torch.equal(a[1], b[1]) and a[2] == b[2]


def _zero_policy(obs):
    return np.zeros((obs.shape[0], 3), dtype=np.float32)


def test_seeded_rollouts_are_reproducible_and_masked():
    first = rollout(_zero_policy, "Hopper-v5", n_episodes=3, seed=5)
    second = rollout(_zero_policy, "Hopper-v5", n_episodes=3, seed=5)
    assert np.array_equal(first.obs, second.obs) and np.array_equal(first.returns, second.returns)
    assert first.mask.sum(1).tolist() == first.lengths.tolist()
    assert np.all(first.rewards[~first.mask] == 0)
    assert np.allclose(first.returns, [first.rewards[i, : n].sum() for i, n in enumerate(first.lengths)])
    obs, act = first.flat()
    assert obs.shape == (first.lengths.sum(), 11) and act.shape == (first.lengths.sum(), 3)
    other = rollout(_zero_policy, "Hopper-v5", n_episodes=3, seed=6)
    assert not np.array_equal(other.obs[:, 0], first.obs[:, 0])


def test_rollout_respects_max_steps_and_evaluate_summarises():
    short = rollout(_zero_policy, "Hopper-v5", n_episodes=2, seed=0, max_steps=7)
    assert short.obs.shape[1] <= 7 and short.lengths.max() <= 7
    mean, std = evaluate(_zero_policy, "Hopper-v5", n_episodes=2, seed=0, max_steps=7)
    assert np.isclose(mean, short.returns.mean()) and np.isclose(std, short.returns.std())


def test_plot_curves_draws_a_mean_line_and_a_band_over_seeds():
    x = np.arange(5)
    ax = plot_curves({"a": (x, np.vstack([x, x + 2])), "b": (x, x * 2.0)}, "step", "return", hlines={"expert": 3})
    assert len(ax.collections) == 1  # one band: only "a" has several seeds
    assert np.allclose(ax.lines[0].get_ydata(), x + 1)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["a (n=2)", "b"]


def test_headless_render_to_an_inline_mp4(tmp_path):
    frames = render_rollout(_zero_policy, "Hopper-v5", seed=0, seconds=0.4, size=64, fps=10)
    assert frames.dtype == np.uint8 and frames.shape[1:] == (64, 64, 3) and len(frames) >= 2
    assert frames.std() > 0, "frames are not blank"
    both = side_by_side([frames, frames[:1]])
    assert both.shape == (len(frames), 64, 128, 3)
    path = save_mp4(both, tmp_path / "clip.mp4", fps=10)
    assert path.stat().st_size > 1000 and path.read_bytes()[4:8] == b"ftyp"
    html = show_video(path)._repr_html_()
    assert "base64" in html and "<video" in html
