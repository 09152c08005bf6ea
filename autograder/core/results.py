"""What grading produces, for every part of the kit that reads it: per-test outcomes, per-stub scores,
one submission's result and its status, and the error that means the grader itself failed.

A result has one of three statuses:

- ``graded``: the hidden suite ran; each stub has its score;
- ``ungradable``: the submission itself cannot be graded (not a notebook, no notebook in the
  folder): listed with its reason and zero, since the fault is the submission's;
- ``grader_error``: the grader failed (the sandbox could not start, the reference could not be
  built, the suite could not run). Such a result carries no score at all: it is never a grade,
  and a batch retries it on its next run.
"""
from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from enum import Enum
from typing import Any

GRADED, UNGRADABLE, GRADER_ERROR = "graded", "ungradable", "grader_error"


class Reason(str, Enum):
    """Why a hidden test came out as it did, decided where it is known (the session, the suite runner),
    stored with the outcome and read by every report: no report infers it from a message's words."""

    PASSED = "passed"
    WRONG = "wrong"                      # the code ran and a check on its result failed
    NOT_IMPLEMENTED = "not_implemented"  # the stub (or a cell it needs) still raises NotImplementedError
    MISSING = "missing"                  # no cell defines the stub, or the name the test calls
    UNREADABLE = "unreadable"            # the stub's cell is damaged or over the size cap: it was not run
    SYNTAX = "syntax"                    # the stub's cell does not compile
    EXCEPTION = "exception"              # the code raised an exception (while its cell ran, or when called)
    TIMEOUT = "timeout"                  # the code ran past its time limit
    CRASH = "crash"                      # the worker died, or sent garbage, while running the code
    LOST = "lost"                        # never judged: the submission as a whole could not be graded
    UNKNOWN = "unknown"                  # a record written before reasons were recorded

    @property
    def attempted(self) -> bool:
        """Whether a test with this outcome shows the student tried the stub."""
        return self not in (Reason.NOT_IMPLEMENTED, Reason.MISSING, Reason.LOST)


_UNENCODABLE = re.compile(r"[\ud800-\udfff]")


def encodable(text: str) -> str:
    """``text`` with what no UTF-8 writer accepts (lone surrogates: a file name of invalid UTF-8, a hostile
    message) replaced by ``?``; the rest is kept for the outputs to make inert."""
    return _UNENCODABLE.sub("?", text)


SYNTAX_ERRORS = frozenset({"SyntaxError", "IndentationError", "TabError"})
"""The exception types (by name) of a cell that does not compile."""


class GraderError(RuntimeError):
    """The grader itself failed; no student may receive a score for this run."""


@dataclass
class TestOutcome:
    name: str
    stub: str
    points: float
    passed: bool
    message: str = ""
    hint: str | None = None
    seconds: float = 0.0
    reason: Reason = Reason.UNKNOWN

    def __post_init__(self) -> None:
        self.reason = Reason(self.reason)


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
    status: str = GRADED
    suite_version: str = ""
    """:func:`autograder.core.course.suite_version` of the suite that graded it (empty in results older than it)."""
    sandbox_cpu: float = 0.0
    """CPU seconds its sandbox workers' main threads used (cells and tests): what the grading process's own CPU
    accounts leave out, recorded so that a benchmark can count a class's whole cost (0 in older results)."""
    notebook_sha256: str = ""
    """:func:`autograder.core.store.notebook_digest` of the notebook graded (empty when none was read, and in older
    results): a batch run again grades a submission anew when its notebook changed."""
    wrong_notebook: str = ""
    """Set when the notebook defines none of the assignment's stubs: what it seems to be instead (another
    assignment's notebook, say). It is graded all the same (0 for every stub); the batch and the gradebook's
    ``reason`` column name it, so that a wrong upload is seen (empty in older results)."""

    @property
    def score(self) -> float:
        return sum(s.score for s in self.stubs)

    @property
    def max_score(self) -> float:
        return sum(s.max_score for s in self.stubs)

    @property
    def has_score(self) -> bool:
        """False for a grader error: such a result must never be shown or recorded as a grade."""
        return self.status != GRADER_ERROR

    def make_encodable(self) -> "GradeResult":
        """Every text of the result (much of it the submission's) made encodable, in place; returns ``self``.

        Called wherever a result leaves the core, so that no writer (file, terminal, JSON, CSV) can be stopped
        by a character the submission chose."""
        self.submission, self.error = encodable(self.submission), None if self.error is None else encodable(self.error)
        self.notes = [encodable(n) for n in self.notes]
        self.wrong_notebook = encodable(self.wrong_notebook)
        for stub in self.stubs:
            stub.note = encodable(stub.note)
            for test in stub.tests:
                test.message = encodable(test.message)
        return self


def result_to_dict(result: GradeResult) -> dict[str, Any]:
    data = asdict(result.make_encodable())
    for stub in data["stubs"]:
        for test in stub["tests"]:
            test["reason"] = Reason(test["reason"]).value
    if result.has_score:
        data.update(score=result.score, max_score=result.max_score)
    return data


def result_from_dict(data: dict[str, Any]) -> GradeResult:
    stubs = [StubResult(s["name"], [TestOutcome(**t) for t in s["tests"]], s.get("note", "")) for s in data["stubs"]]
    status = data.get("status", UNGRADABLE if data["error"] else GRADED)
    return GradeResult(data["assignment"], data["submission"], stubs, [tuple(m) for m in data["manual"]],
                       data["notes"], data["error"], data["isolation"], data["seconds"], status,
                       str(data.get("suite_version", "")), float(data.get("sandbox_cpu", 0.0)),
                       str(data.get("notebook_sha256", "")), str(data.get("wrong_notebook", "")))
