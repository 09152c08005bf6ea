"""A corpus of submissions that try to cheat or to harm, graded in one batch.

Each case replaces the fixture assignment's `scaled_sum` cell (every other stub
is left unimplemented, so an honest empty submission scores 0). Several return
the right answer only if their trick worked (reading the suites, reaching the
network, finding a secret in the environment), so a score above zero means the
sandbox let the trick through. Every case must score 0, and the batch must
finish with every case in the gradebook. The corpus runs as root and, through
a user switch, as a normal user.
"""
from __future__ import annotations

import csv
import json
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from autograder.outputs.files import grade_folder
from conftest import FIXTURE_COURSE, REPO, with_cells

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

RIGHT = "SCALE * np.asarray(x, dtype=float).sum(axis=-1)"
CHANNEL = """def _channel():
    \"\"\"The worker's end of the channel to the grader: its one write-only descriptor past stderr.\"\"\"
    for fd in sorted(map(int, os.listdir("/proc/self/fd"))):
        try:
            if fd > 2 and fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE == os.O_WRONLY:
                return fd
        except OSError:
            pass
"""

CASES = {
    "always_equal": """
        class Anything(float):
            shape = (4,)
            def __eq__(self, other): return True
            def __ne__(self, other): return False
            __hash__ = float.__hash__
        def scaled_sum(x):
            return Anything(0.0)
        """,
    "ndarray_subclass": """
        class Yes(np.ndarray):
            def __eq__(self, other): return np.ones(np.shape(other), bool)
        def scaled_sum(x):
            return np.zeros(np.shape(x)[:-1]).view(Yes)
        """,
    "nan_answers": """
        def scaled_sum(x):
            return np.full(np.shape(x)[:-1], np.nan)
        """,
    "monkeypatch_numpy_pytest_builtins": """
        import builtins, numpy, pytest
        numpy.allclose = numpy.isclose = lambda *a, **k: True
        numpy.testing.assert_allclose = lambda *a, **k: None
        pytest.approx = lambda *a, **k: True
        builtins.isinstance = lambda *a: True
        builtins.type = lambda *a: np.ndarray
        import autograder.suite, autograder.wire
        autograder.suite.check_array = lambda *a, **k: None
        def scaled_sum(x):
            return 0
        """,
    "read_suites_and_solutions": """
        import glob, os
        FOUND = glob.glob("/**/suites/fx/*.py", recursive=False) + glob.glob(os.environ.get("HOME", "/") + "/../**")
        for path in [SUITE, SOLUTION]:
            try:
                FOUND.append(open(path).read())
            except OSError:
                pass
        def scaled_sum(x):
            return {RIGHT} if any("scaled_sum" in f for f in FOUND) else None
        """,
    "import_the_suite_or_reference": """
        import sys
        sys.path[:0] = ["{course}/autograder/suites/fx", "{course}/solutions/fx"]
        try:
            import test_fx
            OK = True
        except ImportError:
            OK = False
        def scaled_sum(x):
            return {RIGHT} if OK else None
        """,
    "secret_in_environment": """
        import os
        def scaled_sum(x):
            return {RIGHT} if "RLCOURSE_TEST_SECRET" in os.environ else None
        """,
    "secret_in_the_original_environment_block": """
        import glob
        def _blocks():
            for path in ["/proc/self/environ", "/proc/1/environ", *glob.glob("/proc/[0-9]*/environ")]:
                try:
                    with open(path, "rb") as f:
                        yield f.read()
                except OSError:
                    pass
        FOUND = any(b"RLCOURSE_TEST_SECRET" in block for block in _blocks())
        def scaled_sum(x):
            return {RIGHT} if FOUND else None
        """,
    "forked_children_hold_memory_together": """
        import os, time
        def scaled_sum(x):
            for _ in range(6):
                if os.fork() == 0:
                    held = bytearray(450 * 2**20)
                    time.sleep(30)
                    os._exit(0)
            time.sleep(5)
            return {RIGHT}
        """,
    "stand_in_asked_again_and_again": {"double_scaled": """
        def double_scaled(x):
            for _ in range(100_000):
                scaled_sum(x)
            return 2 * scaled_sum(x)
        """},
    "network": """
        import socket
        def scaled_sum(x):
            try:
                socket.create_connection(("127.0.0.1", PORT), timeout=1).close()
                return {RIGHT}
            except OSError:
                return None
        """,
    "write_results_and_fake_scores": """
        import json, os
        for folder in [OUT, "/autograder/results", os.getcwd()]:
            try:
                with open(os.path.join(folder, "results.json"), "w") as f:
                    json.dump({"score": 100, "tests": []}, f)
            except OSError:
                pass
        print(json.dumps({"score": 100, "tests": [{"name": "scaled_sum", "score": 3, "max_score": 3}]}))
        def scaled_sum(x):
            print("PASSED 3/3")
            return None
        """,
    "alter_course_code_on_disk": """
        import os, sysconfig
        for path in [os.path.join(COURSE_CODE, "rlcourse", "__init__.py"), os.path.join(COURSE_CODE, "autograder", "suite.py"),
                     os.path.join(sysconfig.get_paths()["purelib"], "sitecustomize.py")]:
            try:
                with open(path, "a") as f:
                    f.write("\\nraise SystemExit('tampered')\\n")
            except OSError:
                pass
        def scaled_sum(x):
            return None
        """,
    "exit_and_kill": """
        import os, signal, sys
        def scaled_sum(x):
            for target in (os.getppid(), -1, 1):
                try:
                    os.kill(target, signal.SIGKILL)
                except OSError:
                    pass
            sys.exit(0)
        """,
    "os_exit_at_import": """
        import os
        os._exit(0)
        """,
    "sys_exit_in_call": """
        import sys
        def scaled_sum(x):
            sys.exit("done")
        """,
    "infinite_loop_in_call": """
        def scaled_sum(x):
            while True:
                pass
        """,
    "infinite_loop_at_import": """
        while True:
            pass
        """,
    "sleep_past_limits": """
        import time
        def scaled_sum(x):
            time.sleep(1000)
        """,
    "fork_bomb": """
        import os
        def scaled_sum(x):
            while True:
                try:
                    os.fork()
                except OSError:
                    pass
        """,
    "memory_bomb": """
        def scaled_sum(x):
            hog = []
            while True:
                hog.append(bytearray(50 * 1024 * 1024))
        """,
    "fill_the_disk": """
        import os
        def scaled_sum(x):
            with open("filler", "wb") as f:
                for _ in range(4096):
                    f.write(os.urandom(1024 * 1024))
        """,
    "garbage_on_the_channel": """
        import os
        def scaled_sum(x):
            for fd in map(int, os.listdir("/proc/self/fd")):
                try:
                    os.write(fd, b"\\xff" * 64)
                except OSError:
                    pass
            return None
        """,
    "huge_return_value": """
        def scaled_sum(x):
            return np.zeros(40_000_000)
        """,
    "output_flood": """
        import sys
        def scaled_sum(x):
            for _ in range(20000):
                sys.stdout.write("x" * 4096)
            return None
        """,
    "stash_a_reference_stand_in": {
        "scaled_sum": """
            STASH = []
            def scaled_sum(x):
                if STASH:
                    try:
                        return STASH[0](x)  # must be refused: nothing stands in while scaled_sum is tested
                    except Exception:
                        pass
                return None
            """,
        "double_scaled": """
            def double_scaled(x):
                STASH.append(scaled_sum)    # the reference stand-in, while double_scaled is tested
                return None
            """},
    "import_course_files_outside_the_release": """
        import importlib.util, os, sys
        FOUND = []
        for rel in ["tests/lectures/lecture_math.py", "tests/conftest.py", "bench/bench_hw3_preferences.py",
                    "datasets/scripts/make_hw4_reward_model.py", "lectures/figures/make_figures.py", ".git/config",
                    "autograder/core/grader.py", "autograder/suites/hw0_setup/test_discounted_returns.py", "README.md",
                    "solutions/hw0_setup/hw0_setup.ipynb", "autograder/samples/hw0_setup/complete.ipynb"]:
            try:
                FOUND += [text for text in [open(os.path.join(COURSE_CODE, rel)).read()] if text]  # a mask reads empty
            except OSError:
                pass
        sys.path[:0] = [os.path.join(COURSE_CODE, "tests", "lectures"), os.path.join(COURSE_CODE, "datasets", "scripts")]
        for module in ("lecture_math", "make_hw4_reward_model", "autograder.core.grader", "autograder.suites"):
            try:
                FOUND.append(str(importlib.import_module(module)))
            except BaseException:
                pass
        def scaled_sum(x):
            return {RIGHT} if FOUND else None
        """,
    "search_own_memory_for_the_reference": """
        import gc
        FOUND = [o for o in gc.get_objects() if callable(o) and getattr(o, "__name__", "") == "scaled_sum"
                 and getattr(o, "__globals__", {}).get("__name__") == "__reference__"]
        FOUND += [o for o in gc.get_objects() if type(o) is str and "BEGIN SOLUTION" in o]
        FOUND += [o for o in gc.get_objects() if isinstance(o, dict) and o.get("__name__") == "__reference__"]
        def scaled_sum(x):
            return FOUND[0](x) if FOUND and callable(FOUND[0]) else ({RIGHT} if FOUND else None)
        """,
    "undo_the_view": """
        import ctypes, os
        libc = ctypes.CDLL(None, use_errno=True)
        def hidden_readable():
            try:
                return bool(open(SUITE).read())
            except OSError:
                return False
        for target in [b"/", b"/tmp", b"/usr", COURSE_CODE.encode(), b"/proc"]:
            libc.umount2(target, 2)
        libc.mount(b"none", b"/", None, 32 | 4096, None)          # remount the view read-write
        libc.chroot(b"/proc/1/root")
        libc.unshare(0x10000000 | 0x00020000)                   # a new user and mount namespace, then try again
        for target in [b"/", b"/tmp", COURSE_CODE.encode()]:
            libc.umount2(target, 2)
        libc.mount(b"/", b"/tmp", None, 4096 | 16384, None)      # bind whatever the root was over /tmp
        try:
            os.setuid(0)
        except OSError:
            pass
        OK = hidden_readable() or os.path.exists(SOLUTION) or os.path.exists("/tmp" + SUITE)
        def scaled_sum(x):
            return {RIGHT} if OK else None
        """,
    "child_process_reads_the_course": """
        import subprocess, sys
        def scaled_sum(x):
            code = f"import sys; print(open({SUITE!r}).read()[:50]); print(open({COURSE_CODE!r} + '/tests/conftest.py').read()[:50])"
            try:
                done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=10)
            except Exception:
                return None
            return {RIGHT} if done.returncode == 0 and done.stdout.strip() else None
        """,
    # -- what the sandbox can read: an allowlist, and nothing a grading writes survives into another
    "find_other_copies_classmates_and_git": """
        import os
        FOUND = []
        SKIP = {"/proc", "/sys", "/dev", "/usr", "/bin", "/sbin", "/lib", "/lib64", "/etc"}
        for root, dirs, files in os.walk("/"):
            dirs[:] = [d for d in dirs if os.path.join(root, d) not in SKIP and "site-packages" not in d]
            FOUND += [os.path.join(root, d) for d in dirs if d in (".git", "solutions", "submissions", "suites")]
            for name in files:  # a suite, a solution or a classmate's notebook, a Gradescope bundle, results
                path = os.path.join(root, name)
                if name in ("test_fx.py", "fx.zip", "gradebook.csv", "results.json", "result.json", "feedback.md") \\
                        or (name.endswith(".ipynb") and "/assignments/" not in path):
                    FOUND.append(path)
        for path in [SUBMISSIONS, OUT, COPY, os.path.join(COURSE_CODE, ".git"), os.path.join(COURSE_CODE, "build")]:
            if os.path.exists(path):
                FOUND.append(path)
        def scaled_sum(x):
            return {RIGHT} if FOUND else None
        """,
    "files_shared_between_gradings": """
        import os
        SEEN = [p for d in ("/var/tmp", "/run/lock", "/dev/shm", "/tmp") if os.path.isdir(d)
                for p in os.listdir(d) if p.startswith("rlcourse-marker")]
        for d in ("/var/tmp", "/run/lock", "/dev/shm", "/tmp", os.environ.get("HOME", "/tmp")):
            try:
                with open(os.path.join(d, "rlcourse-left-behind"), "w") as f:
                    f.write("for the next submission")
            except OSError:
                pass
        def scaled_sum(x):
            return {RIGHT} if SEEN else None
        """,
    # -- hostile code the grader analyses: a very long expression
    "very_long_expression": "def scaled_sum(x):\n    return " + "+".join(["x"] * 200_000) + "\n",
    # -- the channel, seen from the grader: a worker that stops reading, calls back for ever, or sends too much
    "worker_stops_reading": {
        "scaled_sum": """
            import time
            import autograder.sandbox.wire as wire
            wire.FrameReader.read_message = lambda *a, **k: time.sleep(10**6)  # the worker never reads again
            """,
        "Counter": "# " + "x" * 400_000 + "\nclass Counter:\n    pass\n"},  # a message far over the pipe's buffer
    "calls_back_for_ever": {
        "double_scaled": """
            def double_scaled(x):
                while True:   # each call is answered by the grader's reference stand-in
                    scaled_sum(np.zeros(3))
            """},
    "reply_that_inflates": """
        import fcntl, os, struct, time
        {CHANNEL}
        def scaled_sum(x):
            body = b'{"ok": true, "nblobs": 0, "value": [' + b"[]," * 80_000_000 + b"[]]}"
            os.write(_channel(), struct.pack(">I", len(body)) + body)  # 240 MB of JSON, 80 million lists once parsed
            time.sleep(1000)
        """,
    "many_maximal_blobs": """
        import fcntl, json, os, struct, time
        {CHANNEL}
        def scaled_sum(x):
            fd = _channel()
            head = json.dumps({"ok": True, "value": None, "nblobs": 9999}).encode()
            blob = struct.pack(">I", 200 * 2**20) + bytes(200 * 2**20)
            os.write(fd, struct.pack(">I", len(head)) + head)
            for _ in range(9999):
                os.write(fd, blob)
            time.sleep(1000)
        """,
    # -- what a student's text can do to the outputs
    "forge_the_outputs": """
        FORGED = ("\\n## `scaled_sum`: 3 / 3\\n\\n- ✓ all checks passed\\n✓ scaled sum (3/3)\\n<img src=x onerror=alert(1)>"
                  "&check; :white_check_mark: $\\\\color{green}{3/3}$ \\x1b[2J\\x1b[H\\rscaled_sum 3/3 \\u202e" + "padding " * 20000)
        def scaled_sum(x):
            raise ValueError(FORGED)
        """,
    "recursion_and_deep_nesting": """
        def scaled_sum(x):
            value = []
            for _ in range(10000):
                value = [value]
            return value
        """,
}


def _case_source(code: str, port: int, tmp: Path) -> str:
    header = (f"SUITE = {str(FIXTURE_COURSE / 'autograder/suites/fx/test_fx.py')!r}\n"
              f"SOLUTION = {str(FIXTURE_COURSE / 'solutions/fx/fx.ipynb')!r}\nPORT = {port}\nOUT = {str(tmp / 'out')!r}\n"
              f"SUBMISSIONS = {str(tmp / 'submissions')!r}\nCOPY = {str(tmp / 'copy')!r}\n"
              f"COURSE_CODE = {str(REPO)!r}\n")
    body = textwrap.dedent(code).replace("{RIGHT}", RIGHT).replace("{course}", str(FIXTURE_COURSE))
    body = body.replace("{CHANNEL}", CHANNEL)
    return header + body


SHARED_FOLDERS = ("/var/tmp", "/run/lock", "/dev/shm")
"""World-writable folders of the host: a sandbox must neither see what is there nor leave anything."""


def _hostile_files(folder: Path, tmp: Path) -> dict[str, str]:
    """Submissions that are not plain notebooks: links, a pipe, damaged and inflating JSON. Each must be
    listed with its reason (ungradable) or graded as nothing, without harming the batch; returns name -> status."""
    solution = FIXTURE_COURSE / "solutions/fx/fx.ipynb"
    (folder / "link_to_the_solution.ipynb").symlink_to(solution)
    (folder / "link_to_a_device.ipynb").symlink_to("/dev/zero")
    os.mkfifo(folder / "a_pipe.ipynb")
    (tmp / "elsewhere").mkdir()
    shutil.copy(solution, tmp / "elsewhere" / "fx.ipynb")
    (folder / "linked_folder").symlink_to(tmp / "elsewhere")
    (folder / "folder_with_a_link").mkdir()
    (folder / "folder_with_a_link" / "fx.ipynb").symlink_to(solution)
    (folder / "nbgrader_style" / "fx").mkdir(parents=True)
    (folder / "nbgrader_style" / "fx" / "fx.ipynb").symlink_to(solution)
    release = json.loads((FIXTURE_COURSE / "assignments/fx/fx.ipynb").read_text())
    damaged = json.loads(json.dumps(release))
    damaged["cells"][3]["source"] = {"not": "text"}
    damaged["cells"][5]["source"] = 12345
    damaged["cells"].insert(1, "not a cell")
    (folder / "source_not_text.ipynb").write_text(json.dumps(damaged))
    inflating = json.loads(json.dumps(release))
    inflating["metadata"]["padding"] = "@@@"  # 39 MB of empty lists (under the 50 MB cap): over 800 MB once parsed
    (folder / "json_that_inflates.ipynb").write_text(json.dumps(inflating).replace('"@@@"', "[" + "[]," * 13_000_000 + "[]]"))
    (folder / "json_nested_deeply.ipynb").write_text('{"cells": ' + "[" * 200_000 + "]" * 200_000 + "}")
    for path in folder.glob("*.ipynb"):
        if path.is_file() and not path.is_symlink():
            path.chmod(0o644)
    return {"link_to_the_solution": "ungradable", "link_to_a_device": "ungradable", "a_pipe": "ungradable",
            "linked_folder": "ungradable", "folder_with_a_link": "ungradable", "nbgrader_style": "ungradable",
            "source_not_text": "graded", "json_that_inflates": "ungradable", "json_nested_deeply": "ungradable"}


@pytest.fixture
def corpus(open_tmp):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    port = server.getsockname()[1]
    folder = open_tmp / "submissions"
    for name, code in CASES.items():
        cells = code if isinstance(code, dict) else {"scaled_sum": code}
        with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", folder / f"{name}.ipynb",
                   {cell: _case_source(source, port, open_tmp) for cell, source in cells.items()})
    hostile = _hostile_files(folder, open_tmp)
    shutil.copytree(FIXTURE_COURSE, open_tmp / "copy")  # another copy of the course on the machine
    markers = []
    for shared in SHARED_FOLDERS:
        if os.path.isdir(shared) and os.access(shared, os.W_OK):
            markers.append(Path(shared) / f"rlcourse-marker-{os.getpid()}")
            markers[-1].write_text("left by the host")
    left_before = _left_behind()
    yield folder, open_tmp / "out", hostile
    server.close()
    for marker in markers:
        marker.unlink(missing_ok=True)
    assert _left_behind() == left_before, "a sandbox left files in the host's shared folders"


def _left_behind() -> set[str]:
    return {str(Path(d) / n) for d in SHARED_FOLDERS if os.path.isdir(d) for n in os.listdir(d)
            if n.startswith("rlcourse-left-behind")}


def _code_digest() -> dict[str, bytes | None]:
    """The files the tampering case writes to (a sitecustomize.py must not appear at all)."""
    import sysconfig

    paths = [REPO / "rlcourse/__init__.py", REPO / "autograder/suite.py",
             os.path.join(sysconfig.get_paths()["purelib"], "sitecustomize.py")]
    return {str(p): open(p, "rb").read() if os.path.exists(p) else None for p in paths}


def _check_gradebook(out, hostile):
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    assert sorted(r["submission"] for r in rows) == sorted([*CASES, *hostile]), "every case is in the gradebook"
    over = {r["submission"]: r["score"] for r in rows if r["score"] and float(r["score"]) > 0}
    assert not over, f"cheating cases scored above an honest empty submission: {over}"
    status = {r["submission"]: r["status"] for r in rows}
    assert all(status[name] == "graded" for name in CASES), {n: status[n] for n in CASES if status[n] != "graded"}
    for name in CASES:  # the results are the grader's, not the student's forgeries
        data = json.loads((out / name / "results.json").read_text())
        assert data["score"] == 0 and len(data["tests"]) == 4
    for name, expected in hostile.items():  # each with its reason, none a grader error
        assert status[name] == expected, (name, status[name], [r["reason"] for r in rows if r["submission"] == name])
    reasons = {r["submission"]: r["reason"] for r in rows}
    for name in ("link_to_the_solution", "link_to_a_device", "linked_folder", "folder_with_a_link", "nbgrader_style"):
        assert "symbolic link" in reasons[name], (name, reasons[name])
    assert "not a regular file" in reasons["a_pipe"], reasons["a_pipe"]
    _check_forged_outputs(out / "forge_the_outputs")


def _check_forged_outputs(folder: Path) -> None:
    """A student's exception text is shown inert in feedback.md, results.json and the gradebook."""
    feedback = (folder / "feedback.md").read_text()
    honest = (folder.parent / "nan_answers" / "feedback.md").read_text()
    headings = [line for line in feedback.splitlines() if line.startswith("#")]
    assert len(headings) == sum(line.startswith("#") for line in honest.splitlines()), \
        f"student text added headings to feedback.md: {headings}"
    for raw in ("<img", "&check;", ":white_check_mark:", "$\\color"):  # unless escaped by a backslash
        assert not re.search(r"(?<!\\)" + re.escape(raw), feedback), f"feedback.md shows {raw!r} as the student wrote it"
    for raw in ("\x1b", "\r", "\u202e"):
        assert raw not in feedback, f"feedback.md shows {raw!r} as the student wrote it"
    assert len(feedback) < 20_000, "student text is not capped in feedback.md"
    results = json.loads((folder / "results.json").read_text())
    assert results.get("output_format") == "text" and results.get("test_output_format") == "text"
    for test in results["tests"]:
        lines = test["output"].splitlines()
        assert not any(line.startswith("✓") for line in lines), f"a forged check mark in Gradescope's output: {lines}"
        assert "\x1b" not in test["output"] and "\r" not in test["output"] and len(test["output"]) < 10_000


def _others_may_read(*files: Path) -> bool:
    """Whether a user other than the owner can read each file (every folder above it open to others)."""
    return all(f.exists() and os.stat(f).st_mode & 0o004 and all(os.stat(p).st_mode & 0o001 for p in f.parents)
               for f in files)


def _user_namespaces_work() -> bool:
    return subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "true"], capture_output=True).returncode == 0


def test_corpus_scores_nothing_as_root(corpus, monkeypatch):
    """The grader as root: workers in full namespaces, each dropped to a uid of its own."""
    if os.geteuid() != 0:
        pytest.skip("root mode needs root: this run checks the normal-user mode instead (sudo make test checks both)")
    folder, out, hostile = corpus
    monkeypatch.setenv("RLCOURSE_TEST_SECRET", "do-not-leak")
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))  # for the spawned grading processes
    from autograder.core import course

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    before = _code_digest()
    results = grade_folder("fx", folder, out, jobs=2, progress=False)
    assert len(results) == len(CASES) + len(hostile)
    _check_gradebook(out, hostile)
    assert _code_digest() == before, "course code on disk was modified"
    assert {r.isolation for r in results if r.isolation != "unknown"} == {"full"}


def test_corpus_scores_nothing_as_a_normal_user(corpus):
    """The same corpus with the grader itself running as a normal user (user namespaces instead of root):
    as this user when it is not root, else as `nobody`."""
    if not _user_namespaces_work():
        pytest.skip("this machine refuses unprivileged user namespaces (a container without them, say): "
                    "the grader falls back to limits alone there, which this corpus would rightly fail")
    folder, out, hostile = corpus
    q = shlex.quote
    batch = f"{q(sys.executable)} -m autograder batch fx {q(str(folder))} --out {q(str(out))} --jobs 2"
    env = f"env HOME={q(str(out.parent))} RLCOURSE_REPO={q(str(FIXTURE_COURSE))} RLCOURSE_TEST_SECRET=do-not-leak"
    if os.geteuid() != 0:
        command = ["sh", "-c", f"exec {env} {batch}"]
    elif not _others_may_read(REPO / "autograder" / "__init__.py", Path(sys.prefix) / "pyvenv.cfg"):
        pytest.skip("this checkout is private to root (umask 077 or a mode-700 folder), so no other user can run the "
                    "grader from it; run make test as a normal user in a checkout of theirs to check this mode")
    else:
        python_root = os.path.realpath(sys.base_prefix)
        switch = f"exec setpriv --reuid=65534 --regid=65534 --clear-groups {env} {batch}"
        script = switch
        if python_root.startswith("/root/"):
            # /root is closed to other users: expose the Python installation to `nobody`, as a real user's machine would.
            script = (f"mkdir -p /tmp/.stage && mount --bind {q(python_root)} /tmp/.stage && "
                      f"mount -t tmpfs -o mode=755 tmpfs /root && mkdir -p {q(python_root)} && "
                      f"mount --move /tmp/.stage {q(python_root)} && {switch}")
        command = ["unshare", "--mount", "--propagation", "private", "sh", "-c", script]
    before = _code_digest()
    done = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    _check_gradebook(out, hostile)
    assert _code_digest() == before, "course code on disk was modified"
    isolation = {json.loads((out / n / "result.json").read_text())["isolation"] for n in CASES}
    assert isolation - {"unknown"} == {"user-namespace"}


PEEK_AT_THE_BANDIT = """
def rucb(env, horizon, alpha=0.51, rng=None):
    import gc
    P = None
    for attempt in (lambda: env._P, lambda: vars(env)["_P"], lambda: env.__dict__["_P"],
                    lambda: object.__getattribute__(env, "_lent")[0].attrs["_P"],
                    lambda: next(o._P for o in gc.get_objects() if type(o).__name__ == "DuelingBandit")):
        try:
            P = attempt()
            break
        except Exception:
            pass
    best = int(np.argmax((np.asarray(P) > 0.5).sum(axis=1))) if P is not None else 0
    for _ in range(horizon):
        env.duel(best, best)
    return np.full((horizon, 2), best, dtype=np.int64)
"""


SHIPPED_ANSWERS = """
import torch
from rlcourse.preferences import RewardEnsemble, load_hopper_preferences
from rlcourse.rlhf import load_reward_model

class _LookUp(torch.nn.Module):
    \"\"\"Per-step rewards looked up in the shipped preference file, else the shipped hw4 model.\"\"\"
    def __init__(self, obs):
        super().__init__()
        prefs, self.model = load_hopper_preferences(), load_reward_model()
        self.known = {prefs.obs[i].tobytes(): prefs.rewards[i] for i in range(len(prefs.obs))}
    def predict(self, obs, act):
        obs = np.asarray(obs, dtype=np.float32)
        looked_up = [self.known.get(o.tobytes()) for o in obs]
        if all(r is not None for r in looked_up):
            return np.stack(looked_up)[None]
        return self.model.predict(obs, act)

def train_reward_model(obs, act, pairs, mu, **kwargs):
    return _LookUp(obs)
"""


def test_shipped_answers_and_a_lent_environments_hidden_state_score_nothing(open_tmp):
    """hw3's learners are judged on data no shipped model or file answers, and its rucb gets a dueling bandit
    that stays in the grader (no attribute or object in the sandbox holds P)."""
    from autograder.core.grader import Grader

    notebook = with_cells(REPO / "autograder/samples/hw3_preferences/complete.ipynb", open_tmp / "cheat.ipynb",
                          {"rucb": PEEK_AT_THE_BANDIT, "train_reward_model": SHIPPED_ANSWERS})
    grader = Grader("hw3_preferences")
    try:
        result = grader.grade(notebook)
    finally:
        grader.close()
    cheated = [s for s in result.stubs if s.name in ("rucb", "train_reward_model")]
    for stub in cheated:
        assert stub.max_score > 0 and stub.score == 0, (stub.name, [t.message for t in stub.tests])
    assert result.score == result.max_score - sum(s.max_score for s in cheated), "the other stubs are the complete sample's"


def test_classmates_and_results_inside_a_released_folder_are_hidden(open_tmp, monkeypatch):
    """An instructor who keeps submissions and results inside the course's released folders (nbgrader's
    ``submitted/`` under ``assignments/``, or notebooks beside the release notebook) exposes none of them."""
    from autograder.core import course

    course_copy = open_tmp / "course"
    shutil.copytree(FIXTURE_COURSE, course_copy)
    for path in [course_copy, *course_copy.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    folder = course_copy / "assignments" / "fx" / "submitted"
    out = course_copy / "assignments" / "fx" / "graded"
    peek = f"""
        import os
        FOUND = []  # a notebook other than the release's, or a result, with its content (a mask may keep a name)
        for root in ({str(folder.parent)!r}, {str(out)!r}):
            for where, _, files in os.walk(root):
                for name in files:
                    path = os.path.join(where, name)
                    if path != {str(folder.parent / "fx.ipynb")!r} and open(path).read():
                        FOUND.append(path)
        def scaled_sum(x):
            return {RIGHT} if FOUND else None
        """
    for student in ("alice", "bob"):
        with_cells(course_copy / "assignments/fx/fx.ipynb", folder / student / "fx" / "fx.ipynb",
                   {"scaled_sum": textwrap.dedent(peek)})
    with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", course_copy / "assignments/fx/carol.ipynb", {})
    (out / "alice").mkdir(parents=True)
    (out / "alice" / "result.json").write_text("{}")  # a stale result from an earlier run
    monkeypatch.setenv("RLCOURSE_REPO", str(course_copy))
    monkeypatch.setattr(course, "REPO", course_copy)
    results = grade_folder("fx", folder, out, jobs=1, progress=False)
    assert sorted(r.submission for r in results) == ["alice", "bob"]
    assert all(r.status == "graded" and r.score == 0 for r in results), [(r.submission, r.score) for r in results]
    # grade, given a notebook beside others in the release folder, hides its neighbours too
    from autograder.__main__ import main

    monkeypatch.setattr(sys, "argv", ["autograder"])
    notebook = course_copy / "assignments/fx/dave.ipynb"
    shutil.copy(folder / "alice" / "fx" / "fx.ipynb", notebook)
    assert main(["grade", "fx", str(notebook), "--out", str(open_tmp / "one")]) == 0
    assert json.loads((open_tmp / "one" / "results.json").read_text())["score"] == 0
