"""Rollout videos: render a few seconds of an episode to MP4 and play it inline.

Rendering uses MuJoCo's EGL backend on Mesa's software renderer when there is
no display (see ``rlcourse/__init__.py``), at roughly 15 to 20 frames per second
at 480x480 on a laptop-class CPU, so clips are kept short and small.
"""
from __future__ import annotations

import ctypes.util
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Callable, Sequence

import gymnasium as gym

import rlcourse.mujoco_messages  # noqa: F401 - installs the handler that drops a warning students cannot act on
import numpy as np

EGL_PACKAGES = ["libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libgles2"]


def render_rollout(policy: Callable[[np.ndarray], np.ndarray], env_id: str, seed: int = 0,
                   seconds: float = 3.0, size: int = 240, fps: int = 25, past_the_end: bool = False) -> np.ndarray:
    """Frames ``(n, size, size, 3)`` uint8 of one seeded episode of ``policy``, at most ``seconds`` long.

    ``policy`` maps one observation ``(obs_dim,)`` batch ``(1, obs_dim)`` to actions ``(1, act_dim)``.
    The clip stops where the episode ends, unless ``past_the_end``: then the simulator keeps running
    for the whole ``seconds`` (a hopper whose episode ends as it tips over is seen landing).
    """
    env = gym.make(env_id, render_mode="rgb_array", width=size, height=size)
    obs, _ = env.reset(seed=seed)
    skip = max(1, round(1 / (env.unwrapped.dt * fps)))  # env steps per video frame
    frames = [env.render()]
    for t in range(int(seconds * fps) * skip):
        action = np.asarray(policy(obs[None]))[0]
        obs, _, terminated, truncated, _ = env.step(action)
        if (t + 1) % skip == 0:
            frames.append(env.render())
        if (terminated or truncated) and not past_the_end:
            break
    env.close()
    return np.stack(frames)


def side_by_side(clips: Sequence[np.ndarray]) -> np.ndarray:
    """Place clips left to right; shorter clips hold their last frame."""
    n = max(len(c) for c in clips)
    padded = [np.concatenate([c, np.repeat(c[-1:], n - len(c), axis=0)]) for c in clips]
    return np.concatenate(padded, axis=2)


def save_mp4(frames: np.ndarray, path: str | Path, fps: int = 25) -> Path:
    """Write frames as an H.264 MP4 with the ffmpeg binary bundled by ``imageio-ffmpeg``."""
    import imageio.v2 as imageio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimwrite(path, list(frames), fps=fps, codec="libx264", macro_block_size=8, pixelformat="yuv420p")
    return path


def show_video(path: str | Path, width: int = 480):
    """An inline, embedded (self-contained) video player for Jupyter."""
    from IPython.display import Video

    return Video(str(path), embed=True, width=width, html_attributes="controls loop autoplay muted")


def egl_available() -> bool:
    """Whether the EGL library that headless MuJoCo rendering needs can be found."""
    return ctypes.util.find_library("EGL") is not None


def ensure_egl() -> int:
    """Install Mesa's EGL libraries with apt when missing and running as root; else say what to install."""
    if egl_available():
        return 0
    if os.geteuid() == 0 and shutil.which("apt-get"):
        print("installing EGL libraries for headless rendering: " + " ".join(EGL_PACKAGES), flush=True)
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        subprocess.run(["apt-get", "update", "-qq"], check=True, env=env)
        subprocess.run(["apt-get", "install", "-y", "-qq", *EGL_PACKAGES], check=True, env=env)
        return 0 if egl_available() else 1
    print("headless MuJoCo rendering needs EGL: install it with "
          f"`sudo apt-get install {' '.join(EGL_PACKAGES)}` (Debian/Ubuntu) or your system's Mesa EGL package",
          file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(ensure_egl())
