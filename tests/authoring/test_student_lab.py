"""nbgrader's Validate in the student's environment: it runs the public checks and tells the truth.

tests/test_browser.py clicks the same Validate in JupyterLab; this runs nbgrader's Validator (what
the button's server extension calls) on a fresh student release, with the release's own
nbgrader_config.py, and needs no browser.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from autograder.authoring.release import build_student_release
from conftest import REPO
from rlcourse.student_lab import HIDDEN_LAB_PLUGINS, configure_validate, inject_fast


def test_inject_fast_adds_fast_after_the_parameters_cell_only():
    params = nbformat.v4.new_code_cell("FAST = False", metadata={"tags": ["parameters"]})
    other = nbformat.v4.new_code_cell("FAST = False")
    for cell in (params, other):
        inject_fast(cell=cell, cell_index=0)
    namespace: dict = {}
    exec(params.source, namespace)
    assert namespace["FAST"] is True and other.source == "FAST = False"


def test_configure_validate_sets_nbgraders_own_options():
    from traitlets.config import Config

    c = Config()
    configure_validate(c)
    assert c.Validator.validate_all is True and c.Execute.timeout >= 300 and c.Execute.on_cell_start is inject_fast


def _validate(release: Path, notebook: Path) -> dict:
    """nbgrader's Validator on ``notebook``, configured as the button's handler configures it (from the folder
    JupyterLab started in, here the release), in a child process started there."""
    code = ("import json, sys; from nbgrader.apps import NbGrader; from nbgrader.validator import Validator\n"
            "app = NbGrader(); app.load_config_file()\n"
            "print(json.dumps(Validator(config=app.config).validate(sys.argv[1])))")
    env = dict(os.environ, PYTHONPATH=str(release), RLCOURSE_DATASETS=str(release / "datasets"),
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    done = subprocess.run([sys.executable, "-c", code, str(notebook)], cwd=release, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def complete_hw0(folder: Path) -> Path:
    """hw0's complete sample with its written answer given: what a student who finished submits."""
    nb = nbformat.read(REPO / "autograder/samples/hw0_setup/complete.ipynb", as_version=4)
    for cell in nb.cells:
        if cell.metadata.get("nbgrader", {}).get("grade_id") == "q_fast":
            cell.source = "It shrinks the budgets; a stub that read it would be graded on other inputs."
    path = folder / "complete_check.ipynb"
    nbformat.write(nb, path)
    return path


@pytest.mark.slow
def test_validate_fails_an_untouched_hw0_and_passes_a_complete_one(tmp_path):
    release = build_student_release(tmp_path / "course")
    untouched = _validate(release, release / "assignments/hw0_setup/hw0_setup.ipynb")
    errors = [cell["raw_error"] for cell in untouched.get("failed", [])]
    assert sum("NotImplementedError" in e for e in errors) >= 2, untouched  # both public checks fail in place
    assert any("did not provide a response" in e for e in errors), untouched  # and the written answer is missing
    assert _validate(release, complete_hw0(release / "assignments/hw0_setup")) == {}  # nbgrader's "Success!"


def test_the_student_commands_hide_nbgraders_instructor_entries(tmp_path):
    env = dict(os.environ, JUPYTER_CONFIG_DIR=str(tmp_path))
    subprocess.run([sys.executable, "-m", "rlcourse.student_lab", "--user"], env=env, check=True, capture_output=True)
    disabled = json.loads((tmp_path / "labconfig/page_config.json").read_text())["disabledExtensions"]
    assert {name for name, off in disabled.items() if off} == set(HIDDEN_LAB_PLUGINS)
    assert "@jupyter/nbgrader:validate-assignment" not in disabled
    server = json.loads((tmp_path / "jupyter_server_config.json").read_text())["ServerApp"]["jpserver_extensions"]
    assert server["nbgrader.server_extensions.formgrader"] is False
    assert "nbgrader.server_extensions.validate_assignment" not in server
