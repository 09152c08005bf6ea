"""A tiny 2-D race track where behaviour cloning drifts off and DAgger recovers (hw1).

A car drives at constant speed ``SPEED`` round a closed, curved track whose
centre line is the polar curve ``r(phi) = RADIUS * (1 + WOBBLE * sin(3 phi))``
(it bends both ways) and whose half-width, measured along the radius, is
``HALF_WIDTH``. The only control is the steering: an action ``a`` in
``[-1, 1]`` turns the car by ``a * MAX_TURN`` radians in one step, plus a
little Gaussian steering noise (``STEER_NOISE``), so no two laps are the same.
The episode ends (``terminated``) when the car leaves the track and is cut off
(``truncated``) after ``HORIZON`` steps, a little over two laps.

The car observes where it is and which way it points, ``(x / RADIUS,
y / RADIUS, cos heading, sin heading)``: nothing tells it directly how far it
is from the centre line. The reward is the progress along the centre line in
one step divided by the car's speed: about 1 per step on the track, so a
return is roughly the number of steps the car stayed on it.

The scripted :class:`Expert` steers with the track's curvature (feed-forward)
plus a correction of its heading error and of its offset from the centre line
(feedback), all computed from the observation, so it can label any state. It
holds the centre line so tightly that its demonstrations cover a thin band of
positions and headings; a clone fits the steering along that band and has no
data about what to do a little to either side of it, so its small errors grow
until it leaves the track. DAgger asks the expert exactly there.

Importing this module registers the environment as ``ENV_ID`` with gymnasium,
so :func:`rlcourse.rollouts.rollout` runs it like any MuJoCo task.
"""
from __future__ import annotations

from typing import Callable

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np

ENV_ID = "rlcourse/RaceTrack-v0"
RADIUS = 10.0        # mean radius of the centre line
WOBBLE = 0.15        # relative amplitude of the three-lobed bulge
HALF_WIDTH = 1.0     # the car is on the track while |offset| <= HALF_WIDTH
SPEED = 0.5          # distance driven per step
MAX_TURN = 0.25      # radians of heading change for action +1
STEER_NOISE = 0.02   # standard deviation of the heading noise per step, radians
START_NOISE = 0.01   # standard deviation of the starting offset (half-widths) and heading error (radians)
HORIZON = 300        # steps per episode: a little over two laps
OBS_DIM, ACT_DIM = 4, 1


# ---------------------------------------------------------------- geometry of the centre line

def _radius(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r(phi) and its first two derivatives."""
    s, c = np.sin(3 * phi), np.cos(3 * phi)
    return RADIUS * (1 + WOBBLE * s), 3 * RADIUS * WOBBLE * c, -9 * RADIUS * WOBBLE * s


def centre_line(phi: np.ndarray) -> np.ndarray:
    """Points of the centre line at polar angles ``phi``, shape ``phi.shape + (2,)``."""
    r, _, _ = _radius(phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def track_heading(phi: np.ndarray) -> np.ndarray:
    """Direction of travel (anticlockwise) of the centre line at ``phi``, in radians."""
    r, dr, _ = _radius(phi)
    tx, ty = dr * np.cos(phi) - r * np.sin(phi), dr * np.sin(phi) + r * np.cos(phi)
    return np.arctan2(ty, tx)


def curvature(phi: np.ndarray) -> np.ndarray:
    """Signed curvature of the centre line at ``phi`` (positive where it turns left)."""
    r, dr, ddr = _radius(phi)
    return (r**2 + 2 * dr**2 - r * ddr) / (r**2 + dr**2) ** 1.5


def arc_speed(phi: np.ndarray) -> np.ndarray:
    """Length of centre line per radian of polar angle, ``|dc/dphi|``."""
    r, dr, _ = _radius(phi)
    return np.sqrt(r**2 + dr**2)


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped into ``[-pi, pi)``."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def track_frame(state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where cars ``(n, 3)`` are relative to the track: lateral offset (half-widths, + = left), heading error, polar angle."""
    x, y, heading = state[:, 0], state[:, 1], state[:, 2]
    phi = np.arctan2(y, x)
    r, _, _ = _radius(phi)
    offset = (r - np.hypot(x, y)) / HALF_WIDTH  # inside the loop is left of anticlockwise travel
    return offset, wrap(heading - track_heading(phi)), phi


def observe(state: np.ndarray) -> np.ndarray:
    """Observations ``(n, OBS_DIM)`` float32 of car states ``(n, 3)`` = (x, y, heading)."""
    x, y, heading = state[:, 0], state[:, 1], state[:, 2]
    return np.column_stack([x / RADIUS, y / RADIUS, np.cos(heading), np.sin(heading)]).astype(np.float32)


def state_of(obs: np.ndarray) -> np.ndarray:
    """Car states ``(n, 3)`` back from observations ``(n, OBS_DIM)``."""
    obs = np.asarray(obs, dtype=np.float64)
    return np.column_stack([RADIUS * obs[:, 0], RADIUS * obs[:, 1], np.arctan2(obs[:, 3], obs[:, 2])])


def start_states(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` car states ``(n, 3)`` near the centre line at uniformly random places round the track."""
    phi = rng.uniform(-np.pi, np.pi, size=n)
    normal_in = -centre_line(phi) / np.linalg.norm(centre_line(phi), axis=-1, keepdims=True)
    position = centre_line(phi) + (START_NOISE * HALF_WIDTH * rng.normal(size=n))[:, None] * normal_in
    heading = track_heading(phi) + START_NOISE * rng.normal(size=n)
    return np.column_stack([position, heading])


def step_states(state: np.ndarray, action: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Next states ``(n, 3)`` and rewards ``(n,)`` for actions ``(n,)`` and standard-normal ``noise`` ``(n,)``."""
    heading = state[:, 2] + MAX_TURN * np.clip(action, -1.0, 1.0) + STEER_NOISE * noise
    position = state[:, :2] + SPEED * np.column_stack([np.cos(heading), np.sin(heading)])
    phi = np.arctan2(state[:, 1], state[:, 0])
    turned = wrap(np.arctan2(position[:, 1], position[:, 0]) - phi)  # polar angle covered in this step
    progress = turned * arc_speed(phi + turned / 2)                   # centre-line length covered
    return np.column_stack([position, heading]), progress / SPEED


# ---------------------------------------------------------------- the environment and its expert

class RaceTrackEnv(gym.Env):
    """One car on the track, as a gymnasium environment (see the module docstring for the spaces)."""

    metadata = {"render_modes": []}

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(OBS_DIM,), dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(ACT_DIM,), dtype=np.float32)
        self.state = np.zeros((1, 3))

    @property
    def position(self) -> np.ndarray:
        """The car's (x, y)."""
        return self.state[0, :2].copy()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.state = start_states(self.np_random, 1)
        return observe(self.state)[0], {}

    def step(self, action):
        noise = self.np_random.normal(size=1)
        self.state, progress = step_states(self.state, np.asarray(action, dtype=float).reshape(1), noise)
        obs = observe(self.state)[0]
        return obs, float(progress[0]), bool(abs(track_frame(self.state)[0][0]) > 1.0), False, {}


gym.register(ENV_ID, entry_point=RaceTrackEnv, max_episode_steps=HORIZON)


class Expert:
    """The scripted driver: feed-forward curvature plus feedback on heading error and offset.

    ``act(obs)`` maps observations ``(n, OBS_DIM)`` (or one ``(OBS_DIM,)``) to actions of the
    same leading shape with last dimension ``ACT_DIM``, float32, in ``[-1, 1]``. It is
    deterministic, so it can label any state a learner reaches.
    """

    def __init__(self, heading_gain: float = 0.5, offset_gain: float = 0.3) -> None:
        self.heading_gain, self.offset_gain = heading_gain, offset_gain

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float64)
        state = state_of(obs.reshape(-1, OBS_DIM))
        offset, heading_error, phi = track_frame(state)
        ahead = phi + 0.5 * SPEED / arc_speed(phi)  # the curvature half a step ahead, where the car turns
        turn = SPEED * curvature(ahead) - self.heading_gain * heading_error - self.offset_gain * HALF_WIDTH * offset
        return np.clip(turn / MAX_TURN, -1.0, 1.0).astype(np.float32).reshape(obs.shape[:-1] + (ACT_DIM,))

    __call__ = act


# ---------------------------------------------------------------- paths and pictures

def drive(policy: Callable[[np.ndarray], np.ndarray], n_episodes: int, seed: int) -> list[np.ndarray]:
    """The (x, y) path of each of ``n_episodes`` seeded episodes of ``policy``: a list of ``(T_i + 1, 2)`` arrays.

    Seeds ``seed, seed + 1, ...`` give the same episodes as :func:`rlcourse.rollouts.rollout` with ``seed``.
    """
    envs = [gym.make(ENV_ID) for _ in range(n_episodes)]
    obs = np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(envs)])
    paths = [[env.unwrapped.position] for env in envs]
    alive = np.ones(n_episodes, dtype=bool)
    while alive.any():
        actions = np.asarray(policy(obs), dtype=np.float32)
        for i in np.flatnonzero(alive):
            obs[i], _, terminated, truncated, _ = envs[i].step(actions[i])
            paths[i].append(envs[i].unwrapped.position)
            alive[i] = not (terminated or truncated)
    return [np.array(p) for p in paths]


def plot_track(ax: plt.Axes | None = None) -> plt.Axes:
    """Draw the track (its two edges and a dashed centre line) on equal axes."""
    ax = ax or plt.subplots(figsize=(4.5, 4.5))[1]
    phi = np.linspace(-np.pi, np.pi, 721)
    centre = centre_line(phi)
    inward = -centre / np.linalg.norm(centre, axis=-1, keepdims=True)
    for side in (-1, 1):
        edge = centre + side * HALF_WIDTH * inward
        ax.plot(edge[:, 0], edge[:, 1], color="black", linewidth=1.2)
    ax.plot(centre[:, 0], centre[:, 1], color="grey", linestyle="--", linewidth=0.6)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    return ax


def plot_paths(ax: plt.Axes, paths: list[np.ndarray], color: str, label: str) -> None:
    """Draw car paths in one colour with one legend entry; a cross marks where a car left the track."""
    for i, path in enumerate(paths):
        ax.plot(path[:, 0], path[:, 1], color=color, linewidth=1.0, alpha=0.8, label=label if i == 0 else None)
        if len(path) <= HORIZON:  # ended early: it left the track
            ax.plot(path[-1, 0], path[-1, 1], marker="x", color=color, markersize=7)
