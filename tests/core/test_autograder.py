"""The grading model end to end: full marks, zero, exact partial credit, handles, isolation."""
from __future__ import annotations


import pytest

from autograder.core.grader import Grader
from autograder.outputs.feedback import feedback_markdown
from conftest import REPO, with_cells

SOLVED = {
    "scaled_sum": "def scaled_sum(x):\n    return SCALE * np.asarray(x, dtype=float).sum(axis=-1)",
    "mean_of": "def mean_of(values):\n    return float(np.mean(values))",
    "double_scaled": "def double_scaled(x):\n    return 2 * scaled_sum(x)",
}


@pytest.fixture(scope="module")
def fx_grader():
    from autograder.core import course

    saved = course.REPO
    course.REPO = REPO / "tests" / "fixtures" / "course"
    try:
        grader = Grader("fx")  # the grader keeps its course's paths from here on
    finally:
        course.REPO = saved
    yield grader
    grader.close()


def scores(result):
    return {stub.name: (stub.score, stub.max_score) for stub in result.stubs}


def test_reference_solution_scores_full_marks(fx_grader):
    result = fx_grader.grade(REPO / "tests/fixtures/course/solutions/fx/fx.ipynb")
    assert result.error is None
    assert result.score == result.max_score == 7
    assert result.isolation in ("full", "user-namespace")


def test_the_result_counts_the_sandbox_cpu_of_the_students_code(fx_grader, tmp_path):
    """What a benchmark adds to the grading process's own CPU: the workers' CPU, which a busy cell raises."""
    from autograder.core.results import result_from_dict, result_to_dict

    idle = fx_grader.grade(REPO / "tests/fixtures/course/solutions/fx/fx.ipynb")
    busy_cell = SOLVED["mean_of"] + "\n\nimport time\n_t = time.process_time()\nwhile time.process_time() - _t < 0.5:\n    pass"
    busy = fx_grader.grade(with_cells(REPO / "tests/fixtures/course/solutions/fx/fx.ipynb", tmp_path / "busy.ipynb",
                                      {"mean_of": busy_cell}))
    assert 0 < idle.sandbox_cpu < 0.5 <= busy.sandbox_cpu, (idle.sandbox_cpu, busy.sandbox_cpu)
    assert result_from_dict(result_to_dict(busy)).sandbox_cpu == busy.sandbox_cpu


def test_student_notebook_scores_zero_with_not_implemented(fx_grader):
    result = fx_grader.grade(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb")
    assert result.score == 0 and result.max_score == 7
    for stub in result.stubs:
        assert all("not implemented" in t.message for t in stub.tests), stub


def test_half_done_submission_gets_credit_exactly_on_completed_stubs(fx_grader, tmp_path):
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "half.ipynb",
                    {"scaled_sum": SOLVED["scaled_sum"]})
    assert scores(fx_grader.grade(nb)) == {"scaled_sum": (3, 3), "Counter": (0, 2), "mean_of": (0, 1),
                                           "double_scaled": (0, 1)}


def test_objects_come_back_as_handles_whose_methods_run_in_the_sandbox(fx_grader, tmp_path):
    counter = "class Counter:\n    def __init__(self, start=0):\n        self.value = start\n" \
              "    def increment(self, by=1):\n        self.value += by\n        return self.value\n"
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "c.ipynb", {"Counter": counter})
    assert scores(fx_grader.grade(nb))["Counter"] == (2, 2)


def test_a_wrong_answer_fails_with_a_message_and_hint(fx_grader, tmp_path):
    wrong = "def scaled_sum(x):\n    return SCALE * np.asarray(x, dtype=float).sum(axis=0)"
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "w.ipynb", {"scaled_sum": wrong})
    result = fx_grader.grade(nb)
    failed = [t for s in result.stubs if s.name == "scaled_sum" for t in s.tests if not t.passed]
    assert failed and "shape" in failed[0].message and failed[0].hint == "Sum over the last axis, then scale."
    text = feedback_markdown(result)
    assert "✗" in text and "hint" in text and "q_why" in text  # the manual cell is listed with its points


@pytest.mark.parametrize("broken", [
    "def scaled_sum(x):\n    return -x.sum(axis=0)",          # wrong
    "def scaled_sum(x):\n    return )(",                        # does not even parse
    None,                                                         # deleted
])
def test_a_stub_that_calls_a_broken_stub_is_graded_on_its_own(fx_grader, tmp_path, broken):
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "dep.ipynb",
                    {"scaled_sum": broken, "double_scaled": SOLVED["double_scaled"]})
    got = scores(fx_grader.grade(nb))
    assert got["scaled_sum"] == (0, 3) and got["double_scaled"] == (1, 1)


def test_stand_ins_are_restored_after_the_test(fx_grader, tmp_path):
    """double_scaled's test runs the reference scaled_sum; scaled_sum's own tests see the student's again."""
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "dep.ipynb",
                    {"scaled_sum": "def scaled_sum(x):\n    return x.sum(axis=-1)",  # forgets SCALE
                     "double_scaled": SOLVED["double_scaled"]})
    got = scores(fx_grader.grade(nb))
    assert got["scaled_sum"][0] < 3 and got["double_scaled"] == (1, 1)


class _Bandit:
    """A trusted object with a secret: student code may duel, and read n_arms, nothing else."""

    def __init__(self) -> None:
        self.n_arms, self._P, self.calls = 3, "the hidden matrix", 0

    def duel(self, i: int, j: int) -> float:
        self.calls += 1
        return float(i > j)


def test_a_lent_object_stays_in_the_grader(fx_grader):
    from autograder.core.session import Cell, Namespace, Session, StudentError
    from autograder.suite import lend

    session = Session(fx_grader.zygote, [Cell("setup", "import numpy as np")], fx_grader.config)
    try:
        session.start()
        student, bandit = Namespace(session, "student"), _Bandit()
        env = lend(bandit, methods=["duel"], attrs=["n_arms"])
        assert student.eval("[env.duel(2, 1), env.duel(np.int64(0), 1), env.n_arms]", env=env) == [1.0, 0.0, 3]
        assert bandit.calls == 2, "each duel runs on the trusted side"
        for peek in ("env._P", "vars(env)", "env.calls", "env.__dict__", "setattr(env, 'n_arms', 9)",
                     "repr(object.__getattribute__(env, '_lent')[0].__dict__)"):
            with pytest.raises(StudentError) as caught:
                student.eval(peek, env=env)
            assert "hidden matrix" not in str(caught.value), peek
        assert "hidden matrix" not in str(student.eval("repr(object.__getattribute__(env, '_lent'))", env=env))
        forged = "object.__getattribute__(env, '_lent')[0].methods.append('_bandit_secret') or env._bandit_secret()"
        with pytest.raises(StudentError, match="not lent"):  # the grader checks its own list, not the sandbox's copy
            student.eval(forged, env=env)
    finally:
        session.close()


def test_a_lent_object_is_its_tests_alone(fx_grader):
    """Code that keeps a lent object's reference (a global) cannot call it once the test that lent it is over, nor
    reach a later test's object through the old reference's id."""
    from autograder.core.session import Cell, Namespace, Session, StudentError
    from autograder.suite import lend

    keep = "KEPT = []\ndef keep(env):\n    KEPT.append(env)\n    return env.duel(2, 1)\n"
    session = Session(fx_grader.zygote, [Cell("setup", "import numpy as np"), Cell("keep", keep)], fx_grader.config)
    try:
        session.start()
        student, first, second = Namespace(session, "student"), _Bandit(), _Bandit()
        session.begin_test()
        assert student.keep(lend(first, methods=["duel"])) == 1.0 and first.calls == 1
        assert student.eval("KEPT[0].duel(0, 1)") == 0.0, "within its test, the reference works"
        session.end_test()
        session.begin_test()
        with pytest.raises(StudentError, match="not lent"):
            student.eval("KEPT[0].duel(2, 1)")
        assert student.keep(lend(second, methods=["duel"])) == 1.0
        with pytest.raises(StudentError, match="not lent"):  # the first reference's id does not name the second
            student.eval("KEPT[0].duel(2, 1)")
        assert first.calls == 2 and second.calls == 1
        session.end_test()
    finally:
        session.close()


def test_student_text_cannot_forge_the_terminal_the_feedback_or_the_gradebook(tmp_path):
    """An exception message with terminal escapes, Markdown links and a formula is shown inert everywhere."""
    import csv

    from autograder.outputs.feedback import feedback_markdown

    from autograder.outputs.terminal import summary_lines

    from autograder.outputs.files import write_gradebook
    from autograder.core.results import GradeResult, StubResult, TestOutcome

    forged = "\x1b[2J\rscaled_sum 3/3\n# All passed [claim](http://example.com) <img src=x>"
    result = GradeResult("fx", "=cmd|' /C calc'!A0", [StubResult("scaled_sum", [
        TestOutcome("matches", "scaled_sum", 3, False, f"your code raised ValueError: {forged}")])], [],
        notes=[f"several notebooks were submitted; graded {forged}"], error=None)
    terminal = "\n".join(summary_lines(result))
    assert "\x1b" not in terminal and "\r" not in terminal and terminal.count("\n") == 1
    markdown = feedback_markdown(result)
    assert "\x1b" not in markdown and "](http" not in markdown and "<img" not in markdown.replace("\\<", "")
    assert "\n# All passed" not in markdown and "\\# All passed" in markdown
    write_gradebook([GradeResult("fx", "x", [], [], error="=HYPERLINK(1)", status="ungradable")], tmp_path / "g.csv")
    row = next(csv.DictReader((tmp_path / "g.csv").open()))
    assert row["reason"].startswith("'=")


def test_every_failure_records_its_reason_where_it_is_known(fx_grader, tmp_path):
    """A failure's reason is a type set by the session and the suite runner, stored in the result record."""
    from autograder.core.results import Reason, result_from_dict, result_to_dict

    def reasons(result):
        return {stub.name: {t.reason for t in stub.tests} for stub in result.stubs}

    assert set().union(*reasons(fx_grader.grade(REPO / "tests/fixtures/course/solutions/fx/fx.ipynb")).values()) \
        == {Reason.PASSED}
    untouched = fx_grader.grade(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb")
    assert set().union(*reasons(untouched).values()) == {Reason.NOT_IMPLEMENTED}
    nb = with_cells(REPO / "tests/fixtures/course/assignments/fx/fx.ipynb", tmp_path / "mixed.ipynb", {
        "scaled_sum": None,
        "mean_of": "def mean_of(values):\n    raise ValueError('not today')",
        "Counter": "class Counter(:\n    pass",
        "double_scaled": "def double_scaled(x):\n    return 0 * np.asarray(x, dtype=float).sum(axis=-1) + 1.5",
    })
    got = reasons(fx_grader.grade(nb))
    assert got["scaled_sum"] == {Reason.MISSING}
    assert got["mean_of"] == {Reason.EXCEPTION}
    assert got["Counter"] == {Reason.SYNTAX}
    assert got["double_scaled"] == {Reason.WRONG}
    bad = tmp_path / "not_a_notebook.ipynb"
    bad.write_text("this is not JSON")
    lost = fx_grader.grade(bad)
    assert lost.status == "ungradable" and set().union(*reasons(lost).values()) == {Reason.LOST}
    again = result_from_dict(result_to_dict(fx_grader.grade(nb)))
    assert reasons(again) == got, "the reason survives the record on disk"
