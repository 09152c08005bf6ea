"""The reference passes its own hidden suite on draws of the hidden inputs it has never met
(``bench/bench_suite_draws.py`` runs 20 draws of every assignment; here a few of the quick ones)."""
from __future__ import annotations

import importlib.util

import pytest
from conftest import REPO


def _bench():
    spec = importlib.util.spec_from_file_location("bench_suite_draws", REPO / "bench" / "bench_suite_draws.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize("assignment", ["hw0_setup", "hw1b_multimodal", "hw6_group_rl"])
def test_the_reference_passes_every_draw(assignment):
    row = _bench().reference_draws(assignment, draws=3, first=7_777_777)
    assert row["tests"] > 0
    assert not row["failing"], f"the reference fails its own suite on some draw: {row['failing']}"


def test_a_reference_that_raises_is_seen_as_the_students_error():
    """The bench grades the reference as the student: what it raises must reach the suite as a student's error
    (a test that expects a ValueError passes), not as a fault of the reference."""
    from autograder.core.session import Namespace, StudentError

    def f(x):
        raise ValueError("bad input")

    student = Namespace(_bench().student_transport({"f": f}, None), "student")
    with pytest.raises(StudentError) as caught:
        student.f(1.0)
    assert caught.value.kind == "ValueError"
