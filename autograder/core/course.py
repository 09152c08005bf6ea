"""Where an assignment's pieces live in this repository (or in the Gradescope bundle built from it)."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterable

INSTALLED = Path(__file__).resolve().parents[2]
"""The repository this package runs from."""
REPO = Path(os.environ.get("RLCOURSE_REPO", INSTALLED))
"""The course being graded: this repository, or another laid out the same way (tests use a small one)."""


def assignment_ids() -> list[str]:
    """Assignments that have a solution notebook, in order."""
    return sorted(p.name for p in (REPO / "solutions").iterdir() if (p / f"{p.name}.ipynb").exists())


def solution_notebook(assignment: str) -> Path:
    return REPO / "solutions" / assignment / f"{assignment}.ipynb"


def release_notebook(assignment: str) -> Path:
    return REPO / "assignments" / assignment / f"{assignment}.ipynb"


def suite_dir(assignment: str) -> Path:
    return REPO / "autograder" / "suites" / assignment


def common_helpers() -> Path:
    """``autograder/suites/sandbox_common.py``: helpers every suite may call (``student.helpers.<name>``), run in
    the sandbox before the suite's own ``sandbox_helpers.py``, into the same module."""
    return REPO / "autograder" / "suites" / "sandbox_common.py"


def samples_root() -> Path:
    """``autograder/samples/``: a folder of sample submissions per assignment."""
    return REPO / "autograder" / "samples"


def samples_dir(assignment: str) -> Path:
    return samples_root() / assignment


def check_assignment(assignment: str) -> None:
    """Fail early, with the list of known ids, on a mistyped assignment id."""
    if not release_notebook(assignment).exists() or not suite_dir(assignment).is_dir():
        known = ", ".join(i for i in assignment_ids() if suite_dir(i).is_dir())
        raise SystemExit(f"unknown or ungradable assignment {assignment!r}; gradable ones: {known}")


def stub_owner(names: set[str], exclude: str) -> str | None:
    """The assignment other than ``exclude`` with the most stubs among ``names`` (grading ids and names a
    notebook's code cells define), or None when no other assignment's stub is among them."""
    counts = []
    for other in assignment_ids():
        if other == exclude or not release_notebook(other).is_file():  # a grading bundle may ship one assignment
            continue
        try:
            counts.append((len(names & set(stub_names(other))), other))
        except Exception:  # noqa: BLE001 - an assignment being written may not read yet: it is no one's answer
            continue
    best = max(counts, default=(0, None))
    return best[1] if best[0] else None


def stub_names(assignment: str) -> list[str]:
    """The graded stubs of an assignment, in notebook order (from its student notebook)."""
    from autograder.core.notebook import read_notebook, release_plan

    return [c.label for c in release_plan(read_notebook(release_notebook(assignment))) if c.kind == "stub"]


PER_TEST_KEYS = ("tests", "tests_reference")
"""The keys of ``limits.json`` that are not fields of ``Limits``: each hidden test's own limit, and the reference's
measured time it came from (see :func:`per_test_limits`)."""


def _limits_json(assignment: str) -> dict:
    import json

    path = suite_dir(assignment) / "limits.json"
    return json.loads(path.read_text()) if path.exists() else {}


def limits(assignment: str) -> "Limits":
    """The sandbox limits of an assignment: defaults, overridden by its suite's ``limits.json``."""
    from autograder.sandbox.config import Limits

    raw = _limits_json(assignment)
    return Limits(**{k: v for k, v in raw.items() if k not in PER_TEST_KEYS})


def per_test_limits(assignment: str) -> dict[str, float]:
    """Each hidden test's own time limit in seconds, by pytest node id (``test_rucb.py::test_regret``), from the
    ``"tests"`` object of the suite's ``limits.json``; a test not named there has ``test_seconds``.

    The rule that wrote them (``python -m autograder.authoring.limits ID``): the complete sample is graded once,
    and a test whose reference run took ``t`` seconds of its own (its wall time from its start to its end, less
    the time the worker and the grader spent waiting for a busy CPU) gets ``MULTIPLE * t + CONSTANT`` seconds
    (``autograder/authoring/limits.py``), never more than ``test_seconds``. The CPU-wait credit of every
    deadline applies on top, as for any limit. A test's own limit bounds all of its calls, those with a
    suite's own ``timeout`` too, but not the cells re-run after a crash.
    """
    tests = _limits_json(assignment).get("tests", {})
    return {str(k): float(v) for k, v in tests.items()}


STUDENT_RELEASE = ("assignments", "lectures", "rlcourse", "datasets")
"""The folders of the student release (``make student-release``), and all a sandbox shows of the course
(of ``assignments/``, only the release notebooks)."""
INSTRUCTOR_ONLY = ("datasets/scripts", "lectures/figures/make_figures.py")
"""Instructor tools inside those folders, left out of both: the data scripts fit models that students
write, and the figure script computes soft value iteration, visitation frequencies and RUCB."""


def release_paths(root: Path) -> tuple[list[Path], list[Path]]:
    """The released folders of the course at ``root``, and the instructor-only paths inside them."""
    shown = [root / name for name in STUDENT_RELEASE if (root / name).exists()]
    masked = [root / name for name in INSTRUCTOR_ONLY if (root / name).exists()]
    return shown, masked


def release_notebooks(assignments: Path, only: str | None = None) -> list[Path]:
    """The release notebooks in an ``assignments/`` folder (``<id>/<id>.ipynb``): all the sandbox shows of it,
    so a student's notebook an instructor keeps there (nbgrader's ``submitted/``, or beside the release
    notebook), or results written there, never show. With ``only``, that assignment's alone."""
    return sorted(p for p in assignments.glob("*/*.ipynb")
                  if p.stem == p.parent.name and p.is_file() and only in (None, p.stem))


LIBRARY = "rlcourse"
"""The student library: the one package of the release that a notebook, and so a stub, imports."""


def _library_file(root: Path, module: str) -> Path | None:
    """The source file of library module ``module`` under ``root`` (``rlcourse.lm`` -> ``rlcourse/lm.py``)."""
    parts = module.split(".")
    if parts[0] != LIBRARY:
        return None
    for path in (root.joinpath(*parts).with_suffix(".py"), root.joinpath(*parts, "__init__.py")):
        if path.is_file():
            return path
    return None


def library_modules(assignment: str, root: Path | None = None) -> set[Path]:
    """The library files grading ``assignment`` needs: the modules that its trusted cells (the release's
    parameters and setup), its reference's stub cells and its suite's sandbox helpers import, and all that
    those import in turn (each module's imports read from its AST, those inside functions too).

    A worker grading ``assignment`` sees these and no other module of the library (:func:`library_masks`):
    a helper written for another assignment (a fitter, a planner, a loss) can then never answer one of this
    assignment's stubs, under its own name or behind an adapter. A student's stub may import anything its
    reference imports, so a correct stub never misses a module.
    """
    from autograder.core.notebook import imported_names, read_notebook, release_plan

    root = Path(root or REPO)
    sources = [c.source for c in release_plan(read_notebook(release_notebook(assignment))) if c.kind != "stub"]
    sources += [c.source for c in release_plan(read_notebook(solution_notebook(assignment))) if c.kind == "stub"]
    sources += [p.read_text() for p in (common_helpers(), suite_dir(assignment) / "sandbox_helpers.py") if p.is_file()]
    wanted = {n for s in sources for n in imported_names(s) if n.split(".")[0] == LIBRARY}
    found: dict[str, Path] = {}
    while wanted:
        module = wanted.pop()
        path = _library_file(root, module)
        if path is None or module in found:
            continue
        found[module] = path
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        wanted |= {n for n in imported_names(path.read_text(), package) if n.split(".")[0] == LIBRARY} - set(found)
    init = root / LIBRARY / "__init__.py"
    return {*found.values(), *([init] if init.is_file() else [])}


def library_masks(assignment: str, root: Path | None = None) -> list[Path]:
    """What a worker grading ``assignment`` must not read of the library at ``root``: every module outside
    :func:`library_modules`, and every compiled cache (``__pycache__``), which would hold a masked module's
    code (a worker compiles what it imports from source, in memory)."""
    library = Path(root or REPO) / LIBRARY
    if not library.is_dir():
        return []
    needed = library_modules(assignment, library.parent)
    with contextlib.suppress(OSError):  # a cache the grader's own imports make later would not be masked: make it now
        (library / "__pycache__").mkdir(exist_ok=True)
    caches = sorted(p for p in library.rglob("__pycache__") if p.is_dir())
    return [*(p for p in sorted(library.rglob("*.py")) if p not in needed and "__pycache__" not in p.parts), *caches]


def sandbox_view(hide: "Iterable[Path]" = (), assignment: str | None = None) -> "View":
    """What a sandbox worker sees: the student release of this course and of the installed library,
    and the Python environment; read as the owner of the installed checkout.

    ``hide`` are the grading's own inputs and outputs (a folder of submissions, the notebook being
    graded and those beside it, an output folder): where an instructor keeps one inside a released
    folder (nbgrader's ``submitted/`` under ``assignments/``, say), it is masked like the instructor tools.
    With ``assignment``, the view holds that assignment's release notebook only (not another's, whose given
    cells are another assignment's helpers) and, of the library, only what grading it needs
    (:func:`library_masks`); the masked modules are secret too, for a worker without namespaces.
    """
    import sys

    from autograder.sandbox.config import View

    shown, masked = [], []
    for root in dict.fromkeys([INSTALLED, REPO]):
        s, m = release_paths(Path(root))
        shown += [n for p in s for n in (release_notebooks(p, assignment) if p.name == "assignments" else [p])]
        masked += [*m, *(library_masks(assignment, Path(root)) if assignment is not None else ())]
    python = [Path(p) for p in (sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix)]
    paths = [*shown, *python, *(p.resolve() for p in (*shown, *python))]
    paths = sorted({str(p) for p in paths})
    outermost = [p for p in paths if not any(p != q and p.startswith(q.rstrip("/") + "/") for q in paths)]
    inside = [Path(h).resolve() for h in hide if os.path.lexists(h)]
    masked += [h for h in inside if any(str(h).startswith(p.rstrip("/") + "/") for p in outermost)]
    secret = [*masked, *inside, *(p for root in dict.fromkeys([INSTALLED, REPO]) for p in instructor_paths(Path(root)))]
    owner = INSTALLED.stat()
    return View(outermost, sorted({str(p) for p in (*masked, *(m.resolve() for m in masked))}),
                (owner.st_uid, owner.st_gid), sorted({str(p) for p in (*secret, *(s.resolve() for s in secret))}))


INSTRUCTOR_FOLDERS = ("solutions", "autograder/suites", "autograder/samples", "tests", "bench", ".git")
"""Folders of a checkout outside the release whose content would answer or reveal a hidden test."""


def instructor_paths(root: Path) -> list[Path]:
    """What a worker must never read of the course at ``root``: the instructor folders and the instructor tools
    inside released folders (those that exist)."""
    return [p for p in (*(root / f for f in INSTRUCTOR_FOLDERS), *release_paths(root)[1]) if os.path.lexists(p)]


def set_container_permissions(root: Path = REPO, environment: bool = True, assignment: str | None = None) -> list[str]:
    """Make the file modes the only wall a worker needs where it runs without namespaces as a uid of its own
    (isolation "none" as root, the Gradescope and PrairieLearn containers): the instructor paths readable by
    their owner only, the release and the virtual environment readable by everyone, with every folder above
    them searchable (a system Python, or any with ``environment`` false, is left as it is). With ``assignment``
    (the one this container grades), the library modules and compiled caches grading it must not see
    (:func:`library_masks`) are readable by their owner only too; a worker without namespaces refuses to
    serve while they are not. Returns one line per path changed. Meant for a grading container, run as the
    owner of the files (root, there): on a shared machine it would widen the release and the virtual
    environment to every user."""
    import stat
    import sys

    changed = []

    def chmod(path: Path, mode: int) -> None:
        current = stat.S_IMODE(path.lstat().st_mode)
        if current != mode and not path.is_symlink():
            os.chmod(path, mode)
            changed.append(f"{mode:o} {path}")

    secrets = [*instructor_paths(root), *(library_masks(assignment, root) if assignment else ())]
    for secret in secrets:
        for path in [secret, *(secret.rglob("*") if secret.is_dir() and not secret.is_symlink() else ())]:
            chmod(path, stat.S_IMODE(path.lstat().st_mode) & 0o700)
    shown = [n for p in release_paths(root)[0] for n in (release_notebooks(p) if p.name == "assignments" else [p])]
    shown += [Path(sys.prefix)] if environment and sys.prefix != sys.base_prefix else []
    hidden = {str(p) for p in secrets}
    for top in shown:
        for path in [top, *(top.rglob("*") if top.is_dir() else ())]:
            if any(str(path) == h or str(path).startswith(h + "/") for h in hidden):
                continue
            mode = stat.S_IMODE(path.lstat().st_mode)
            chmod(path, mode | (0o055 if path.is_dir() or mode & 0o100 else 0o044))
        for parent in top.resolve().parents:
            chmod(parent, stat.S_IMODE(parent.stat().st_mode) | 0o011)
    return changed


def suite_version(assignment: str) -> str:
    """A digest of what decides a grade: the hidden suite's files, its limits, the solution and the release.

    Recorded by every batch (and shard of one): results graded under different versions are never merged.
    """
    import hashlib

    digest = hashlib.sha256()
    suite = suite_dir(assignment)
    files = [(f"suite/{p.relative_to(suite).as_posix()}", p) for p in sorted(suite.rglob("*"))
             if p.is_file() and "__pycache__" not in p.parts and not p.name.endswith(".pyc")]
    files += [("solution", solution_notebook(assignment)), ("release", release_notebook(assignment))]
    if common_helpers().is_file():
        files.append(("common helpers", common_helpers()))
    for name, path in files:
        data = path.read_bytes()
        digest.update(f"{name}\0{len(data)}\0".encode())
        digest.update(data)
    return digest.hexdigest()[:16]
