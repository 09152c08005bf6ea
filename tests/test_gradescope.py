"""The Gradescope bundle, unpacked into a tree laid out as Gradescope lays it out, and run there."""
from __future__ import annotations

import pytest

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from autograder.outputs.gradescope import build_bundle
from autograder.core.grader import Grader
from autograder.outputs.gradescope import gradescope_results
from conftest import REPO

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it


def test_gradescope_results_have_one_test_per_stub():
    grader = Grader("hw0_setup")
    try:
        result = grader.grade(REPO / "autograder/samples/hw0_setup/partial.ipynb")
    finally:
        grader.close()
    data = json.loads(json.dumps(gradescope_results(result)))
    assert [t["name"] for t in data["tests"]] == ["discounted_returns", "episode_returns"]
    assert data["score"] == sum(t["score"] for t in data["tests"]) == 5
    assert {"score", "max_score", "status", "output", "visibility"} <= set(data["tests"][0])
    assert data["tests"][1]["status"] == "failed" and "not implemented" in data["tests"][1]["output"]
    assert "execution_time" in data




def test_bundle_grades_a_submission_in_a_gradescope_layout(tmp_path):
    bundle = build_bundle("hw0_setup", tmp_path / "hw0_setup.zip")
    names = zipfile.ZipFile(bundle).namelist()
    assert {"setup.sh", "run_autograder", "pyproject.toml"} <= set(names)
    assert any(n.startswith("autograder/suites/hw0_setup/") for n in names)
    assert not any(n.startswith("autograder/samples/") or "suites/hw1" in n for n in names)

    root = tmp_path / "autograder"
    source = root / "source"
    with zipfile.ZipFile(bundle) as z:
        z.extractall(source)
    for name in ("setup.sh", "run_autograder"):
        (source / name).chmod(0o755)
    # setup.sh installs the pins from the network on Gradescope; here the repository's environment stands in.
    os.symlink(Path(sys.prefix), source / ".venv")
    (root / "submission").mkdir()
    shutil.copy(REPO / "autograder/samples/hw0_setup/partial.ipynb", root / "submission" / "my_work.ipynb")
    done = subprocess.run(["bash", str(source / "run_autograder")], env=dict(os.environ, GRADESCOPE_ROOT=str(root)),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads((root / "results" / "results.json").read_text())
    assert results["score"] == 5
    assert [t["score"] for t in results["tests"]] == [5, 0]
    assert all(t["visibility"] == "visible" for t in results["tests"])

    # A submission that is a link to the solution is graded as nothing, with the reason, never followed.
    (root / "submission" / "my_work.ipynb").unlink()
    (root / "submission" / "my_work.ipynb").symlink_to(REPO / "solutions/hw0_setup/hw0_setup.ipynb")
    done = subprocess.run(["bash", str(source / "run_autograder")], env=dict(os.environ, GRADESCOPE_ROOT=str(root)),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads((root / "results" / "results.json").read_text())
    assert results["score"] == 0 and "symbolic link" in results["output"], results["output"]
    assert results["output_format"] == "text"
