"""MuJoCo's warnings, minus the one every HalfCheetah prints.

Gymnasium's ``half_cheetah.xml`` sets its mass with the compiler attribute ``settotalmass``, which MuJoCo
4 compiles as before but announces as deprecated each time a model is built: five pink blocks in a
notebook that trains on HalfCheetah, none of them the student's concern. Importing this module installs
a MuJoCo warning handler that drops that announcement and writes every other warning to stderr, as
MuJoCo does by default. The model itself is unchanged (the attribute still applies).
"""
from __future__ import annotations

import sys

import mujoco

KNOWN = ("compiler attribute 'settotalmass' is deprecated",)
"""Warnings of the models the course ships with that a student cannot act on."""


def _warn(message: str) -> None:
    if not message.startswith(KNOWN):
        print(f"WARNING: {message}", file=sys.stderr)


mujoco.set_mju_user_warning(_warn)
