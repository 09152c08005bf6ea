"""Start sandbox workers: isolated, resource-limited processes that run student code.

A *zygote* process is forked from the grader before it runs anything heavy; it
imports the assignment's libraries once (torch, gymnasium, ... take over a
second to import) and then forks a fresh worker per request, so a worker starts
in milliseconds and never inherits the grader's thread pools or secrets.

Each worker, before it reads any student code:
- gets new PID, mount, network, IPC and UTS namespaces (as root directly; as a
  normal user inside a new user namespace), so it sees no other process, has
  no network, and killing it kills everything it started;
- mounts an empty read-only tmpfs over every hidden path (the suites, the
  solutions, the samples, the results and the submissions) and a small private
  tmpfs on ``/tmp`` as its working directory;
- sets resource limits (address space, CPU time, processes, file size, open files);
- as root, drops to an unprivileged uid of its own.
Where namespaces are unavailable it falls back to resource limits alone and
says so once: isolation is then partial.
"""
from __future__ import annotations

import ctypes
import json
import os
import resource
import signal
import socket
import sys
import threading
from dataclasses import asdict, dataclass, field
from typing import Any

from autograder.wire import FrameReader, send_message

CLONE_NEWNS, CLONE_NEWUTS, CLONE_NEWIPC = 0x00020000, 0x04000000, 0x08000000
CLONE_NEWUSER, CLONE_NEWPID, CLONE_NEWNET = 0x10000000, 0x20000000, 0x40000000
MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC, MS_REMOUNT = 1, 2, 4, 8, 32
MS_BIND, MS_MOVE, MS_REC, MS_PRIVATE = 4096, 8192, 16384, 1 << 18
PR_SET_DUMPABLE, PR_SET_NO_NEW_PRIVS, PR_SET_PDEATHSIG = 4, 38, 1


@dataclass
class Limits:
    """Resource limits of one worker; ``call_seconds`` and ``submission_seconds`` are enforced by the grader."""

    call_seconds: float = 20.0
    exec_seconds: float = 60.0
    submission_seconds: float = 600.0
    memory_bytes: int = 4 * 1024**3
    cpu_seconds: int = 900
    processes: int = 64
    file_bytes: int = 16 * 1024**2
    tmp_bytes: int = 64 * 1024**2
    open_files: int = 256


@dataclass
class SpawnConfig:
    """What the zygote needs to start one worker (sent as JSON)."""

    hidden_paths: list[str] = field(default_factory=list)
    readonly_paths: list[str] = field(default_factory=list)
    limits: Limits = field(default_factory=Limits)


SAFE_ENV = {"PATH", "LANG", "MUJOCO_GL", "PYOPENGL_PLATFORM", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
            "OPENBLAS_NUM_THREADS", "OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "VIRTUAL_ENV"}

_libc = ctypes.CDLL(None, use_errno=True)


def _check(result: int, what: str) -> None:
    if result != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"{what}: {os.strerror(err)}")


def _mount(source: str | None, target: str, fstype: str | None, flags: int, data: str | None = None) -> None:
    enc = lambda s: None if s is None else s.encode()  # noqa: E731
    _check(_libc.mount(enc(source), enc(target), enc(fstype), ctypes.c_ulong(flags), enc(data)), f"mount {target}")


def _enter_namespaces() -> str:
    """Unshare namespaces in the calling process; return the isolation level reached."""
    flags = CLONE_NEWNS | CLONE_NEWNET | CLONE_NEWPID | CLONE_NEWIPC | CLONE_NEWUTS
    if os.geteuid() == 0:
        _check(_libc.unshare(flags), "unshare")
        return "full"
    uid, gid = os.geteuid(), os.getegid()
    _check(_libc.unshare(flags | CLONE_NEWUSER), "unshare")
    with open("/proc/self/setgroups", "w") as f:
        f.write("deny")
    with open("/proc/self/uid_map", "w") as f:
        f.write(f"0 {uid} 1")
    with open("/proc/self/gid_map", "w") as f:
        f.write(f"0 {gid} 1")
    return "user-namespace"


def _isolate_filesystem(hidden: list[str], readonly: list[str], tmp_bytes: int) -> None:
    """Inside the new mount namespace: private mounts, a fresh /proc, read-only code, hidden paths, a small /tmp."""
    _mount(None, "/", None, MS_REC | MS_PRIVATE)
    _mount("proc", "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC)
    _private_tmp(tmp_bytes, keep=readonly)
    _expose([*readonly, sys.base_prefix])
    for path in readonly:  # the course code and the Python environment: student code cannot alter them
        if os.path.isdir(path):
            keep = os.statvfs(path).f_flag & (MS_NOSUID | MS_NODEV | MS_NOEXEC)  # flags a user namespace must keep
            _mount(path, path, None, MS_BIND | MS_REC)
            _mount(None, path, None, MS_BIND | MS_REMOUNT | MS_RDONLY | keep)
    for path in hidden:
        if os.path.isdir(path):
            _mount("tmpfs", path, "tmpfs", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC, "size=4k,mode=0555")
        elif os.path.exists(path):
            _mount("/dev/null", path, None, MS_BIND)


def _private_tmp(size: int, keep: list[str]) -> None:
    """Fresh, size-limited tmpfs on ``/dev/shm`` and ``/tmp``, keeping the ``keep`` paths that lie in ``/tmp``.

    A course checked out under ``/tmp`` must stay visible: such paths are bind-mounted aside (into
    the new ``/dev/shm``), ``/tmp`` is covered, and the mounts are moved back to where they were.
    """
    options = f"size={size},mode=1777"
    _mount("tmpfs", "/dev/shm", "tmpfs", MS_NOSUID | MS_NODEV, options)
    inside = [p for p in map(os.path.realpath, keep) if p.startswith("/tmp/") and os.path.isdir(p)]
    for i, path in enumerate(inside):
        os.makedirs(f"/dev/shm/.keep{i}")
        _mount(path, f"/dev/shm/.keep{i}", None, MS_BIND | MS_REC)
    _mount("tmpfs", "/tmp", "tmpfs", MS_NOSUID | MS_NODEV, options)
    for i, path in enumerate(inside):
        os.makedirs(path, exist_ok=True)
        _mount(f"/dev/shm/.keep{i}", path, None, MS_MOVE)
        os.rmdir(f"/dev/shm/.keep{i}")


def _expose(targets: list[str]) -> None:
    """Make ``targets`` reachable by an unprivileged uid when a parent folder is closed to others.

    Python often lives under ``/root`` (mode 700). The closed folder is replaced, in this mount
    namespace only, by an empty tmpfs holding just the needed subfolder (moved in from a staging
    bind mount), which also hides everything else in it.
    """
    children: dict[str, set[str]] = {}
    for target in targets:
        parts = os.path.realpath(target).split(os.sep)[1:]
        for depth in range(1, len(parts)):
            folder = os.sep + os.path.join(*parts[:depth])
            if not os.stat(folder).st_mode & 0o001:
                children.setdefault(folder, set()).add(parts[depth])
                break
    for i, (folder, names) in enumerate(sorted(children.items())):
        stage = f"/tmp/.expose{i}"
        for name in names:
            os.makedirs(f"{stage}/{name}")
            _mount(os.path.join(folder, name), f"{stage}/{name}", None, MS_BIND | MS_REC)
        _mount("tmpfs", folder, "tmpfs", MS_NOSUID | MS_NODEV, "size=4k,mode=0755")
        for name in names:
            os.makedirs(os.path.join(folder, name))
            _mount(f"{stage}/{name}", os.path.join(folder, name), None, MS_MOVE)


def _processes_of(uid: int) -> int:
    """How many processes (threads included, as RLIMIT_NPROC counts them) ``uid`` runs now."""
    count = 0
    for pid in os.listdir("/proc"):
        try:
            if pid.isdigit() and os.stat(f"/proc/{pid}").st_uid == uid:
                count += len(os.listdir(f"/proc/{pid}/task"))
        except OSError:
            pass
    return count


def _set_limits(limits: Limits, processes: int) -> None:
    def cap(which: int, value: int) -> None:
        soft, hard = resource.getrlimit(which)
        value = value if hard == resource.RLIM_INFINITY else min(value, hard)
        resource.setrlimit(which, (value, value))

    cap(resource.RLIMIT_AS, limits.memory_bytes)
    cap(resource.RLIMIT_CPU, limits.cpu_seconds)
    cap(resource.RLIMIT_FSIZE, limits.file_bytes)
    cap(resource.RLIMIT_NOFILE, limits.open_files)
    cap(resource.RLIMIT_CORE, 0)
    cap(resource.RLIMIT_NPROC, processes)


def _worker_process(config: SpawnConfig, fds: list[int], isolation: str, uid: int, existing: int) -> None:
    """The worker proper (PID 1 of its namespace when isolated); never returns."""
    to_worker, from_worker, output = fds
    try:
        if isolation != "none":
            _isolate_filesystem(config.hidden_paths, config.readonly_paths, config.limits.tmp_bytes)
        uid = uid if isolation == "full" else None
        workdir = "/tmp/work"
        os.makedirs(workdir, exist_ok=True)
        if uid is not None:
            os.chown(workdir, uid, uid)
        os.chdir(workdir)
        keep = {k: v for k, v in os.environ.items() if k in SAFE_ENV or k.startswith(("LC_", "PYTHON"))}
        os.environ.clear()  # nothing of the grader's environment (tokens, paths) reaches student code
        os.environ.update(keep, HOME=workdir, TMPDIR=workdir, MPLCONFIGDIR=workdir, MPLBACKEND="Agg")
        os.dup2(output, 1)
        os.dup2(output, 2)
        devnull = os.open(os.devnull, os.O_RDONLY)
        os.dup2(devnull, 0)
        for fd in range(3, 1024):
            if fd not in (to_worker, from_worker):
                try:
                    os.close(fd)
                except OSError:
                    pass
        # Whatever the grader's own streams were (pytest replaces them), the student's go to the pipe.
        sys.stdin = open(0, "r", closefd=False)
        sys.stdout = open(1, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
        sys.stderr = open(2, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
        # RLIMIT_NPROC counts every process of the real uid: a worker's own uid starts at zero,
        # while a normal user's grader shares its uid with everything else that user runs.
        _set_limits(config.limits, config.limits.processes + (0 if uid is not None else existing))
        if uid is not None:
            os.setgroups([])
            os.setresgid(uid, uid, uid)
            os.setresuid(uid, uid, uid)
        _libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)
        from autograder.worker import serve

        serve(to_worker, from_worker)
    except BaseException as err:  # noqa: BLE001 - report any set-up failure, then die
        try:
            send_message(from_worker, {"ok": False, "kind": "SandboxError", "error": f"sandbox set-up failed: {err}"})
        except OSError:
            pass
    os._exit(0)


def _launch(config: SpawnConfig, fds: list[int]) -> None:
    """In a fresh child of the zygote: enter namespaces, fork the worker, report its pid, wait for it."""
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    os.setsid()
    try:
        isolation = _enter_namespaces()
    except OSError:
        isolation = "none"
    uid = 20000 + os.getpid() % 40000  # one uid per live worker: workers cannot signal each other
    existing = _processes_of(os.getuid())  # counted before the worker's /proc shows only its own namespace
    sync_r, sync_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(sync_w)
        os.read(sync_r, 1)
        os.close(sync_r)
        _worker_process(config, fds, isolation, uid, existing)
    os.close(sync_r)
    send_message(fds[1], {"ok": True, "pid": pid, "pgid": os.getpgid(0), "isolation": isolation})
    os.write(sync_w, b"go")
    os.close(sync_w)
    for fd in fds:
        os.close(fd)
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:
        pass
    os._exit(0)


def _zygote_main(sock: socket.socket, preload: list[str]) -> None:
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children are reaped automatically
    _libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # die with the grader
    os.environ.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")
    for module in preload:
        try:
            __import__(module)
        except Exception:  # noqa: BLE001 - a module that fails here fails again, visibly, in the worker
            pass
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    while True:
        try:
            message, fds, _, _ = socket.recv_fds(sock, 1 << 20, 3)
        except OSError:
            os._exit(0)
        if not message:
            os._exit(0)
        raw = json.loads(message)
        config = SpawnConfig(raw["hidden_paths"], raw["readonly_paths"], Limits(**raw["limits"]))
        if os.fork() == 0:
            sock.close()
            _launch(config, list(fds))
        for fd in fds:
            os.close(fd)


class Zygote:
    """A pristine, pre-imported process that forks workers on request."""

    def __init__(self, preload: list[str]) -> None:
        parent, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        pid = os.fork()
        if pid == 0:
            parent.close()
            try:
                _zygote_main(child, preload)
            finally:
                os._exit(0)
        child.close()
        self.sock, self.pid = parent, pid
        self.lock = threading.Lock()
        _libc.prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)  # workers may not read the grader's memory

    def spawn(self, config: SpawnConfig) -> "WorkerProcess":
        to_r, to_w = os.pipe()
        from_r, from_w = os.pipe()
        out_r, out_w = os.pipe()
        message = json.dumps(asdict(config)).encode()
        with self.lock:
            socket.send_fds(self.sock, [message], [to_r, from_w, out_w])
        for fd in (to_r, from_w, out_w):
            os.close(fd)
        return WorkerProcess(to_w, from_r, out_r)

    def close(self) -> None:
        self.sock.close()
        try:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass


class WorkerProcess:
    """The grader's end of one worker: request channel, output capture, and kill."""

    OUTPUT_KEEP = 4096

    def __init__(self, to_fd: int, from_fd: int, out_fd: int) -> None:
        self.to_fd, self.reader, self.out_fd = to_fd, FrameReader(from_fd), out_fd
        self.output = bytearray()
        self.pid = self.pgid = None
        self.isolation = "unknown"
        self.alive = True
        self._drain = threading.Thread(target=self._read_output, daemon=True)
        self._drain.start()

    def _read_output(self) -> None:
        while True:
            try:
                chunk = os.read(self.out_fd, 65536)
            except OSError:
                return
            if not chunk:
                return
            self.output += chunk
            del self.output[: -self.OUTPUT_KEEP]

    def start(self, timeout: float) -> dict[str, Any]:
        """Read the launcher's pid report and the worker's ready message."""
        header, _ = self.reader.read_message(timeout)
        self.pid, self.pgid, self.isolation = header.get("pid"), header.get("pgid"), header.get("isolation")
        ready, _ = self.reader.read_message(timeout)
        if not ready.get("ok"):
            raise RuntimeError(ready.get("error", "the sandbox failed to start"))
        return header

    def request(self, header: dict[str, Any], blobs: list[bytes], timeout: float) -> tuple[dict[str, Any], list[bytes]]:
        send_message(self.to_fd, header, blobs)
        return self.reader.read_message(timeout)

    def tail(self) -> str:
        return bytes(self.output[-1500:]).decode("utf-8", "replace")

    def kill(self) -> None:
        """Kill the worker and, through its PID namespace (or process group), everything it started."""
        if not self.alive:
            return
        self.alive = False
        for target, kill in ((self.pid, os.kill), (self.pgid, os.killpg)):
            if isinstance(target, int) and target > 1:
                try:
                    kill(target, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
        for fd in (self.to_fd, self.reader.fd, self.out_fd):
            try:
                os.close(fd)
            except OSError:
                pass
