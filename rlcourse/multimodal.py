"""When demonstrators disagree: the race track with an obstacle on its centre line (hw1b).

The car, the track and the dynamics are :mod:`rlcourse.racetrack`'s. A round obstacle of radius
``OBSTACLE_RADIUS`` sits on the centre line at polar angle ``OBSTACLE_PHI``. An episode starts near
the centre line a little before the obstacle (``START_WINDOW`` radians of polar angle before it) and
lasts ``HORIZON`` steps, most of a lap; it ends early (``terminated``) when the car touches the
obstacle or leaves the track. A **success** is an episode that runs its ``HORIZON`` steps: it passed
the obstacle without touching it and stayed on the track.

The scripted :class:`ObstacleExpert` drives the centre line and swerves round the obstacle on one
side, ``side = +1`` (left, the inside of the loop) or ``-1`` (right), along a quick swerve to a lateral
offset of ``side * SWERVE_OFFSET`` half-widths that starts ``-SWERVE_START`` before the obstacle. The
demonstrations (``datasets/hw1b/demos.npz``, made by ``datasets/scripts/make_multimodal_demos.py``)
draw the side by a fair coin per episode, which the observation does not show: at the same state,
before the swerve starts, half the demonstrators steer left and half right. A regression clone learns
the average of the two, which is straight into the obstacle.

Given building blocks (the stubs of hw1b are written in its notebook, never here): the environment,
the expert, :func:`passing_sides` (which side each episode passed on), :func:`make_chunks` (the
expert's next ``H`` actions from every state), three small networks (:class:`ChunkRegressor`,
:class:`MixtureNet`, :class:`VelocityNet`), a minibatch trainer that takes the loss as an argument
(:func:`fit`), and pictures and video frames of the track.

The environment is vectorised (:class:`ObstacleTracks`, a batch of seeded episodes stepped together)
rather than a gymnasium environment: policies here plan chunks of actions for the whole batch at once.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import matplotlib.pyplot as plt
import numpy as np
import torch
from torch import nn

from rlcourse import racetrack as rt
from rlcourse.nets import mlp

OBS_DIM, ACT_DIM = 5, rt.ACT_DIM
OBSTACLE_PHI = 0.0         # polar angle of the obstacle's centre (on the centre line)
OBSTACLE_RADIUS = 0.35     # world units (the track is 2 * rt.HALF_WIDTH = 2 wide)
SWERVE_OFFSET = 0.6        # the expert's lateral offset when it passes the obstacle, in half-widths
SWERVE_START = -4.5        # the expert starts to swerve this far (arc length) before the obstacle's centre,
SWERVE_RISE = 3.0          # is fully out after this much more arc,
SWERVE_HOLD = 1.0          # holds the offset until this far past the centre,
SWERVE_FALL = 4.0          # and comes back to the centre line over this much arc
START_WINDOW = (0.7, 0.5)  # episodes start between 0.7 and 0.5 radians of polar angle before the obstacle
HORIZON = 100              # steps per episode (50 units of arc, most of a lap)
STEER_NOISE = 0.04         # heading noise per step (radians): twice the race track's, so demonstrations show recoveries
START_NOISE = (0.05, 0.03)  # standard deviations of the starting offset (half-widths) and heading error (radians)
ARC_SCALE = 10.0           # the observation's arc length to the obstacle is divided by this
LEFT, RIGHT, NOT_PASSED = 1, -1, 0


@dataclass(frozen=True)
class ObstacleTask:
    """One version of the obstacle track: where episodes start, how long they last, how noisy the steering is and
    how the demonstrators swerve. The defaults are the module's constants (:data:`CLOSED_LOOP`, the notebook's
    main task); :data:`COMMIT_TASKS` are the versions where the demonstrators split at the very first step."""

    name: str = "closed loop"
    start_window: tuple[float, float] = START_WINDOW   # radians of polar angle before the obstacle (far, near)
    start_noise: tuple[float, float] = START_NOISE     # std of the starting offset (half-widths) and heading error
    steer_noise: float = STEER_NOISE                   # heading noise per step, radians
    horizon: int = HORIZON                             # steps per episode
    swerve_start: float = SWERVE_START                 # the swerve's profile, in arc length (see swerve_profile)
    swerve_rise: float = SWERVE_RISE
    swerve_hold: float = SWERVE_HOLD
    swerve_fall: float = SWERVE_FALL
    swerve_offset: float = SWERVE_OFFSET


CLOSED_LOOP = ObstacleTask()
# Where averaging bites: every episode starts where the demonstrators begin to swerve, about 4.5 units of arc (9
# steps) before the obstacle, so the very first observation is the one where they split 50/50; 30 steps, past the
# obstacle and back to the centre line. The steering noise is the race track's own (half of CLOSED_LOOP's) and
# the swerve a little narrower (0.55), so that chunks of 8 actions can be driven open loop: the expert's own
# chunks, planned without noise and driven open loop, succeed in 98.7 to 99.4% of episodes (0.93 to 0.96 at
# offset 0.65). The three versions differ only in how fast the demonstrators swerve out (the arc over which the
# offset rises): the protocol's three settings, fixed with these numbers before any learner was trained.
COMMIT_START_WINDOW = (0.56, 0.50)   # polar angle before the obstacle: arc_to_obstacle from about -4.75 to -4.25
_COMMIT = ObstacleTask(name="commit", start_window=COMMIT_START_WINDOW, steer_noise=rt.STEER_NOISE, horizon=30,
                       swerve_start=-4.75, swerve_offset=0.55)
COMMIT_TASKS = {name: replace(_COMMIT, name=name, swerve_rise=rise)
                for name, rise in (("sharp", 2.0), ("medium", 3.0), ("gentle", 4.0))}


# ---------------------------------------------------------------- geometry

def obstacle_centre() -> np.ndarray:
    """The obstacle's centre ``(2,)``."""
    return rt.centre_line(np.array(OBSTACLE_PHI))


def arc_to_obstacle(phi: np.ndarray) -> np.ndarray:
    """Signed arc length along the centre line from the obstacle to polar angle ``phi`` (negative before it)."""
    return rt.wrap(np.asarray(phi) - OBSTACLE_PHI) * rt.arc_speed(np.asarray(phi))


def _smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3x^2 - 2x^3 on [0, 1] (0 before, 1 after) and its derivative."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x), 6 * x * (1 - x)


def swerve_profile(arc: np.ndarray, task: ObstacleTask = CLOSED_LOOP) -> tuple[np.ndarray, np.ndarray]:
    """The expert's target path for side +1: lateral offset (half-widths) and its slope d offset / d arc, at ``arc``.

    The offset rises from 0 to ``task.swerve_offset`` between ``task.swerve_start`` and ``swerve_start +
    swerve_rise`` of arc (before the obstacle), holds past it until ``swerve_hold``, and falls back to the centre
    line over ``swerve_fall``.
    """
    arc = np.asarray(arc, dtype=float)
    rise, d_rise = _smoothstep((arc - task.swerve_start) / task.swerve_rise)
    fall, d_fall = _smoothstep((arc - task.swerve_hold) / task.swerve_fall)
    offset = task.swerve_offset * rise * (1 - fall)
    slope = task.swerve_offset * (d_rise / task.swerve_rise * (1 - fall) - rise * d_fall / task.swerve_fall)
    return offset, slope


def collided(state: np.ndarray) -> np.ndarray:
    """Whether cars ``(n, 3)`` touch the obstacle, ``(n,)`` bool."""
    return np.linalg.norm(state[:, :2] - obstacle_centre(), axis=-1) < OBSTACLE_RADIUS


def observe(state: np.ndarray) -> np.ndarray:
    """Observations ``(n, OBS_DIM)`` float32 of car states ``(n, 3)`` = (x, y, heading), in the track's frame:
    (lateral offset in half-widths, + = left; heading error, radians; signed arc length to the obstacle over
    ``ARC_SCALE``, negative before it; cos and sin of the polar angle)."""
    offset, heading_error, phi = rt.track_frame(np.asarray(state, dtype=np.float64))
    return np.column_stack([offset, heading_error, arc_to_obstacle(phi) / ARC_SCALE,
                            np.cos(phi), np.sin(phi)]).astype(np.float32)


def state_of(obs: np.ndarray) -> np.ndarray:
    """Car states ``(n, 3)`` back from observations ``(n, OBS_DIM)``."""
    obs = np.asarray(obs, dtype=np.float64)
    phi = np.arctan2(obs[:, 4], obs[:, 3])
    r, _, _ = rt._radius(phi)
    distance = r - rt.HALF_WIDTH * obs[:, 0]
    return np.column_stack([distance * np.cos(phi), distance * np.sin(phi), rt.track_heading(phi) + obs[:, 1]])


def start_states(rng: np.random.Generator, n: int, task: ObstacleTask = CLOSED_LOOP) -> np.ndarray:
    """``n`` car states ``(n, 3)`` near the centre line, ``task.start_window`` before the obstacle."""
    phi = OBSTACLE_PHI - rng.uniform(task.start_window[1], task.start_window[0], size=n)
    normal_in = -rt.centre_line(phi) / np.linalg.norm(rt.centre_line(phi), axis=-1, keepdims=True)
    position = rt.centre_line(phi) + (task.start_noise[0] * rt.HALF_WIDTH * rng.normal(size=n))[:, None] * normal_in
    heading = rt.track_heading(phi) + task.start_noise[1] * rng.normal(size=n)
    return np.column_stack([position, heading])


# ---------------------------------------------------------------- the environment and its expert

class ObstacleTracks:
    """A batch of ``n_envs`` episodes on the obstacle track, stepped together (vectorised numpy).

    Episode ``i`` draws its start and its steering noise from ``np.random.default_rng(seed + i)``, so a seed
    fixes every episode whatever the policy. ``reset()`` returns the first observations ``(n_envs, OBS_DIM)``
    float32; ``step(actions)`` takes ``(n_envs, ACT_DIM)`` actions (clipped to [-1, 1]) and returns
    ``(obs, rewards, terminated, truncated)``: observations ``(n_envs, OBS_DIM)``, rewards ``(n_envs,)``
    (progress along the centre line over the speed, about 1 per step), and two ``(n_envs,)`` bool arrays
    (the car touched the obstacle or left the track; the episode reached ``task.horizon`` steps). A car whose
    episode has ended stays where it is, earns 0 and keeps reporting the flag that ended it. ``done``
    ``(n_envs,)`` is True for the episodes that have ended. ``task`` picks the version of the track
    (:class:`ObstacleTask`; the default is the notebook's main one).
    """

    def __init__(self, n_envs: int, seed: int, task: ObstacleTask = CLOSED_LOOP) -> None:
        self.n_envs, self.seed, self.task = int(n_envs), int(seed), task
        self.state = np.zeros((self.n_envs, 3))
        self.reset()

    def reset(self) -> np.ndarray:
        """Start every episode again from its seeded start; the first observations ``(n_envs, OBS_DIM)``."""
        self._rngs = [np.random.default_rng(self.seed + i) for i in range(self.n_envs)]
        self.state = np.concatenate([start_states(rng, 1, self.task) for rng in self._rngs])
        self.t = 0
        self.terminated = np.zeros(self.n_envs, dtype=bool)
        self.truncated = np.zeros(self.n_envs, dtype=bool)
        return observe(self.state)

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        actions = np.asarray(actions, dtype=float).reshape(self.n_envs, ACT_DIM)[:, 0]
        running = ~self.done
        noise = np.array([rng.normal() for rng in self._rngs]) * (self.task.steer_noise / rt.STEER_NOISE)
        moved, progress = rt.step_states(self.state, actions, noise)   # the race track's step, more noise
        self.state = np.where(running[:, None], moved, self.state)
        self.t += 1
        crashed = collided(self.state) | (np.abs(rt.track_frame(self.state)[0]) > 1.0)
        self.terminated = self.terminated | (running & crashed)
        self.truncated = self.truncated | (running & ~crashed & (self.t >= self.task.horizon))
        rewards = np.where(running, progress, 0.0).astype(np.float32)
        return observe(self.state), rewards, self.terminated.copy(), self.truncated.copy()


class ObstacleExpert:
    """The scripted driver that passes the obstacle on ``side`` (+1 left, -1 right; one per episode).

    ``side`` is a number or an array ``(n,)``, one per row of the observations it will be asked about
    (the episodes of a batched rollout). ``act(obs)`` maps ``(n, OBS_DIM)`` to ``(n, ACT_DIM)`` float32 in
    ``[-1, 1]``: the race track's expert, steering towards the swerving target path instead of the
    centre line. Deterministic given ``side``. ``task`` gives the swerve's profile (:class:`ObstacleTask`).
    """

    def __init__(self, side, heading_gain: float = 0.8, offset_gain: float = 0.6,
                 task: ObstacleTask = CLOSED_LOOP) -> None:
        self.side, self.task = np.asarray(side, dtype=float), task
        self.heading_gain, self.offset_gain = heading_gain, offset_gain

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        flat = obs.reshape(-1, OBS_DIM)
        offset, heading_error, phi = flat[:, 0], flat[:, 1], np.arctan2(flat[:, 4], flat[:, 3])
        ahead = phi + 0.5 * rt.SPEED / rt.arc_speed(phi)
        target, slope = swerve_profile(arc_to_obstacle(ahead), self.task)
        side = np.broadcast_to(self.side.reshape(-1), offset.shape) if self.side.size > 1 else self.side.reshape(())
        target_heading = np.arctan(side * slope * rt.HALF_WIDTH)   # the target path's heading error
        turn = (rt.SPEED * rt.curvature(ahead) - self.heading_gain * (heading_error - target_heading)
                - self.offset_gain * rt.HALF_WIDTH * (offset - side * target))
        return np.clip(turn / rt.MAX_TURN, -1.0, 1.0).astype(np.float32).reshape(obs.shape[:-1] + (ACT_DIM,))

    __call__ = act


def passing_sides(obs: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Which side each episode passed the obstacle on: ``LEFT`` (+1), ``RIGHT`` (-1) or ``NOT_PASSED`` (0).

    obs ``(n, T, OBS_DIM)`` and mask ``(n, T)`` as in :class:`rlcourse.rollouts.Episodes`. An episode passed
    when two consecutive real observations straddle the obstacle's polar angle; the side is the sign of
    the lateral offset there (the mean of the two). Episodes that ended before it count as ``NOT_PASSED``.
    Returns ``(n,)`` int64.
    """
    obs, mask = np.asarray(obs, dtype=np.float64), np.asarray(mask, dtype=bool)
    n, T = mask.shape
    offset, rel = obs[..., 0], rt.wrap(np.arctan2(obs[..., 4], obs[..., 3]) - OBSTACLE_PHI)
    crossing = (rel[:, :-1] < 0) & (rel[:, 1:] >= 0) & (np.abs(rel[:, 1:] - rel[:, :-1]) < 1.0) & mask[:, 1:]
    sides = np.zeros(n, dtype=np.int64)
    for i in np.flatnonzero(crossing.any(axis=1)):
        t = int(np.argmax(crossing[i]))
        sides[i] = LEFT if offset[i, t] + offset[i, t + 1] >= 0 else RIGHT
    return sides


def open_loop_offsets(obs: np.ndarray, chunks: np.ndarray) -> np.ndarray:
    """Where chunks lead: the lateral offset (half-widths) after driving each chunk ``(n, H, ACT_DIM)`` from its
    observation ``(n, OBS_DIM)`` on a noise-free track, ``(n,)``. A picture of what a plan commits to."""
    state = state_of(obs)
    chunks = np.asarray(chunks, dtype=float)
    for j in range(chunks.shape[1]):
        state, _ = rt.step_states(state, chunks[:, j, 0], np.zeros(len(state)))
    return rt.track_frame(state)[0]


# ---------------------------------------------------------------- data

def make_chunks(obs: np.ndarray, actions: np.ndarray, lengths: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Every state of flat demonstrations with the next ``horizon`` expert actions from it.

    obs ``(N, obs_dim)``, actions ``(N, act_dim)`` stored episode after episode with ``lengths`` ``(E,)``.
    Returns obs ``(N, obs_dim)`` float32 and chunks ``(N, horizon, act_dim)`` float32, where
    ``chunks[i, j]`` is the action ``j`` steps after state ``i`` in its episode, repeating the episode's
    last action past its end.
    """
    obs, actions = np.asarray(obs, dtype=np.float32), np.asarray(actions, dtype=np.float32)
    starts = np.r_[0, np.cumsum(lengths)[:-1]].astype(np.int64)
    ends = np.repeat(starts + np.asarray(lengths, dtype=np.int64) - 1, lengths)    # last index of each step's episode
    index = np.minimum(np.arange(len(obs))[:, None] + np.arange(horizon)[None, :], ends[:, None])
    return obs, actions[index]


# ---------------------------------------------------------------- networks

class Standardise(nn.Module):
    """``(obs - mean) / std`` with fixed statistics (buffers, saved with the network, never trained)."""

    def __init__(self, mean=None, std=None, dim: int = OBS_DIM) -> None:
        super().__init__()
        mean = torch.zeros(dim) if mean is None else torch.as_tensor(np.asarray(mean), dtype=torch.float32)
        std = torch.ones(dim) if std is None else torch.as_tensor(np.asarray(std), dtype=torch.float32)
        self.register_buffer("mean", mean.clone())
        self.register_buffer("std", std.clamp_min(1e-3).clone())

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - self.mean) / self.std


def obs_statistics(obs: np.ndarray) -> dict[str, np.ndarray]:
    """``{"obs_mean": ..., "obs_std": ...}`` of observations ``(N, OBS_DIM)``, for the networks' ``**`` arguments."""
    return {"obs_mean": np.mean(obs, axis=0), "obs_std": np.std(obs, axis=0)}


class ChunkRegressor(nn.Module):
    """A deterministic policy: observation ``(n, obs_dim)`` to a chunk of actions ``(n, horizon, act_dim)``."""

    def __init__(self, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, horizon: int = 1,
                 hidden: tuple[int, ...] = (128, 128), obs_mean=None, obs_std=None) -> None:
        super().__init__()
        self.act_dim, self.horizon = act_dim, horizon
        self.standardise = Standardise(obs_mean, obs_std, obs_dim)
        self.net = mlp([obs_dim, *hidden, horizon * act_dim], activation="relu")

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(self.standardise(obs)).reshape(obs.shape[:-1] + (self.horizon, self.act_dim))


class MixtureNet(nn.Module):
    """A Gaussian mixture over chunks: ``forward(obs)`` gives (logits ``(n, M)``, means ``(n, M, D)``,
    log_stds ``(n, M, D)``), with ``M = n_components`` and ``D = horizon * act_dim`` (a chunk, flattened).
    ``sample`` draws a component by its weight, then a chunk from it (or its mean)."""

    def __init__(self, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, horizon: int = 1, n_components: int = 5,
                 hidden: tuple[int, ...] = (128, 128), obs_mean=None, obs_std=None) -> None:
        super().__init__()
        self.act_dim, self.horizon, self.n_components = act_dim, horizon, n_components
        self.dim = horizon * act_dim
        self.standardise = Standardise(obs_mean, obs_std, obs_dim)
        self.net = mlp([obs_dim, *hidden, n_components * (1 + 2 * self.dim)], activation="relu")

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        out = self.net(self.standardise(obs))
        M, D = self.n_components, self.dim
        logits, means, log_stds = out[..., :M], out[..., M:M + M * D], out[..., M + M * D:]
        shape = obs.shape[:-1] + (M, D)
        return logits, means.reshape(shape), log_stds.reshape(shape).clamp(-7.0, 2.0)

    @torch.no_grad()
    def sample(self, obs: torch.Tensor, generator: torch.Generator | None = None, noise: bool = True) -> torch.Tensor:
        """Chunks ``(n, horizon, act_dim)`` for observations ``(n, obs_dim)``."""
        logits, means, log_stds = self(obs)
        k = torch.multinomial(torch.softmax(logits, -1), 1, generator=generator)[:, 0]
        rows = torch.arange(len(k))
        chunk = means[rows, k]
        if noise:
            chunk = chunk + log_stds[rows, k].exp() * torch.randn(chunk.shape, generator=generator)
        return chunk.reshape(-1, self.horizon, self.act_dim)


class VelocityNet(nn.Module):
    """A velocity field ``v(a_t, t | obs)`` over chunks: ``forward(a_t, t, obs)`` with ``a_t`` ``(n, horizon,
    act_dim)``, ``t`` ``(n,)`` in [0, 1] and ``obs`` ``(n, obs_dim)`` gives a velocity shaped like ``a_t``."""

    def __init__(self, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM, horizon: int = 8,
                 hidden: tuple[int, ...] = (128, 128, 128), n_frequencies: int = 4, obs_mean=None,
                 obs_std=None) -> None:
        super().__init__()
        self.act_dim, self.horizon = act_dim, horizon
        self.standardise = Standardise(obs_mean, obs_std, obs_dim)
        self.register_buffer("frequencies", torch.pi * 2.0 ** torch.arange(n_frequencies, dtype=torch.float32))
        self.net = mlp([obs_dim + horizon * act_dim + 1 + 2 * n_frequencies, *hidden, horizon * act_dim], "relu")

    def forward(self, a_t: torch.Tensor, t: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
        t = t.reshape(-1, 1).to(a_t.dtype)
        features = torch.cat([self.standardise(obs), a_t.reshape(len(a_t), -1), t, torch.sin(t * self.frequencies),
                              torch.cos(t * self.frequencies)], dim=-1)
        return self.net(features).reshape(a_t.shape)


def fit(model: nn.Module, batch_loss: Callable[[np.ndarray, torch.Generator], torch.Tensor], n_samples: int,
        n_steps: int, batch_size: int = 256, lr: float = 1e-3, seed: int = 0) -> list[float]:
    """Minibatch Adam on ``model``'s parameters, in place; returns the loss of every step.

    ``batch_loss(index, generator)`` returns the scalar loss of the samples ``index`` (an ``(batch_size,)``
    int array drawn with replacement from ``range(n_samples)``); ``generator`` is a seeded torch generator
    for any noise the loss draws (flow matching's ``a_0`` and ``t``), so a seed fixes the whole run.
    """
    rng = np.random.default_rng(seed)
    generator = torch.Generator().manual_seed(seed)
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=max(n_steps, 1), eta_min=lr / 10)
    history = []
    for _ in range(n_steps):
        loss = batch_loss(rng.integers(0, n_samples, size=batch_size), generator)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        history.append(float(loss.item()))
    return history


# ---------------------------------------------------------------- paths, pictures and video

def paths(obs: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """The (x, y) positions of each episode's real steps: a list of ``(lengths[i], 2)`` arrays.

    obs ``(n, T, OBS_DIM)`` and mask ``(n, T)`` as a rollout returns them.
    """
    obs, mask = np.asarray(obs), np.asarray(mask, dtype=bool)
    return [state_of(o[m])[:, :2] for o, m in zip(obs, mask)]


def plot_scene(ax: plt.Axes | None = None, zoom: bool = True) -> plt.Axes:
    """Draw the track and the obstacle; ``zoom`` shows only the stretch round the obstacle."""
    ax = rt.plot_track(ax)
    ax.add_patch(plt.Circle(tuple(obstacle_centre()), OBSTACLE_RADIUS, color="dimgrey", zorder=3))
    if zoom:
        x, y = obstacle_centre()
        ax.set_xlim(x - 5.5, x + 2.5)
        ax.set_ylim(y - 9.0, y + 7.0)
    return ax


SIDE_COLOURS = {LEFT: "tab:blue", RIGHT: "tab:orange", NOT_PASSED: "tab:red"}


def plot_sided_paths(ax: plt.Axes, paths: list[np.ndarray], sides: np.ndarray, horizon: int = HORIZON) -> None:
    """Draw paths coloured by the side they passed on (blue left, orange right, red: crashed before it); a path
    shorter than ``horizon`` steps ended early and gets a red cross."""
    for path, side in zip(paths, sides):
        ax.plot(path[:, 0], path[:, 1], color=SIDE_COLOURS[int(side)], linewidth=0.8, alpha=0.7)
        if len(path) < horizon:  # ended early: it crashed
            ax.plot(path[-1, 0], path[-1, 1], marker="x", color="tab:red", markersize=6)


def render_frames(paths: list[np.ndarray], size: int = 200, every: int = 2, horizon: int = HORIZON) -> np.ndarray:
    """Frames ``(n, size, size, 3)`` uint8 of cars driving ``paths`` (one dot each, with a short trail).

    One frame every ``every`` steps; a car that stopped before ``horizon`` steps stays where it stopped, marked red.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = plt.Figure(figsize=(size / 50, size / 50), dpi=50)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    plot_scene(ax)
    dots = [ax.plot([], [], "o", color="black", markersize=5, zorder=4)[0] for _ in paths]
    trails = [ax.plot([], [], color="tab:green", linewidth=1.2, zorder=2)[0] for _ in paths]
    frames = []
    for t in range(0, max(len(p) for p in paths), every):
        for dot, trail, path in zip(dots, trails, paths):
            s = min(t, len(path) - 1)
            dot.set_data([path[s, 0]], [path[s, 1]])
            dot.set_color("tab:red" if len(path) < horizon and s == len(path) - 1 else "black")
            trail.set_data(path[max(0, s - 12):s + 1, 0], path[max(0, s - 12):s + 1, 1])
        canvas.draw()
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return np.stack(frames)
