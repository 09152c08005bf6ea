"""The ``meta`` object every results file carries: which code, when, and how busy the machine was.

    from bench.run_record import meta
    json.dumps({"meta": meta(), ...})

A figure without its load is unreadable on a shared 2-core machine, and a figure from uncommitted code
cannot be reproduced from its commit, so both are recorded (``bench/numbers_pages.py`` shows them).
"""
from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _git(*args: str, cwd: Path = REPO) -> str:
    done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=cwd)
    return done.stdout.strip() if done.returncode == 0 else ""


def head_commit(repo: Path = REPO) -> str:
    """The short commit checked out in ``repo`` (a clone being measured, say), or ``"unknown"``."""
    return _git("rev-parse", "--short", "HEAD", cwd=repo) or "unknown"


def meta(paths: Sequence[str] = ()) -> dict:
    """Commit, date, load averages, machine, Python, and how many tracked files under ``paths`` (all, if
    none) differ from that commit. ``BENCH_COMMIT`` names the commit instead, for a run of an earlier
    commit's code unpacked outside the checkout (a paired comparison)."""
    if os.environ.get("BENCH_COMMIT"):
        commit, changed = os.environ["BENCH_COMMIT"], []
    else:
        commit = head_commit()
        changed = _git("status", "--porcelain", "--untracked-files=no", "--", *paths).splitlines()
    now = datetime.datetime.now(datetime.timezone.utc)
    return {"commit": commit, "uncommitted_files": len(changed), "date": now.date().isoformat(),
            "time_utc": now.strftime("%H:%M"), "load": [round(x, 2) for x in os.getloadavg()],
            "machine": f"{os.cpu_count()}-core CPU", "platform": platform.machine(),
            "python": sys.version.split()[0]}
