"""Grade one submission: sandbox its cells, run the hidden suite against it, score each stub.

The suite is plain pytest, run in this (trusted) process with three fixtures
(``student``, ``reference``, ``rng``) supplied by :class:`SuitePlugin`; each
test carries its stub and points on a ``stub`` marker. A stub's score is the
sum of the points of its passing tests; anything that goes wrong in the
student's code (an exception, a timeout, a crash, garbage on the channel)
fails only the test that met it, with a message meant for the student.
"""
from __future__ import annotations

import ast
import contextlib
import io
import os
import sys
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from autograder import course
from autograder.notebook import (NotebookError, find_stubs, imported_modules, manual_cells, read_notebook,
                                 read_submission, release_plan, with_parameters)
from autograder.sandbox import Limits, Zygote
from autograder.session import (Cell, CellStatus, LocalTransport, Namespace, SandboxFailure, Session,
                                StudentError)
from autograder.wire import ProtocolError, decode, encode

FAST_PARAMETERS = {"FAST": True}


@dataclass
class TestOutcome:
    name: str
    stub: str
    points: float
    passed: bool
    message: str = ""
    hint: str | None = None
    seconds: float = 0.0


@dataclass
class StubResult:
    name: str
    tests: list[TestOutcome] = field(default_factory=list)
    note: str = ""

    @property
    def score(self) -> float:
        return sum(t.points for t in self.tests if t.passed)

    @property
    def max_score(self) -> float:
        return sum(t.points for t in self.tests)


@dataclass
class GradeResult:
    assignment: str
    submission: str
    stubs: list[StubResult]
    manual: list[tuple[str, float]]
    notes: list[str] = field(default_factory=list)
    error: str | None = None
    isolation: str = "unknown"
    seconds: float = 0.0

    @property
    def score(self) -> float:
        return sum(s.score for s in self.stubs)

    @property
    def max_score(self) -> float:
        return sum(s.max_score for s in self.stubs)


def feedback_message(exc: BaseException) -> str:
    """What a failed test tells the student."""
    if isinstance(exc, StudentError):
        if exc.kind == "NotImplementedError":
            return "not implemented yet: the stub still raises NotImplementedError"
        return f"your code raised {exc}"
    if isinstance(exc, SandboxFailure):
        return f"your code {exc}"
    if isinstance(exc, AssertionError):
        return str(exc).split("\nassert ")[0].strip() or "a hidden check failed"
    if isinstance(exc, pytest.fail.Exception):
        return str(exc.msg)
    return f"the result could not be checked ({type(exc).__name__}: {str(exc)[:300]}); check its type and shape"


class SuitePlugin:
    """Fixtures for the hidden suites, and the collector of their outcomes."""

    def __init__(self, student: Namespace, reference: Namespace, status: dict[str, CellStatus],
                 session: Session | None = None, dependencies: dict[str, list[str]] | None = None) -> None:
        self.student_ns, self.reference_ns, self.status = student, reference, status
        self.session, self.dependencies = session, dependencies or {}
        self.outcomes: list[TestOutcome] = []
        self.collected: list[tuple[Any, pytest.Item]] = []

    def pytest_collection_modifyitems(self, items: list[pytest.Item]) -> None:
        self.collected = [(i.get_closest_marker("stub"), i) for i in items]

    def pytest_configure(self, config: pytest.Config) -> None:
        config.addinivalue_line("markers", "stub(name, points, hint): the stub a hidden test checks, and its points")

    @pytest.fixture
    def student(self, request: pytest.FixtureRequest) -> Namespace:
        marker = request.node.get_closest_marker("stub")
        stub = marker.kwargs["name"] if marker else None
        status = self.status.get(stub)
        if status is not None and not status.ok:
            pytest.fail(status.message, pytrace=False)
        # The other stubs this one calls run as the reference while it is tested: one mistake, one loss.
        needed = self.dependencies.get(stub, [])
        if self.session is not None and needed:
            self.session.stand_in(needed)
        yield self.student_ns
        if self.session is not None and needed:
            try:
                self.session.restore()
            except (SandboxFailure, StudentError):
                pass

    @pytest.fixture
    def reference(self) -> Namespace:
        return self.reference_ns

    @pytest.fixture
    def rng(self, request: pytest.FixtureRequest) -> np.random.Generator:
        return np.random.default_rng(zlib.crc32(request.node.name.encode()))

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo):
        outcome = yield
        report = outcome.get_result()
        if report.when == "call" or (report.when == "setup" and report.failed):
            marker = item.get_closest_marker("stub")
            kwargs = marker.kwargs if marker else {"name": "(unmarked)", "points": 0}
            exc = call.excinfo.value if call.excinfo is not None else None
            if isinstance(exc, SandboxFailure) and "timed out" in str(exc) and marker:
                # Later checks of a stub that hangs would each wait out the limit again: fail them at once.
                self.status[kwargs["name"]] = CellStatus(False, f"not run: an earlier check of this stub {exc}")
            self.outcomes.append(TestOutcome(
                name=_title(item), stub=kwargs["name"], points=float(kwargs.get("points", 0)), passed=report.passed,
                message="" if exc is None else feedback_message(exc), hint=kwargs.get("hint"),
                seconds=report.duration))


def _title(item: pytest.Item) -> str:
    """A test's first docstring line, else its name in words."""
    doc = (getattr(item, "obj", None).__doc__ or "").strip().splitlines()
    return doc[0] if doc else item.name.removeprefix("test_").replace("_", " ")


def build_reference(assignment: str, parameters: dict[str, Any] = FAST_PARAMETERS) -> dict[str, Any]:
    """Run the solution notebook's parameters (overridden by ``parameters``), setup and solution cells."""
    namespace: dict[str, Any] = {"__name__": "__reference__"}
    for cell in release_plan(read_notebook(course.solution_notebook(assignment))):
        source = with_parameters(cell.source, parameters) if cell.kind == "parameters" else cell.source
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(source, f"<solution {cell.label}>", "exec"), namespace)
    return namespace


def stub_dependencies(assignment: str, stubs: list[str]) -> dict[str, list[str]]:
    """For each stub, the other stubs its reference solution calls (by name)."""
    out = {}
    for cell in read_notebook(course.solution_notebook(assignment)).cells:
        grade_id = cell.metadata.get("nbgrader", {}).get("grade_id")
        if cell.cell_type == "code" and grade_id in stubs:
            try:
                names = {n.id for n in ast.walk(ast.parse(cell.source)) if isinstance(n, ast.Name)}
            except SyntaxError:
                names = set()
            out[grade_id] = sorted((names & set(stubs)) - {grade_id})
    return out


def _safe_hidden(paths: list[Path]) -> list[str]:
    """Paths to hide, minus any that would hide the course code or the Python environment itself."""
    keep = [Path(p).resolve() for p in (course.REPO, sys.prefix, sys.base_prefix)]
    out = []
    for path in paths:
        path = Path(path).resolve()
        if path.exists() and not any(k == path or k.is_relative_to(path) for k in keep):
            out.append(str(path))
    return out


class Grader:
    """Grades submissions of one assignment; build once, call :meth:`grade` many times."""

    def __init__(self, assignment: str, limits: Limits | None = None, hidden: list[Path] = ()) -> None:
        course.check_assignment(assignment)
        self.assignment, self.limits = assignment, limits or course.limits(assignment)
        self.suite = course.suite_dir(assignment)
        release = read_notebook(course.release_notebook(assignment))
        self.plan = release_plan(release)
        self.expected = [c.label for c in self.plan if c.kind == "stub"]
        self.manual = manual_cells(release)
        # The zygote forks before this process runs anything heavy (the reference, pytest).
        self.zygote = Zygote(imported_modules([c.source for c in self.plan if c.kind != "stub"]))
        self.reference_ns = build_reference(assignment)
        self.hidden = _safe_hidden([*course.secret_paths(), *hidden])
        self.readonly = sorted({str(Path(p).resolve()) for p in (course.REPO, course.INSTALLED, sys.prefix)})
        self.catalogue = self._catalogue()
        self.dependencies = stub_dependencies(assignment, self.expected)

    def _reference_call(self, name: str, tree: Any, blobs: list[bytes]) -> tuple[dict[str, Any], list[bytes]]:
        """Run reference ``name`` for a stand-in in the sandbox; plain data in and out, never handles."""
        def refuse(id: int, type_name: str) -> Any:
            raise ProtocolError("objects cannot be sent to the reference")

        try:
            args, kwargs = decode(tree, blobs, refuse)
            value = self.reference_ns[name](*args, **kwargs)
            out_tree, out_blobs = encode(value)
            return {"ok": True, "value": out_tree}, out_blobs
        except Exception as err:  # noqa: BLE001 - reported to the student's code as an exception
            return {"ok": False, "error": f"{type(err).__name__}: {str(err)[:300]}"}, []

    def _catalogue(self) -> list[TestOutcome]:
        """Every hidden test with its stub and points (collected, not run), for results that cannot run."""
        plugin = SuitePlugin(None, None, {})
        self._run_suite(plugin, "--collect-only")
        return [TestOutcome(_title(item), marker.kwargs["name"], float(marker.kwargs["points"]), False,
                            hint=marker.kwargs.get("hint")) for marker, item in plugin.collected if marker]

    def cells_for(self, stubs: dict[str, Any]) -> list[Cell]:
        cells = []
        for c in self.plan:
            if c.kind == "parameters":
                cells.append(Cell(c.label, with_parameters(c.source, FAST_PARAMETERS)))
            elif c.kind == "setup":
                cells.append(Cell(c.label, c.source))
            elif c.label in stubs:
                cells.append(Cell(c.label, stubs[c.label].source, stub=c.label))
        return cells

    def grade(self, path: str | Path, name: str | None = None, hidden: list[Path] = ()) -> GradeResult:
        start = time.monotonic()
        path = Path(path)
        result = GradeResult(self.assignment, name or path.name, [], list(self.manual))
        try:
            nb, notes = read_submission(path)
        except (NotebookError, OSError) as err:
            return self._ungradable(result, f"could not read the notebook: {err}", start)
        stubs, match_notes = find_stubs(nb, self.expected)
        result.notes += notes + match_notes
        session = Session(self.zygote, self.cells_for(stubs), self.hidden + _safe_hidden(list(hidden)),
                          self.readonly, self.limits)
        for missing in set(self.expected) - set(stubs):
            session.status[missing] = CellStatus(False, f"no cell defines `{missing}` (was its cell deleted, or the "
                                                          "function renamed?)")
        try:
            session.start()
            broken_setup = [s.message for label, s in session.status.items()
                            if not s.ok and label not in self.expected]
            if broken_setup:
                for stub in self.expected:
                    session.status[stub] = CellStatus(False, "the notebook's setup failed in the grader: "
                                                             + broken_setup[0])
            result.isolation = session.isolation
            session.reference_call = self._reference_call
            plugin = SuitePlugin(Namespace(session, "student"),
                                 Namespace(LocalTransport(self.reference_ns), "reference"), session.status,
                                 session, self.dependencies)
            self._run_suite(plugin)
        except SandboxFailure as err:
            return self._ungradable(result, str(err), start)
        finally:
            session.close()
        result.stubs = self._collect(plugin.outcomes)
        if session.restarts:
            result.notes.append(f"the sandbox was restarted {session.restarts} time(s) after failures in your code")
        result.seconds = time.monotonic() - start
        return result

    def _run_suite(self, plugin: SuitePlugin, *extra: str) -> None:
        suite = self.suite
        args = [str(suite), *extra, "-q", "-p", "no:cacheprovider", "--import-mode=importlib", "-c", os.devnull,
                "--rootdir", str(suite), "-o", "python_files=test_*.py", "-W", "ignore::DeprecationWarning"]
        log = io.StringIO()
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            code = pytest.main(args, plugins=[plugin])
        for module in [m for m, mod in sys.modules.items() if str(getattr(mod, "__file__", "")).startswith(str(suite))]:
            del sys.modules[module]
        if code not in (pytest.ExitCode.OK, pytest.ExitCode.TESTS_FAILED) or not (plugin.outcomes or plugin.collected):
            raise RuntimeError(f"the hidden suite of {self.assignment} could not run (pytest exit {code}):\n"
                               + log.getvalue()[-3000:])

    def _collect(self, outcomes: list[TestOutcome]) -> list[StubResult]:
        by_stub = {name: StubResult(name) for name in self.expected}
        for outcome in outcomes:
            by_stub.setdefault(outcome.stub, StubResult(outcome.stub)).tests.append(outcome)
        return list(by_stub.values())

    def ungradable(self, name: str, reason: str, notes: list[str] = ()) -> GradeResult:
        """A result with every hidden test failed for ``reason``: the submission stays in the gradebook."""
        failed = [TestOutcome(t.name, t.stub, t.points, False, reason, t.hint) for t in self.catalogue]
        return GradeResult(self.assignment, name, self._collect(failed), list(self.manual), list(notes), reason)

    def _ungradable(self, result: GradeResult, reason: str, start: float) -> GradeResult:
        out = self.ungradable(result.submission, reason, result.notes)
        out.seconds = time.monotonic() - start
        return out

    def close(self) -> None:
        self.zygote.close()
