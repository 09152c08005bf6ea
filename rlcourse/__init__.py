"""rlcourse: the small library that the course notebooks import.

Importing it first selects headless MuJoCo rendering (EGL through Mesa's
software renderer) when no display is present, before MuJoCo picks a backend.
"""
import os as _os

if "MUJOCO_GL" not in _os.environ and not _os.environ.get("DISPLAY"):
    _os.environ["MUJOCO_GL"] = "egl"
    _os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"
