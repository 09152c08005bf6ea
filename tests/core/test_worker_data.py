"""What the worker sends is the student's: data the grader cannot take fails the student's stub, never the grader,
and the grader's own work for a test is bounded in its fixtures as in its body (red team B, 2026-12-05)."""
from __future__ import annotations

import contextlib

import pytest

from autograder.core import grader as grader_module
from conftest import FIXTURE_COURSE, with_cells

FIND_WORKER = '''
import os, struct, sys
frame = sys._getframe()
while frame is not None and type(frame.f_locals.get("self")).__name__ != "Worker":
    frame = frame.f_back
worker = frame.f_locals["self"]
'''
ATTACKS = {
    "a callback whose reference name is a list (unhashable)":
        'try:\n    worker._ask_grader({"callback": {"reference": []}, "args": None}, [], "x")\nexcept BaseException:\n    pass\n',
    "a header holding an integer of 5,000 digits":
        'head = b\'{"ok":true,"value":\' + b"1" * 5000 + b\',"nblobs":0}\'\n'
        'os.write(worker.channel[1], struct.pack(">I", len(head)) + head)\nos.read(worker.channel[0].fd, 1)\n',
}


@pytest.mark.parametrize("attack", ATTACKS)
def test_data_the_grader_cannot_take_fails_the_stub_that_sent_it(fx_grader, tmp_path, attack):
    """Each of these raised an exception no handler caught: ``grade`` crashed and ``batch`` recorded a grader
    error, a status any submission could give itself to avoid a zero."""
    code = FIND_WORKER + ATTACKS[attack] + "def mean_of(values):\n    return sum(values) / len(values)\n"
    nb = with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", tmp_path / "attack.ipynb", {"mean_of": code})
    result = fx_grader.grade(nb)
    assert result.status == "graded", result.error
    stubs = {s.name: s for s in result.stubs}
    assert stubs["mean_of"].score == 0
    assert all("malformed data" in t.message for t in stubs["mean_of"].tests), [t.message for t in stubs["mean_of"].tests]
    assert stubs["scaled_sum"].score == stubs["scaled_sum"].max_score


def test_the_graders_work_is_bounded_in_a_tests_setup_and_teardown_too(fx_grader, tmp_path, monkeypatch):
    """A test's fixtures ask the worker to stand the reference in for the stubs the tested one calls, and a
    hostile worker can answer with callbacks that run in the grader: before, only the test's body was bounded
    (a reference looping for minutes, or 4 GB of the grader's memory, from hw2's setup). Every phase of every
    test now runs under ``bounded``, with the test's own limit where it has one."""
    entered = []
    real = grader_module.bounded

    @contextlib.contextmanager
    def recording(seconds, extra_bytes):
        entered.append(seconds)
        with real(seconds, extra_bytes):
            yield

    monkeypatch.setattr(grader_module, "bounded", recording)
    nb = with_cells(FIXTURE_COURSE / "solutions/fx/fx.ipynb", tmp_path / "solved.ipynb", {})
    result = fx_grader.grade(nb)
    tests = sum(len(s.tests) for s in result.stubs)
    assert result.score == result.max_score
    assert len(entered) == 3 * tests, (len(entered), tests)  # setup, body, teardown
    assert set(entered) == {fx_grader.limits.test_seconds * grader_module.CPU_WAIT_STRETCH}

    class EveryTestHasItsOwn(dict):  # a limits.json naming every test, whatever its id
        def get(self, key, default=None):
            return 7.0

    entered.clear()
    monkeypatch.setattr(fx_grader, "test_limits", EveryTestHasItsOwn({"any": 7.0}))
    assert fx_grader.grade(nb).score == result.max_score
    assert set(entered) == {7.0 * grader_module.CPU_WAIT_STRETCH}, "a test's own limit bounds the grader's work"
