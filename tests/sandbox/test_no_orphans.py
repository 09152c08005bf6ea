"""A grader killed mid-grading takes its sandbox with it: no worker is left looping until its CPU limit."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            tree.setdefault(int(fields[1]), []).append(int(entry.name))
    return tree


def _descendants(pid: int) -> set[tuple[int, str]]:
    """(pid, start time) of every process under ``pid``: the start time tells a reused pid apart."""
    tree, found, todo = _children(), set(), [pid]
    while todo:
        for child in tree.get(todo.pop(), []):
            try:
                found.add((child, (Path("/proc") / str(child) / "stat").read_text().rsplit(")", 1)[1].split()[19]))
            except OSError:
                continue
            todo.append(child)
    return found


def _alive(processes: set[tuple[int, str]]) -> set[tuple[int, str]]:
    alive = set()
    for pid, start in processes:
        try:
            fields = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[19] == start and fields[0] != "Z":
            alive.add((pid, start))
    return alive


def test_killing_the_grader_kills_a_looping_worker(tmp_path):
    grader = subprocess.Popen([sys.executable, "-m", "autograder", "grade", "hw0_setup",
                               str(REPO / "autograder/samples/hw0_setup/infinite_loop.ipynb"), "--out", str(tmp_path)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # Wait until a worker has run for a while (the loop is in a stub the suite calls), then kill the grader.
    deadline, sandbox = time.monotonic() + 120, set()
    while time.monotonic() < deadline and grader.poll() is None:
        sandbox = _descendants(grader.pid)
        if len(sandbox) >= 3:  # zygote, launcher, worker
            break
        time.sleep(0.2)
    assert len(sandbox) >= 3, "the grader never started a sandbox worker"
    time.sleep(3)
    sandbox |= _descendants(grader.pid)
    os.kill(grader.pid, signal.SIGKILL)
    grader.wait()
    deadline = time.monotonic() + 20
    while _alive(sandbox) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _alive(sandbox), f"sandbox processes outlived the grader: {sorted(_alive(sandbox))}"
