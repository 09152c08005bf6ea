"""Packaging: pinned stack, and environment.yml carrying exactly pyproject.toml's pins."""
from __future__ import annotations

import re
import tomllib

from conftest import REPO


def pyproject_pins() -> dict[str, str]:
    deps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    return dict(re.fullmatch(r"([A-Za-z0-9_.-]+)==([^\s;]+)", d).groups() for d in deps)


def environment_pins() -> dict[str, str]:
    pins = re.findall(r"^\s*-\s+([A-Za-z0-9_.-]+)==(\S+)\s*$", (REPO / "environment.yml").read_text(), flags=re.M)
    return dict(pins)


def test_every_dependency_is_pinned_exactly_and_torch_is_the_cpu_wheel_version():
    pins = pyproject_pins()
    assert pins["torch"] == "2.13.0"
    assert {"numpy", "gymnasium", "mujoco", "nbgrader", "nbclient", "nbformat", "matplotlib", "tqdm", "imageio",
            "imageio-ffmpeg", "pytest", "jupyterlab"} <= set(pins)


def test_environment_yml_has_the_same_pins():
    assert environment_pins() == pyproject_pins()
    assert re.search(r"python=3\.11", (REPO / "environment.yml").read_text())
