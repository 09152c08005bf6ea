"""No warning block a student cannot act on (issue 40): HalfCheetah's deprecated ``settotalmass``."""
from __future__ import annotations

import subprocess
import sys


def test_halfcheetah_builds_without_the_deprecation_block_and_other_warnings_still_show():
    code = ("import rlcourse.envs, gymnasium as gym\n"
            "env = gym.make('HalfCheetah-v5'); env.reset(seed=0)\n"
            "import rlcourse.mujoco_messages as m; m._warn('a warning that matters')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    out = done.stdout + done.stderr
    assert "settotalmass" not in out
    assert "WARNING: a warning that matters" in done.stderr
