"""A worker's start deadline counts its own start, not the zygote's imports before it.

On a loaded machine the zygote's imports (torch, mujoco) can take longer than a worker may take to
start; counted together, a slow machine turned a submission into a grader error.
"""
from __future__ import annotations

import os
import time

import pytest

from autograder.core import course, supervisor
from autograder.sandbox.config import SpawnConfig
from autograder.core.supervisor import SandboxStartError, Zygote

IMPORT_SECONDS = 6.0
START_TIMEOUT = 5.0  # shorter than the imports, far longer than a worker's start


@pytest.fixture
def preload_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    return tmp_path


def _spawn(zygote: Zygote):
    return zygote.spawn(SpawnConfig(course.sandbox_view(()), course.limits("hw0_setup")))


def test_a_slow_zygote_import_does_not_eat_the_workers_start_deadline(preload_dir, monkeypatch):
    monkeypatch.setattr(supervisor, "PRELOAD_SECONDS", 60.0)  # a wait that is never over fails in a minute
    (preload_dir / "slow_course_module.py").write_text(f"import time\ntime.sleep({IMPORT_SECONDS})\n")
    zygote = Zygote(["slow_course_module"])
    try:
        started = time.monotonic()
        worker = _spawn(zygote)
        assert time.monotonic() - started >= IMPORT_SECONDS - 1, "spawn did not wait for the zygote's imports"
        try:
            worker.start(timeout=START_TIMEOUT)  # timed out here when the imports counted against it
        finally:
            worker.kill()
        started = time.monotonic()
        second = _spawn(zygote)
        assert time.monotonic() - started < 2, "the zygote's imports were waited for twice"
        try:
            second.start(timeout=START_TIMEOUT)
        finally:
            second.kill()
    finally:
        zygote.close()


def test_a_zygote_that_dies_while_importing_is_a_start_error(preload_dir):
    (preload_dir / "fatal_course_module.py").write_text("import os\nos._exit(1)\n")
    zygote = Zygote(["fatal_course_module"])
    try:
        with pytest.raises(SandboxStartError, match="ended while importing"):
            _spawn(zygote)
    finally:
        zygote.close()


def test_a_preloaded_torch_brings_what_it_imports_lazily():
    """torch imports torch._dynamo (about 1 s of CPU) when a submission builds its first optimizer: the zygote
    imports it once, so that no worker pays it again (plain ``import torch`` does not)."""
    from autograder.core.session import Cell, Session

    zygote = Zygote(["torch"])
    probe = Cell("probe", "import sys\nassert 'torch._dynamo' in sys.modules, 'torch._dynamo is not preloaded'")
    session = Session(zygote, [probe], SpawnConfig(course.sandbox_view(()), course.limits("hw0_setup")))
    try:
        session.start()
        assert session.status["probe"].ok, session.status["probe"].message
    finally:
        session.close()
        zygote.close()
