"""Batch grading: the folder layouts, the gradebook, and resuming after a kill."""
from __future__ import annotations

import pytest

import csv
import os
import shutil
import signal
import subprocess
import sys
import time

from autograder.core.batch import discover
from conftest import REPO

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

SAMPLES = REPO / "autograder/samples/hw0_setup"
EXPECTED = ["discounted_returns", "episode_returns"]


def test_layouts_are_recognised(tmp_path):
    flat = tmp_path / "flat"
    flat.mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice.ipynb")
    nbg = tmp_path / "course" / "submitted" / "bob" / "hw0_setup"
    nbg.mkdir(parents=True)
    shutil.copy(SAMPLES / "partial.ipynb", nbg / "hw0_setup.ipynb")
    export = tmp_path / "export"
    (export / "submission_101").mkdir(parents=True)
    (export / "submission_metadata.yml").write_text("{}")
    shutil.copy(SAMPLES / "complete.ipynb", export / "submission_101" / "work.ipynb")
    shutil.copy(SAMPLES / "untouched.ipynb", export / "submission_101" / "scratch.ipynb")
    (export / "submission_102").mkdir()

    assert [(e.name, e.notebook.name) for e in discover(flat, "hw0_setup", EXPECTED)] == [("alice", "alice.ipynb")]
    assert [(e.name, e.notebook.name) for e in discover(tmp_path / "course", "hw0_setup", EXPECTED)] == \
        [("bob", "hw0_setup.ipynb")]
    entries = {e.name: e for e in discover(export, "hw0_setup", EXPECTED)}
    assert entries["submission_101"].notebook.name == "work.ipynb"  # the one with the most stubs found
    assert "several notebooks" in entries["submission_101"].note
    assert entries["submission_102"].notebook is None and "no notebook" in entries["submission_102"].problem


def test_killed_batch_resumes_and_grades_each_submission_once(open_tmp):
    folder, out = open_tmp / "in", open_tmp / "out"
    folder.mkdir()
    kinds = ["complete", "partial", "untouched", "broken_syntax"]
    for i in range(12):
        shutil.copy(SAMPLES / f"{kinds[i % 4]}.ipynb", folder / f"student{i:02d}.ipynb")
    (folder / "empty_folder_submission").mkdir()
    command = [sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out), "--jobs", "2"]
    first = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while len(list(out.glob("*/result.json"))) < 4 and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.2)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    done_before = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/result.json")}
    assert 4 <= len(done_before) < 13, "the kill should land halfway"
    assert not (out / "gradebook.csv").exists()

    second = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr[-2000:]
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    names = [r["submission"] for r in rows]
    assert sorted(names) == sorted([f"student{i:02d}" for i in range(12)] + ["empty_folder_submission"])
    assert len(set(names)) == len(names)
    for name, mtime in done_before.items():  # finished before the kill: not graded again
        assert (out / name / "result.json").stat().st_mtime_ns == mtime
    by_name = {r["submission"]: r for r in rows}
    assert by_name["student00"]["score"] == "8" and by_name["student01"]["score"] == "5"
    assert by_name["empty_folder_submission"]["status"] == "ungradable"
    assert not list(out.rglob("*.tmp")), "no half-written files are left behind"


def test_names_are_made_safe_then_unique_the_same_on_every_run(tmp_path):
    folder = tmp_path / "flat"
    folder.mkdir()
    for name in ("alice smith", "alice_smith", "alice_smith-2", "Bob", "bob", "ça va"):
        shutil.copy(SAMPLES / "complete.ipynb", folder / f"{name}.ipynb")
    first = [e.name for e in discover(folder, "hw0_setup", EXPECTED)]
    assert first == [e.name for e in discover(folder, "hw0_setup", EXPECTED)], "names must not change between runs"
    assert len({n.lower() for n in first}) == 6, f"every submission keeps its own folder and row: {first}"
    assert sorted(first) == sorted(["alice_smith", "alice_smith-3", "alice_smith-2", "Bob", "bob-2", "a_va"])
