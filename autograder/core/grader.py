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
import hashlib
import io
import os
import sys
import time
import zlib
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pytest

from autograder.core import course
from autograder.core.intake import NotebookError, read_code_cells
from autograder.core.notebook import code_cells, find_stubs, imported_modules, manual_cells, read_notebook, release_plan, with_parameters
from autograder.core.results import GRADER_ERROR, UNGRADABLE, GradeResult, GraderError, Reason, StubResult, TestOutcome
from autograder.sandbox.config import Limits, SpawnConfig
from autograder.sandbox.wire import ProtocolError, decode, encode
from autograder.core.session import (CPU_WAIT_STRETCH, HELPERS, Cell, CellStatus, LocalTransport, Namespace, ReferenceCache,
                                     SandboxFailure, SandboxTimeout, Session, StudentError, failure_reason)
from autograder.core.supervisor import Zygote
from autograder.core.trusted_work import TrustedWorkTimeout, bounded

FAST_PARAMETERS = {"FAST": True}
SANDBOX_HELPERS = "sandbox_helpers.py"
"""A suite's trusted helper module: runs in the sandbox after every cell, reached as ``student.helpers``, after the
helpers common to every suite (:func:`autograder.core.course.common_helpers`)."""
SUITE_LOG_CHARS = 3000
"""The end of pytest's own output quoted when a suite cannot run (the traceback that matters is last)."""
REFERENCE_ERROR_CHARS = 300
UNUSED_PYTEST_PLUGINS = ("doctest", "junitxml", "pastebin", "legacypath", "unittest", "faulthandler", "stepwise",
                         "lfplugin", "setuponly", "setupplan", "debugging", "logging", "unraisableexception",
                         "threadexception")
"""pytest's plugins a hidden suite never needs: each costs every grading time (a suite is plain test functions
whose only fixtures are ours; feedback is built from the exception, so pytest formats no traceback: ``--tb=no``)."""
"""How much of an exception's text is quoted when a check cannot read a result, or a reference stand-in fails."""


def feedback_message(exc: BaseException) -> str:
    """What a failed test tells the student."""
    if isinstance(exc, CellNotRun):
        return str(exc)
    if isinstance(exc, StudentError):
        if exc.not_implemented:
            return "not implemented yet: the stub still raises NotImplementedError"
        if exc.not_defined:
            return str(exc)
        return f"your code raised {exc}"
    if isinstance(exc, SandboxFailure):
        return f"your code {exc}"
    if isinstance(exc, AssertionError):
        # The suite's own message, without the comparison that pytest's assertion rewriting appends.
        message = exc.args[0] if exc.args and isinstance(exc.args[0], str) else ""
        return message.strip() or "a hidden check failed"
    if isinstance(exc, pytest.fail.Exception):
        return str(exc.msg)
    if isinstance(exc, TrustedWorkTimeout):
        return str(exc)
    if isinstance(exc, MemoryError) or (isinstance(exc, RuntimeError) and "can't allocate memory" in str(exc)):
        return ("checking your code's results needed more memory than a test may use (do they have the sizes "
                "the docstring asks for?)")
    return (f"the result could not be checked ({type(exc).__name__}: {str(exc)[:REFERENCE_ERROR_CHARS]}); "
            "check its type and shape")


class CellNotRun(Exception):
    """A test's stub did not run (missing, unreadable, raising, hanging): the test fails for the cell's reason."""

    def __init__(self, status: CellStatus) -> None:
        super().__init__(status.message)
        self.status = status


def test_reason(exc: BaseException | None) -> Reason:
    """Why a hidden test failed (or :attr:`Reason.PASSED`), from the exception that ended it."""
    if exc is None:
        return Reason.PASSED
    if isinstance(exc, CellNotRun):
        return exc.status.reason
    if isinstance(exc, (StudentError, SandboxFailure)):
        return failure_reason(exc)
    if isinstance(exc, TrustedWorkTimeout):
        return Reason.TIMEOUT
    return Reason.WRONG


class SuitePlugin:
    """Fixtures for the hidden suites, and the collector of their outcomes."""

    def __init__(self, student: Namespace, reference: Namespace, status: dict[str, CellStatus],
                 session: Session | None = None, dependencies: dict[str, list[str]] | None = None,
                 input_key: int = 0, test_limits: dict[str, float] | None = None) -> None:
        self.student_ns, self.reference_ns, self.status = student, reference, status
        self.session, self.dependencies = session, dependencies or {}
        self.input_key = input_key
        self.test_limits = test_limits or {}
        """Each test's own time limit by node id (``limits.json``'s ``"tests"``); others have ``test_seconds``."""
        self.outcomes: list[TestOutcome] = []
        self.grader_faults: list[str] = []
        self.collected: list[tuple[Any, pytest.Item]] = []
        self.test_stats: dict[str, dict[str, float]] = {}
        """Per test (node id): ``seconds`` (wall of its body), ``grader_cpu`` and ``grader_wait`` (the grader's
        main thread: CPU, and time runnable but waiting for one), and with a sandbox ``span`` (wall from the
        test's start to its end, fixture included: what its limit counts), ``messages``, ``worker_cpu``,
        ``credit`` (the worker's CPU wait forgiven) and ``limit``. Cheap: a few clock reads per test."""

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
            raise CellNotRun(status)
        if self.session is not None:  # from here, the test's calls share one deadline
            self.session.begin_test(self.test_limits.get(request.node.nodeid))
        # The other stubs this one calls run as the reference while it is tested: one mistake, one loss.
        needed = self.dependencies.get(stub, [])
        if self.session is not None and needed:
            self.session.stand_in(needed)
        yield self.student_ns
        if self.session is not None:
            spent = self.session.end_test()
            stats = self.test_stats.setdefault(request.node.nodeid, {})
            stats.update({("span" if k == "wall" else k): v for k, v in spent.items()})
        if self.session is not None and needed:
            try:
                self.session.restore()
            except (SandboxFailure, StudentError):
                pass

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(self, item: pytest.Item):
        """The test's fixtures, bounded as its body is: the ``student`` fixture asks the worker to stand the
        reference in for the stubs this one calls, and a hostile worker can answer with callbacks into the grader."""
        with self._bounded(item):
            yield

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(self, item: pytest.Item, nextitem: pytest.Item | None):
        """The fixtures' end (the worker restores the stubs stood in for), bounded as the body is."""
        with self._bounded(item):
            yield

    def _bounded(self, item: pytest.Item) -> contextlib.AbstractContextManager:
        """The grader's own work for ``item``: at most the test's time limit (its own, else ``test_seconds``),
        stretched as a fair deadline may be, and ``trusted_bytes`` more memory."""
        if self.session is None:
            return contextlib.nullcontext()
        limits = self.session.limits
        seconds = self.test_limits.get(item.nodeid) or limits.test_seconds
        return bounded(seconds * CPU_WAIT_STRETCH, limits.trusted_bytes)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item: pytest.Item):
        """The test's body, with the grader's own work for it bounded in time and memory (``trusted_work``)."""
        start, cpu, wait = time.perf_counter(), time.thread_time(), _own_run_delay()
        try:
            with self._bounded(item):
                yield
        finally:
            stats = self.test_stats.setdefault(item.nodeid, {})
            stats.update(seconds=time.perf_counter() - start, grader_cpu=time.thread_time() - cpu)
            if wait is not None and (now := _own_run_delay()) is not None:
                stats["grader_wait"] = now - wait

    @pytest.fixture
    def reference(self) -> Namespace:
        return self.reference_ns

    @pytest.fixture
    def rng(self, request: pytest.FixtureRequest) -> np.random.Generator:
        """The test's hidden inputs: seeded by the test and by the submission's own code (``input_key``), so an
        answer learnt in one submission (read out through its error text, say) is worth nothing in the next,
        while the same code graded again meets the same inputs."""
        return np.random.default_rng([zlib.crc32(request.node.name.encode()), self.input_key])

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo):
        outcome = yield
        report = outcome.get_result()
        if report.when == "call" or (report.when == "setup" and report.failed):
            marker = item.get_closest_marker("stub")
            kwargs = marker.kwargs if marker else {"name": "(unmarked)", "points": 0}
            exc = call.excinfo.value if call.excinfo is not None else None
            if isinstance(exc, GraderError):
                self.grader_faults.append(f"{item.name}: {exc}")
            if isinstance(exc, SandboxTimeout) and marker:
                # Later checks of a stub that hangs would each wait out the limit again: fail them at once.
                self.status[kwargs["name"]] = CellStatus(False, f"not run: an earlier check of this stub {exc}",
                                                         Reason.TIMEOUT)
            self.outcomes.append(TestOutcome(
                name=_title(item), stub=kwargs["name"], points=float(kwargs.get("points", 0)), passed=report.passed,
                message="" if exc is None else feedback_message(exc),
                hint=None if report.passed else kwargs.get("hint"),  # a hint is for a failed test only
                seconds=report.duration, reason=Reason.PASSED if report.passed else test_reason(exc)))


def _own_run_delay() -> float | None:
    """Seconds this thread has spent runnable but waiting for a CPU (``/proc/thread-self/schedstat``), or None."""
    try:
        with open("/proc/thread-self/schedstat", "rb") as f:
            return int(f.read().split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return None


def _title(item: pytest.Item) -> str:
    """A test's first docstring line, else its name in words."""
    doc = (getattr(item, "obj", None).__doc__ or "").strip().splitlines()
    return doc[0] if doc else item.name.removeprefix("test_").replace("_", " ")


def input_key(suite_version: str, stubs: dict[str, Any]) -> int:
    """A 64-bit key from the suite's version and the submission's stub cells, for the hidden inputs."""
    digest = hashlib.sha256(suite_version.encode())
    for name in sorted(stubs):
        digest.update(f"\0{name}\0{stubs[name].source}".encode("utf-8", "surrogatepass"))
    return int.from_bytes(digest.digest()[:8], "big")


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


class Grader:
    """Grades submissions of one assignment; build once, call :meth:`grade` many times.

    Raises :class:`GraderError` when it cannot be built (the reference or the suite fails). ``hide``: the
    grading's inputs and outputs, masked in the sandbox wherever they lie inside the release.
    """

    def __init__(self, assignment: str, limits: Limits | None = None, hide: Iterable[Path] = (),
                 test_limits: dict[str, float] | None = None) -> None:
        course.check_assignment(assignment)
        self.assignment, self.limits = assignment, limits or course.limits(assignment)
        self.test_limits = course.per_test_limits(assignment) if test_limits is None else dict(test_limits)
        """Each hidden test's own limit (``limits.json``'s ``"tests"``, unless given: ``{}`` for none)."""
        self.last_test_stats: dict[str, dict[str, float]] = {}
        """What each test of the last :meth:`grade` cost (see :attr:`SuitePlugin.test_stats`)."""
        self.suite = course.suite_dir(assignment)
        helpers = [path.read_text() for path in (course.common_helpers(), self.suite / SANDBOX_HELPERS) if path.is_file()]
        self.helpers = "\n\n".join(helpers) if helpers else None
        release = read_notebook(course.release_notebook(assignment))
        self.plan = release_plan(release)
        self.expected = [c.label for c in self.plan if c.kind == "stub"]
        self.manual = manual_cells(release)
        self.zygote = Zygote(imported_modules([c.source for c in self.plan if c.kind != "stub"]))
        self.config = SpawnConfig(course.sandbox_view(hide, assignment), self.limits)
        try:
            self.reference_ns = build_reference(assignment)
        except Exception as err:  # noqa: BLE001 - a broken solution notebook is the course's bug
            self.zygote.close()
            raise GraderError(f"the reference solution of {assignment} could not be built: "
                              f"{type(err).__name__}: {err}") from err
        try:
            self.catalogue = self._catalogue()
        except GraderError:
            self.close()
            raise
        self.dependencies = stub_dependencies(assignment, self.expected)
        self.version = course.suite_version(assignment)
        # A benchmark sets the size to 0 to measure what hidden inputs varied per submission would cost.
        self.reference_cache = ReferenceCache(int(os.environ.get("AUTOGRADER_REFERENCE_CACHE_BYTES", 256 * 2**20)))

    def _reference_call(self, name: str, tree: Any, blobs: list[bytes]) -> tuple[dict[str, Any], list[bytes]]:
        """Run reference ``name`` for a stand-in in the sandbox; plain data in and out, never handles."""
        def refuse(id: int, type_name: str) -> Any:
            raise ProtocolError("objects cannot be sent to the reference")

        try:
            args, kwargs = decode(tree, blobs, refuse)
            value = self.reference_ns[name](*args, **kwargs)
            out_tree, out_blobs = encode(value)
            return {"ok": True, "value": out_tree}, out_blobs
        except TrustedWorkTimeout:  # the test's bound on the grader's work: it ends the test, not just this call
            raise
        except Exception as err:  # noqa: BLE001 - reported to the student's code as an exception
            return {"ok": False, "error": f"{type(err).__name__}: {str(err)[:REFERENCE_ERROR_CHARS]}"}, []

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
        if self.helpers is not None:
            cells.append(Cell("suite helpers", self.helpers, module=HELPERS))
        return cells

    def _wrong_notebook(self, nb) -> str:
        """What a notebook that defines none of this assignment's stubs seems to be, in a sentence."""
        names = {n for cell in code_cells(nb) for n in (cell.grade_id, *cell.defines) if n}
        owner = course.stub_owner(names, self.assignment)
        ours = ", ".join(self.expected[:4]) + (", ..." if len(self.expected) > 4 else "")
        if owner:
            return (f"this notebook defines none of {self.assignment}'s stubs ({ours}); its graded cells are "
                    f"{owner}'s: was another assignment's notebook handed in?")
        return f"this notebook defines none of {self.assignment}'s stubs ({ours}): is it this assignment's notebook?"

    def grade(self, path: str | Path, name: str | None = None) -> GradeResult:
        """Grade one notebook. A fault of the grader comes back as a result of status ``grader_error``,
        with no score; an unreadable submission as ``ungradable``."""
        start = time.monotonic()
        path = Path(path)
        result = GradeResult(self.assignment, name or path.name, [], list(self.manual), suite_version=self.version)
        try:
            nb, notes = read_code_cells(path)
        except NotebookError as err:
            return self._ungradable(result, f"could not read the notebook: {err}", start)
        except GraderError as err:
            return self.grader_error(result.submission, str(err), result.notes, start)
        self.last_test_stats = {}
        stubs, match_notes = find_stubs(nb, self.expected)
        result.notes += notes + match_notes
        if self.expected and not stubs:
            result.wrong_notebook = self._wrong_notebook(nb)
            result.notes.insert(0, result.wrong_notebook)
        unrunnable = {name: match.problem for name, match in stubs.items() if match.problem}
        stubs = {name: match for name, match in stubs.items() if not match.problem}
        session = Session(self.zygote, self.cells_for(stubs), self.config, reference_call=self._reference_call,
                          missing=[s for s in self.expected if s not in stubs and s not in unrunnable],
                          unrunnable=unrunnable)
        failed: GradeResult | None = None
        try:
            session.start()
            broken_setup = [s.message for label, s in session.status.items()
                            if not s.ok and label not in self.expected]
            if broken_setup:
                self._blame_setup(session, broken_setup[0])
            result.isolation = session.isolation
            reference = LocalTransport(self.reference_ns, self.helpers, self.reference_cache)
            plugin = SuitePlugin(Namespace(session, "student"), Namespace(reference, "reference"), session.status,
                                 session, self.dependencies, input_key(self.version, stubs), self.test_limits)
            self.last_test_stats = plugin.test_stats
            self._run_suite(plugin)
            if plugin.grader_faults:
                raise GraderError("; ".join(plugin.grader_faults))
        except GraderError as err:
            failed = self.grader_error(result.submission, str(err), result.notes, start)
        except SandboxFailure as err:
            failed = self._ungradable(result, str(err), start)
        finally:
            session.close()
        if failed is None:
            result.stubs = self._collect(plugin.outcomes)
            if session.restarts:
                result.notes.append(f"the sandbox was restarted {session.restarts} time(s) after failures in your code")
            result.seconds = time.monotonic() - start
        out = result if failed is None else failed
        out.sandbox_cpu = round(session.counters()["worker_cpu"], 3)
        return out.make_encodable()

    def _blame_setup(self, session: Session, failure: str) -> None:
        """A released setup cell failed: the grader's fault if it fails alone too, else the stubs' before it."""
        alone = Session(self.zygote, [c for c in session.cells if c.stub is None], self.config)
        try:
            alone.start()
            fails_alone = not all(s.ok for s in alone.status.values())
        finally:
            alone.close()
        if fails_alone:
            raise GraderError(f"the released notebook's setup fails in the sandbox: {failure}")
        for stub in self.expected:
            session.status[stub] = CellStatus(False, "the notebook's setup failed after your cells ran (does a "
                                                     f"cell of yours redefine or delete a name it uses?): {failure}",
                                              Reason.EXCEPTION)

    def grader_error(self, name: str, reason: str, notes: list[str] = (), start: float | None = None) -> GradeResult:
        """A result that says the grader failed: no stubs, no score (see :mod:`autograder.core.results`)."""
        seconds = 0.0 if start is None else time.monotonic() - start
        return GradeResult(self.assignment, name, [], list(self.manual), list(notes), reason, seconds=seconds,
                           status=GRADER_ERROR, suite_version=self.version).make_encodable()

    def _run_suite(self, plugin: SuitePlugin, *extra: str) -> None:
        suite = self.suite
        # Plain asserts: a failed check's message is exactly the suite's text, the feedback the student reads.
        args = [str(suite), *extra, "-q", "-p", "no:cacheprovider", "--import-mode=importlib", "-c", os.devnull,
                "--rootdir", str(suite), "-o", "python_files=test_*.py", "-W", "ignore::DeprecationWarning",
                "--assert=plain", "--tb=no", "-s", *(f"-pno:{name}" for name in UNUSED_PYTEST_PLUGINS)]
        log = io.StringIO()
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            code = pytest.main(args, plugins=[plugin])
        for module in [m for m, mod in sys.modules.items() if str(getattr(mod, "__file__", "")).startswith(str(suite))]:
            del sys.modules[module]
        if code not in (pytest.ExitCode.OK, pytest.ExitCode.TESTS_FAILED) or not (plugin.outcomes or plugin.collected):
            raise GraderError(f"the hidden suite of {self.assignment} could not run (pytest exit {code}):\n"
                              + log.getvalue()[-SUITE_LOG_CHARS:])

    def _collect(self, outcomes: list[TestOutcome]) -> list[StubResult]:
        by_stub = {name: StubResult(name) for name in self.expected}
        for outcome in outcomes:
            by_stub.setdefault(outcome.stub, StubResult(outcome.stub)).tests.append(outcome)
        return list(by_stub.values())

    def ungradable(self, name: str, reason: str, notes: list[str] = ()) -> GradeResult:
        """A result with every hidden test failed for ``reason``: the submission stays in the gradebook."""
        failed = [TestOutcome(t.name, t.stub, t.points, False, reason, t.hint, reason=Reason.LOST)
                  for t in self.catalogue]
        return GradeResult(self.assignment, name, self._collect(failed), list(self.manual), list(notes), reason,
                           status=UNGRADABLE, suite_version=self.version).make_encodable()

    def _ungradable(self, result: GradeResult, reason: str, start: float) -> GradeResult:
        out = self.ungradable(result.submission, reason, result.notes)
        out.seconds = time.monotonic() - start
        return out

    def close(self) -> None:
        """Stop the zygote and let the reference go (so another grader may start in this process)."""
        self.zygote.close()
        self.reference_ns = None
