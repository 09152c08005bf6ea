"""Isolation of one worker. Runs in the sandbox: in the launcher (namespaces) and in the worker itself,
before it reads any student code (the file-system view, limits, the privilege drop).

The order matters and is fixed by :func:`isolate`: namespaces, then the view (which needs privilege
in the new mount namespace), then the limits, then the privilege drop, after which nothing can
be undone: every capability is gone, for this process and for anything it executes.
"""
from __future__ import annotations

import ctypes
import os
import platform
import resource
from typing import Iterable

from autograder.sandbox.config import Limits, View

CLONE_NEWNS, CLONE_NEWUTS, CLONE_NEWIPC = 0x00020000, 0x04000000, 0x08000000
CLONE_NEWUSER, CLONE_NEWPID, CLONE_NEWNET = 0x10000000, 0x20000000, 0x40000000
MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC, MS_REMOUNT = 1, 2, 4, 8, 32
MS_NOATIME, MS_NODIRATIME, MS_BIND, MS_MOVE, MS_REC = 1024, 2048, 4096, 8192, 16384
MS_PRIVATE, MS_RELATIME = 1 << 18, 1 << 21
ST_RELATIME = 4096
MNT_DETACH = 2
PR_SET_DUMPABLE, PR_CAPBSET_DROP, PR_SET_SECUREBITS, PR_SET_NO_NEW_PRIVS, PR_CAP_AMBIENT = 4, 24, 28, 38, 47
PR_SET_PDEATHSIG, PR_CAP_AMBIENT_CLEAR_ALL = 1, 4
SECBIT_NOROOT, SECBIT_NO_SETUID_FIXUP, SECBIT_NO_CAP_AMBIENT_RAISE = 1 << 0, 1 << 2, 1 << 6
SECBITS_LOCKED = (1 << 1) | (1 << 3) | (1 << 5) | (1 << 7)
LINUX_CAPABILITY_VERSION_3 = 0x20080522
SYS_PIVOT_ROOT = {"x86_64": 155, "aarch64": 41}.get(platform.machine())

DEVICES = ("null", "zero", "full", "random", "urandom")
"""The device nodes a worker gets; no terminal, no disk, no GPU."""
SYSTEM = ("/usr", "/bin", "/lib", "/lib32", "/lib64", "/libx32", "/sbin")
"""System folders every view holds read-only (programs and shared libraries, nothing of a user's)."""
ETC = ("/etc/ld.so.cache", "/etc/ld.so.conf", "/etc/ld.so.conf.d", "/etc/localtime", "/etc/nsswitch.conf",
       "/etc/passwd", "/etc/group", "/etc/fonts", "/etc/mime.types", "/etc/alternatives")
"""The configuration that the dynamic loader, libc and matplotlib read; no secrets, no host names."""
OPEN_FILES_CEILING = 1 << 16
"""Descriptors above this are never inherited: the grader's own limit is far below it."""
SKELETON_BYTES = 1024 * 1024
"""Size of the view's own root: it only holds the empty folders that mounts sit on."""

libc = ctypes.CDLL(None, use_errno=True)


class IsolationError(OSError):
    """A step of the isolation failed; the worker must not run student code."""


def _check(result: int, what: str) -> None:
    if result != 0:
        err = ctypes.get_errno()
        raise IsolationError(err, f"{what}: {os.strerror(err)}")


def _mount(source: str | None, target: str, fstype: str | None, flags: int, data: str | None = None) -> None:
    def enc(s: str | None) -> bytes | None:
        return None if s is None else s.encode()

    _check(libc.mount(enc(source), enc(target), enc(fstype), ctypes.c_ulong(flags), enc(data)), f"mount {target}")


# ------------------------------------------------------------------ launcher: namespaces

def enter_namespaces() -> str:
    """[launcher] Unshare mount, network, PID, IPC and UTS namespaces; return the isolation level.

    As root the namespaces are made directly ("full"); as a normal user inside a new user
    namespace where the user is root ("user-namespace"). Where neither is allowed (some
    containers) nothing is unshared and the level is "none": limits alone, isolation partial.
    """
    flags = CLONE_NEWNS | CLONE_NEWNET | CLONE_NEWPID | CLONE_NEWIPC | CLONE_NEWUTS
    try:
        if os.geteuid() == 0:
            _check(libc.unshare(flags), "unshare")
            return "full"
        uid, gid = os.geteuid(), os.getegid()
        _check(libc.unshare(flags | CLONE_NEWUSER), "unshare")
        with open("/proc/self/setgroups", "w") as f:
            f.write("deny")
        with open("/proc/self/uid_map", "w") as f:
            f.write(f"0 {uid} 1")
        with open("/proc/self/gid_map", "w") as f:
            f.write(f"0 {gid} 1")
        return "user-namespace"
    except OSError:
        return "none"


IPC_CLOSED = {"/proc/sys/kernel/shmmni": "0", "/proc/sys/kernel/shmall": "0", "/proc/sys/kernel/msgmni": "0",
              "/proc/sys/kernel/sem": "0 0 0 0"}
"""System V IPC in the worker's own namespace: no segment, queue or semaphore set. A shared-memory segment
holds its memory after every process has unmapped it, where no look at the processes can see it."""


def close_ipc() -> bool:
    """[launcher, in its new IPC namespace] Allow no System V IPC object there; False where the kernel refused.
    Nothing the course runs uses System V IPC (Python's multiprocessing and torch use memory files)."""
    try:
        for path, value in IPC_CLOSED.items():
            with open(path, "w") as f:
                f.write(value)
        return True
    except OSError:
        return False


# ------------------------------------------------------------------ worker: the file-system view

def _locked_flags(fd: int) -> int:
    """Mount flags a bind of the folder or file open as ``fd`` must keep (a user namespace may not clear them)."""
    f = os.statvfs(fd).f_flag
    flags = f & (MS_NOSUID | MS_NODEV | MS_NOEXEC | MS_NOATIME | MS_NODIRATIME)
    return flags | (MS_RELATIME if f & ST_RELATIME else 0)


def _place(root: str, path: str, is_dir: bool) -> str:
    """Create the empty folder or file that a mount of ``path`` will sit on inside ``root``."""
    target = root + path
    if is_dir:
        os.makedirs(target, exist_ok=True)
    else:
        os.makedirs(os.path.dirname(target), exist_ok=True)
        if not os.path.exists(target):
            os.close(os.open(target, os.O_CREAT | os.O_WRONLY, 0o444))
    return target


def _bind_readonly(fd: int, target: str, devices: bool = False) -> None:
    _mount(f"/proc/self/fd/{fd}", target, None, MS_BIND | MS_REC)
    flags = MS_BIND | MS_REMOUNT | MS_RDONLY | MS_NOSUID | (0 if devices else MS_NODEV) | _locked_flags(fd)
    _mount(None, target, None, flags)


def _tmpfs(target: str, size: int, mode: str, flags: int = MS_NOSUID | MS_NODEV) -> None:
    _mount("tmpfs", target, "tmpfs", flags, f"size={size},mode={mode}")


def _pivot(root: str) -> None:
    """Make ``root`` the file system's root and drop every mount of the old one."""
    os.chdir(root)
    os.mkdir(".old")
    if SYS_PIVOT_ROOT is not None and libc.syscall(SYS_PIVOT_ROOT, b".", b".old") == 0:
        os.chroot(".")
        _check(libc.umount2(b"/.old", MNT_DETACH), "umount the old root")
        os.rmdir("/.old")
    else:  # pivot_root refused (the old root is not a mount point in some containers): move and chroot
        os.rmdir(".old")
        _mount(root, "/", None, MS_MOVE)
        os.chroot(".")
    os.chdir("/")


def build_view(view: View, tmp_bytes: int) -> None:
    """[worker, privileged, in its new mount namespace] Replace the whole file system by ``view``.

    Sources are opened before anything is mounted, so a course checked out under ``/tmp`` (which
    the view's own ``/tmp`` covers) or in a folder closed to others (``/root``, a mode-700
    checkout) is bound in all the same: the folders leading to each exposed path are made anew
    in the view, open to the worker, and hold nothing else.
    """
    _mount(None, "/", None, MS_REC | MS_PRIVATE)
    wanted = [p for p in dict.fromkeys([*SYSTEM, *ETC, *view.expose]) if os.path.lexists(p)]
    links = {p: os.readlink(p) for p in wanted if os.path.islink(p) and p in SYSTEM}
    sources = [(p, os.open(p, os.O_PATH | os.O_CLOEXEC)) for p in wanted if p not in links]
    devices = [(d, os.open(f"/dev/{d}", os.O_PATH | os.O_CLOEXEC)) for d in DEVICES if os.path.exists(f"/dev/{d}")]
    try:
        root = "/tmp"
        _tmpfs(root, SKELETON_BYTES, "0755")
        # The private /tmp first: a course checked out under /tmp is bound on top of it, not hidden by it.
        _tmpfs(_place(root, "/tmp", is_dir=True), tmp_bytes, "1777")
        for path, target in links.items():
            os.symlink(target, root + path)
        for path, fd in sorted(sources, key=lambda s: s[0].count("/")):
            _bind_readonly(fd, _place(root, path, os.path.isdir(f"/proc/self/fd/{fd}")))
        for path in view.mask:
            if os.path.isdir(root + path):
                _tmpfs(root + path, 4096, "0555", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC)
            elif os.path.exists(root + path):
                empty = _place(root, "/.masked", is_dir=False)
                _mount(empty, root + path, None, MS_BIND)
                _mount(None, root + path, None, MS_BIND | MS_REMOUNT | MS_RDONLY | MS_NOSUID | MS_NODEV)
        _tmpfs(_place(root, "/dev", is_dir=True), 65536, "0755", MS_NOSUID | MS_NOEXEC)
        for name, fd in devices:
            _bind_readonly(fd, _place(root, f"/dev/{name}", is_dir=False), devices=True)
        for name, target in (("fd", "/proc/self/fd"), ("stdin", "/proc/self/fd/0"), ("stdout", "/proc/self/fd/1"),
                             ("stderr", "/proc/self/fd/2")):
            os.symlink(target, f"{root}/dev/{name}")
        _tmpfs(_place(root, "/dev/shm", is_dir=True), tmp_bytes, "1777")
        _mount(None, root + "/dev", None, MS_REMOUNT | MS_RDONLY | MS_NOSUID | MS_NOEXEC, "size=65536,mode=0755")
        try:  # a /proc of the worker's own PID namespace, read-only (no sysctl writes)
            _mount("proc", _place(root, "/proc", is_dir=True), "proc", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC)
        except IsolationError:
            pass  # refused inside some containers: the worker then has no /proc at all
    finally:
        for _, fd in [*sources, *devices]:
            os.close(fd)
    _pivot(root)
    _mount(None, "/", None, MS_BIND | MS_REMOUNT | MS_RDONLY | MS_NOSUID | MS_NODEV)


# ------------------------------------------------------------------ worker: limits and privileges

def processes_of(uid: int) -> int:
    """[launcher] How many processes (threads included, as RLIMIT_NPROC counts them) ``uid`` runs now."""
    count = 0
    for pid in os.listdir("/proc"):
        try:
            if pid.isdigit() and os.stat(f"/proc/{pid}").st_uid == uid:
                count += len(os.listdir(f"/proc/{pid}/task"))
        except OSError:
            pass
    return count


def set_limits(limits: Limits, processes: int) -> None:
    """[worker] Kernel limits on memory, CPU time, processes, file size and open files; no core dumps."""
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


def _last_capability() -> int:
    try:
        with open("/proc/sys/kernel/cap_last_cap") as f:
            return int(f.read())
    except (OSError, ValueError):
        return 63


def _drop_capabilities() -> None:
    """Empty every capability set (bounding, ambient, effective, permitted, inheritable), for good."""
    for cap in range(_last_capability() + 1):
        libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0)  # fails only for numbers this kernel does not know
    libc.prctl(PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0)
    header = (ctypes.c_uint32 * 2)(LINUX_CAPABILITY_VERSION_3, 0)
    data = (ctypes.c_uint32 * 6)()
    _check(libc.capset(header, data), "capset")
    _check(libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0), "no_new_privs")


def drop_privileges(uid: int | None, read_as: tuple[int, int]) -> None:
    """[worker] Become unprivileged for good.

    As root (``uid`` given): the worker's real, effective and saved ids become ``uid``, a uid of its
    own (it can signal, count processes and own keys as nobody else), while its file-system ids
    become ``read_as``, the owner of the course checkout, so the view's read-only files of mode
    600 stay readable. In a user namespace (``uid`` None) the ids stay those of the user who runs
    the grader, who owns the checkout. Either way every capability is dropped, so no mount,
    ``setuid`` or ``chown`` is possible any more, and programs the worker starts gain nothing.
    """
    if uid is not None:
        _check(libc.prctl(PR_SET_SECUREBITS, SECBIT_NOROOT | SECBIT_NO_SETUID_FIXUP | SECBIT_NO_CAP_AMBIENT_RAISE
                           | SECBITS_LOCKED, 0, 0, 0), "securebits")
        os.setgroups([])
        os.setresgid(uid, uid, uid)
        os.setresuid(uid, uid, uid)
        libc.setfsgid(ctypes.c_uint(read_as[1]))
        libc.setfsuid(ctypes.c_uint(read_as[0]))
        if libc.setfsuid(ctypes.c_uint(0xFFFFFFFF)) != read_as[0]:  # an invalid id reads the current one
            raise IsolationError(0, "could not set the file-system identity")
    _drop_capabilities()
    if not _capabilities_empty():
        raise IsolationError(0, "capabilities remain after the drop")


def _capabilities_empty() -> bool:
    try:
        with open("/proc/self/status") as f:
            fields = dict(line.split(":", 1) for line in f if ":" in line)
    except OSError:
        return True  # no /proc in this view: capset's success is the check
    return all(int(fields.get(k, "0").strip(), 16) == 0 for k in ("CapEff", "CapPrm", "CapBnd", "CapAmb"))


def _reachable(path: str) -> bool:
    """Whether this process can read ``path``, list it, or pass through it (a folder it can search)."""
    return os.path.lexists(path) and (os.access(path, os.R_OK) or (os.path.isdir(path) and os.access(path, os.X_OK)))


def _unreadable_in(top: str, skip: set[str], limit: int = 20000) -> str | None:
    """The first file or folder under ``top`` (``top`` included, at most ``limit`` entries, none under ``skip``)
    this process cannot read."""
    if not os.access(top, os.R_OK | (os.X_OK if os.path.isdir(top) else 0)):
        return top
    seen = 0
    for folder, dirs, files in os.walk(top, onerror=lambda err: None):
        dirs[:] = [d for d in dirs if os.path.join(folder, d) not in skip]
        for name in (*dirs, *files):
            path = os.path.join(folder, name)
            if path not in skip and not os.path.islink(path) and \
                    not os.access(path, os.R_OK | (os.X_OK if os.path.isdir(path) else 0)):
                return path
            seen += 1
            if seen >= limit:
                return None
    return None


def check_file_modes(view: View, python: Iterable[str]) -> None:
    """[worker, no view, own uid] Refuse to serve unless the modes wall the grading off: no ``view.secret``
    path reachable, every exposed path readable (the course's folders entry by entry, the Python environments
    ``python`` at their top only). Raises :class:`IsolationError` naming the first problem and the fix."""
    fix = ("run `python -m autograder permissions --assignment ID` as root in the course checkout, ID the "
           "assignment being graded (docs/grading.md)")
    reachable = [p for p in view.secret if _reachable(p)]
    if reachable:
        raise IsolationError(0, f"no namespaces here, and a worker of its own uid could read {reachable[0]} "
                                f"(the hidden suites and solutions must be readable by their owner only): {fix}")
    prefixes = tuple(str(p).rstrip("/") + "/" for p in python)
    for top in view.expose:
        inside_python = any((top.rstrip("/") + "/").startswith(p) or p.startswith(top.rstrip("/") + "/")
                            for p in prefixes)
        problem = (top if not os.access(top, os.R_OK) else None) if inside_python else \
            _unreadable_in(top, {*view.secret, *view.mask})
        if problem:
            raise IsolationError(0, f"no namespaces here, and a worker of its own uid could not read {problem}, "
                                    f"which the course's release needs: {fix}")


def close_fds_except(keep: Iterable[int]) -> None:
    """[worker] Close every inherited descriptor but ``keep`` (and 0, 1, 2)."""
    start = 3
    for fd in sorted(k for k in set(keep) if k >= 3):
        os.closerange(start, fd)
        start = fd + 1
    os.closerange(start, OPEN_FILES_CEILING)
