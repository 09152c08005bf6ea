"""A container that refuses namespaces (Docker's and containerd's default capabilities, as on Gradescope):
the grader runs as root with no view, so the worker becomes a uid of its own and the file modes are the
wall. It grades when ``python -m autograder permissions`` has set them, and refuses (a grader fault, never a
grade) while a worker could read the hidden suites or solutions."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from conftest import REPO

from autograder.sandbox import isolation
from autograder.sandbox.config import View

RUNTIME_DEFAULT = ("chown", "dac_override", "fsetid", "fowner", "mknod", "net_raw", "setgid", "setuid", "setfcap",
                   "setpcap", "net_bind_service", "sys_chroot", "kill", "audit_write")
"""The capabilities a container runtime gives by default: no SYS_ADMIN, so no namespaces."""
COPIED = ("pyproject.toml", "assignments", "autograder", "datasets", "lectures", "rlcourse", "solutions")

needs_root = pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("setpriv"), reason="needs root and setpriv")


def _world_readable(path: str) -> bool:
    return all(os.stat(p).st_mode & stat.S_IXOTH for p in [path, *map(str, Path(path).parents)]) and \
        bool(os.stat(path).st_mode & stat.S_IROTH)


@pytest.fixture
def course():
    """A copy of the course in a fresh folder of mode 700 (as under ``umask 077``)."""
    top = Path(tempfile.mkdtemp(prefix="no-namespaces "))
    root = top / "course"
    root.mkdir()
    for name in COPIED:
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, root / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(source, root / name)
    yield root
    shutil.rmtree(top, ignore_errors=True)


def _grade(root: Path, out: Path, notebook: str = "partial") -> subprocess.CompletedProcess:
    env = {"PATH": os.environ["PATH"], "PYTHONPATH": str(root), "RLCOURSE_REPO": str(root), "HOME": str(out.parent)}
    return subprocess.run(["setpriv", f"--bounding-set=-all,{','.join('+' + c for c in RUNTIME_DEFAULT)}",
                           "--inh-caps=-all", "--", sys.executable, "-m", "autograder", "grade", "hw0_setup",
                           str(root / f"autograder/samples/hw0_setup/{notebook}.ipynb"), "--out", str(out)],
                          cwd=root, env=env, capture_output=True, text=True, timeout=600)


@needs_root
@pytest.mark.slow
def test_a_course_walled_by_its_modes_grades_and_one_that_is_not_refuses(course, tmp_path):
    for prefix in {sys.prefix, sys.base_prefix}:
        if not _world_readable(prefix):
            pytest.skip(f"the Python installation {prefix} is not readable by other users (a container's is)")
    refused = _grade(course, tmp_path / "open")
    assert refused.returncode == 3, refused.stderr[-2000:]
    assert "autograder permissions" in refused.stderr and "could" in refused.stderr
    assert not (tmp_path / "open" / "result.json").exists() or \
        json.loads((tmp_path / "open" / "result.json").read_text())["error"]

    done = subprocess.run([sys.executable, "-m", "autograder", "permissions", "--root", str(course), "--no-environment",
                           "--assignment", "hw0_setup"],
                          env={**os.environ, "PYTHONPATH": str(course), "RLCOURSE_REPO": str(course)},
                          capture_output=True, text=True, check=True)
    assert "file modes changed" in done.stdout
    assert stat.S_IMODE(os.stat(course / "solutions").st_mode) & 0o077 == 0
    # of the library, what grading hw0 does not need is its owner's only (another assignment's helpers)
    assert stat.S_IMODE(os.stat(course / "rlcourse/feedback_spectrum.py").st_mode) & 0o077 == 0
    assert stat.S_IMODE(os.stat(course / "rlcourse/rollouts.py").st_mode) & 0o044 == 0o044
    graded = _grade(course, tmp_path / "walled")
    assert graded.returncode == 0, graded.stderr[-2000:]
    result = json.loads((tmp_path / "walled" / "result.json").read_text())
    assert result["isolation"] == "none" and result["error"] is None
    assert sum(t["points"] for s in result["stubs"] for t in s["tests"] if t["passed"]) == 5


def _check_as(uid: int, view: View) -> str:
    """Run :func:`isolation.check_file_modes` in a child that has become ``uid``; its error, or "ok"."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(r)
            os.setgroups([])
            os.setresgid(uid, uid, uid)
            os.setresuid(uid, uid, uid)
            isolation.check_file_modes(view, [sys.prefix])
            os.write(w, b"ok")
        except BaseException as err:  # noqa: BLE001 - the parent reads it
            os.write(w, str(err).encode()[:4000])
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        message = f.read()
    os.waitpid(pid, 0)
    return message


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to become another uid")
def test_the_check_finds_a_reachable_secret_and_an_unreadable_release():
    tmp_path = Path(tempfile.mkdtemp(prefix="modes-"))  # pytest's own folders are mode 700: nobody else gets in
    try:
        _check_the_check(tmp_path)
    finally:
        shutil.rmtree(tmp_path)


def _check_the_check(tmp_path: Path) -> None:
    release, suites = tmp_path / "release", tmp_path / "suites"
    (release / "pkg").mkdir(parents=True)
    (release / "pkg" / "data.txt").write_text("public")
    suites.mkdir()
    (suites / "test_hidden.py").write_text("secret")
    for path in (tmp_path, release, release / "pkg"):
        os.chmod(path, 0o755)
    os.chmod(release / "pkg" / "data.txt", 0o644)
    view = View([str(release)], [], (0, 0), [str(suites)])
    os.chmod(suites, 0o711)  # searchable is reachable: a known file name could be opened
    assert "could read" in _check_as(54321, view) and str(suites) in _check_as(54321, view)
    os.chmod(suites, 0o700)
    assert _check_as(54321, view) == "ok"
    os.chmod(release / "pkg" / "data.txt", 0o600)
    message = _check_as(54321, view)
    assert "could not read" in message and "data.txt" in message


def test_the_view_names_the_instructor_folders_as_secret(tmp_path):
    from autograder.core import course

    secret = course.sandbox_view([tmp_path]).secret
    for name in ("solutions", "autograder/suites", "autograder/samples"):
        assert str(course.REPO / name) in secret
    assert str(tmp_path.resolve()) in secret
