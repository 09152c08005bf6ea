"""What the grader tells the zygote about one worker: its limits and its file-system view.

Plain data, sent as JSON over the zygote's socket; used by both sides.
"""
from __future__ import annotations

from dataclasses import dataclass, field

ZYGOTE_READY = b"R"
"""What the zygote writes on its socket once its imports are done, before it serves any request."""
SAFE_ENV = frozenset({"PATH", "LANG", "MUJOCO_GL", "PYOPENGL_PLATFORM", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                      "OPENBLAS_NUM_THREADS", "OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "VIRTUAL_ENV",
                      "PYTHONPATH", "PYTHONHASHSEED", "PYTHONDONTWRITEBYTECODE", "PYTHONNOUSERSITE", "PYTHONUTF8",
                      "PYTHONIOENCODING", "PYTHONSAFEPATH"})
"""The only environment variables a sandbox process ever holds (with ``LC_*``): no tokens, no paths of the
grader's. The zygote is started with just these, so even the environment block it was born with (which
``/proc/self/environ`` shows every process forked from it) never held the grader's others."""


def safe_environment(environ: dict[str, str]) -> dict[str, str]:
    """The part of ``environ`` a sandbox process may hold (see :data:`SAFE_ENV`)."""
    return {k: v for k, v in environ.items() if k in SAFE_ENV or k.startswith("LC_")}


@dataclass
class Limits:
    """Resource limits of one worker.

    The grader enforces the deadlines and the message cap: ``call_seconds`` per call, ``test_seconds`` per
    hidden test counted from its start (every call, write and callback of the test included: a worker that
    keeps calling back cannot stretch it), ``exec_seconds`` per cell, ``submission_seconds`` for all of a
    submission's time in the sandbox, and ``message_bytes``, the most one message from the worker may hold;
    ``trusted_bytes`` and ``reference_calls`` bound the grader's own work for one test. The rest are kernel
    limits set in the worker (``memory_bytes`` per process there, and for the whole tree by the grader).
    """

    call_seconds: float = 20.0
    test_seconds: float = 180.0
    exec_seconds: float = 60.0
    submission_seconds: float = 600.0
    message_bytes: int = 64 * 1024**2
    memory_bytes: int = 4 * 1024**3
    cpu_seconds: int = 900
    processes: int = 64
    file_bytes: int = 16 * 1024**2
    tmp_bytes: int = 64 * 1024**2
    open_files: int = 256
    trusted_bytes: int = 1024**3
    """How much the grader's own address space may grow while one test runs (its work for the submission)."""
    reference_calls: int = 5000
    """How many times one test's code may call a reference stand-in (a dependency of the stub under test)."""


@dataclass
class View:
    """The worker's whole file system: an allowlist, built fresh for each worker.

    ``expose`` are paths (folders or files) shown read-only at the same place; ``mask`` are paths
    inside them shown as empty (instructor tools inside a released folder). Nothing else of the
    machine exists in the view but ``/proc``, a few devices and a private ``/tmp``. The worker
    reads files with the file-system identity ``read_as`` (uid, gid): the owner of the course
    checkout, so that a checkout of mode 700 and files of mode 600 stay readable without being
    widened for anyone else.

    Where no view can be built (isolation "none": a container that refuses namespaces) and the grader
    runs as root, the worker runs as a uid of its own instead, and the file modes are the only wall:
    ``secret`` are the paths it must then not reach (the hidden suites, the solutions, the grading's
    inputs and outputs), ``expose`` those it must read. The worker refuses to start otherwise
    (``python -m autograder permissions`` sets the modes).
    """

    expose: list[str] = field(default_factory=list)
    mask: list[str] = field(default_factory=list)
    read_as: tuple[int, int] = (0, 0)
    secret: list[str] = field(default_factory=list)


@dataclass
class SpawnConfig:
    """What the zygote needs to start one worker."""

    view: View = field(default_factory=View)
    limits: Limits = field(default_factory=Limits)

    @classmethod
    def from_json(cls, raw: dict) -> "SpawnConfig":
        view = raw["view"]
        return cls(View(list(view["expose"]), list(view["mask"]), tuple(view["read_as"]), list(view.get("secret", []))),
                   Limits(**raw["limits"]))
