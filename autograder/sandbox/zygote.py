"""The zygote and the launcher. Runs in the sandbox's own processes, never in the grader.

The grader starts the zygote as a fresh interpreter (``python -m autograder.sandbox.zygote``, see
:mod:`autograder.core.supervisor`), never as a fork of itself: every worker is forked from the zygote
and inherits its memory, which therefore holds this package and the preloaded libraries and
nothing of the grader (no reference namespace, no suite, no solution text). The zygote imports the assignment's libraries once (torch, gymnasium, ... take over a
second) and then, for each request on its socket, forks a *launcher*, which enters new namespaces
and forks the *worker* (PID 1 of its namespace). The worker isolates itself
(:mod:`autograder.sandbox.isolation`) and serves requests (:mod:`autograder.sandbox.worker`).
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import sys
import tempfile

from autograder.sandbox import isolation
from autograder.sandbox.config import ZYGOTE_READY, SpawnConfig, safe_environment
from autograder.sandbox.wire import send_message
from autograder.sandbox.worker import serve

WORKER_UID_BASE, WORKER_UID_SPAN = 20000, 40000
"""As root, each live worker runs as a uid of its own from this range (so workers cannot signal each other)."""
MAX_REQUEST_BYTES = 1 << 20
"""A spawn request (its JSON config) is far smaller than this."""
WORKDIR = "/tmp/work"
PR_SET_CHILD_SUBREAPER = 36
IMPORT_TIME_PROBES = {"gymnasium": ("gymnasium.envs.mujoco.mujoco_rendering",)}
"""Modules imported in the zygote whenever their package is preloaded, because importing them starts a
program (glfw checks its library's version in a child interpreter). A worker reads the course's files
with the identity of their owner, but a program it starts reads with the worker's own uid (exec resets
the file-system identity), which a checkout of mode 700 shuts out: such probes must run here, before."""
LAZY_IMPORTS = {"torch": ("torch._dynamo",)}
"""Modules a preloaded package imports lazily, on first use, at a cost every worker would pay again: torch
imports torch._dynamo (about 1 s of CPU) when a submission builds its first optimizer."""


def _boot_worker(config: SpawnConfig, fds: list[int], level: str, uid: int, existing: int,
                 launcher: int | None = None, workdir: str = WORKDIR) -> None:
    """[worker] Isolate, then serve; never returns. Any failure before serving is reported, then the worker dies.

    Without namespaces (``level`` "none") there is no view and no private ``/tmp``: the worker works in a
    folder of its own (``workdir``, mode 700), and as root it still becomes a uid of its own, after which the
    file modes must keep it from the hidden files (:func:`isolation.check_file_modes`) or it refuses to serve.
    """
    to_worker, from_worker, output = fds
    try:
        if level != "none":
            isolation.build_view(config.view, config.limits.tmp_bytes)
        own_uid = uid if level == "full" or (level == "none" and os.geteuid() == 0) else None
        os.makedirs(workdir, exist_ok=True)
        if level != "none":  # in the view's private /tmp: the worker reads and writes it as the checkout's owner
            os.chmod(workdir, 0o777)  # (its file-system identity) and, in programs it starts, as its own uid
        if own_uid is not None:
            os.chown(workdir, own_uid, own_uid)
        os.chdir(workdir)
        keep = safe_environment(dict(os.environ))
        os.environ.clear()
        os.environ.update(keep, HOME=workdir, TMPDIR=workdir, MPLCONFIGDIR=workdir, MPLBACKEND="Agg")
        os.dup2(output, 1)
        os.dup2(output, 2)
        devnull = os.open(os.devnull, os.O_RDONLY)
        os.dup2(devnull, 0)
        isolation.close_fds_except([to_worker, from_worker])
        # Whatever the grader's own streams were (pytest replaces them), the student's go to the pipe.
        sys.stdin = open(0, "r", closefd=False)
        sys.stdout = open(1, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
        sys.stderr = open(2, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
        # RLIMIT_NPROC counts every process of the real uid: a worker's own uid starts at zero,
        # while a normal user's grader shares its uid with everything else that user runs.
        isolation.set_limits(config.limits, config.limits.processes + (0 if own_uid is not None else existing))
        if level != "none":
            isolation.drop_privileges(own_uid, config.view.read_as)
        else:
            os.umask(0o077)  # what it writes in the shared /tmp or /dev/shm stays its own
            if own_uid is not None:
                isolation.drop_privileges(own_uid, (own_uid, own_uid))
                isolation.check_file_modes(config.view, {sys.prefix, sys.base_prefix, sys.exec_prefix})
        _die_with_parent(launcher)
    except BaseException as err:  # noqa: BLE001 - report any set-up failure, then die
        try:
            send_message(from_worker, {"ok": False, "kind": "SandboxError", "error": f"sandbox set-up failed: {err}"})
        except OSError:
            pass
        os._exit(0)
    serve(to_worker, from_worker)
    os._exit(0)


def _die_with_parent(parent: int | None) -> None:
    """Be killed when the process that forked this one ends (set after any change of identity, which clears it).

    The chain grader -> zygote -> launcher -> worker then ends with the grader: a batch killed mid-way
    leaves no worker looping until its CPU limit. ``parent``: its pid, to catch a parent already gone
    (None where it cannot be seen: a worker's parent is outside its pid namespace).
    """
    isolation.libc.prctl(isolation.PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if parent is not None and os.getppid() != parent:
        os._exit(0)


def _launch(config: SpawnConfig, fds: list[int], zygote: int | None = None) -> None:
    """[launcher] Enter namespaces, fork the worker, report its pid, wait for it; never returns."""
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    os.setsid()
    isolation.libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)  # orphans of the worker's tree stay under this one
    level = isolation.enter_namespaces()
    if level != "none":
        isolation.close_ipc()
    _die_with_parent(zygote)
    uid = WORKER_UID_BASE + os.getpid() % WORKER_UID_SPAN
    existing = isolation.processes_of(os.getuid())  # counted before the worker's /proc shows only its own namespace
    workdir = tempfile.mkdtemp(prefix="autograder-worker-") if level == "none" else WORKDIR  # else a private /tmp
    sync_r, sync_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(sync_w)
        os.read(sync_r, 1)
        os.close(sync_r)
        # In a new pid namespace the launcher is outside it (getppid() is 0): the worker cannot check it.
        _boot_worker(config, fds, level, uid, existing, os.getppid() or None, workdir)
    os.close(sync_r)
    send_message(fds[1], {"ok": True, "pid": pid, "pgid": os.getpgid(0), "isolation": level})
    os.write(sync_w, b"go")
    os.close(sync_w)
    for fd in fds:
        os.close(fd)
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:
        pass
    if workdir != WORKDIR:
        shutil.rmtree(workdir, ignore_errors=True)
    os._exit(0)


def main(sock: socket.socket, preload: list[str], grader: int) -> None:
    """[zygote] Pre-import ``preload``, then fork a launcher per request on ``sock``; never returns."""
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children are reaped automatically
    isolation.libc.prctl(isolation.PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # die with the grader
    if os.getppid() != grader:  # the grader died before the line above took effect: nobody will ask for workers
        os._exit(0)
    os.environ.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")
    extra = [m for p in preload
             for m in (*IMPORT_TIME_PROBES.get(p.split(".")[0], ()), *LAZY_IMPORTS.get(p.split(".")[0], ()))]
    for module in [*preload, *extra]:
        try:
            __import__(module)
        except Exception:  # noqa: BLE001 - a module that fails here fails again, visibly, in the worker
            pass
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    sock.sendall(ZYGOTE_READY)  # the grader times a worker's start from here, not from before these imports
    while True:
        try:
            message, fds, _, _ = socket.recv_fds(sock, MAX_REQUEST_BYTES, 3)
        except OSError:
            os._exit(0)
        if not message:
            os._exit(0)
        config = SpawnConfig.from_json(json.loads(message))
        zygote = os.getpid()
        if os.fork() == 0:
            sock.close()
            _launch(config, list(fds), zygote)
        for fd in fds:
            os.close(fd)


if __name__ == "__main__":  # python -m autograder.sandbox.zygote FD PRELOAD_JSON GRADER_PID
    main(socket.socket(fileno=int(sys.argv[1])), json.loads(sys.argv[2]), int(sys.argv[3]))
