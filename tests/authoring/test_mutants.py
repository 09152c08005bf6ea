"""The mutation tool (autograder/authoring/mutants.py): which mutants it makes, and an end-to-end run on the fixture course."""
from __future__ import annotations

import json

import pytest

from autograder.authoring import mutants
from autograder.core import course
from conftest import FIXTURE_COURSE

STUB = '''def masked_mean(x, mask, axis=-1):
    """A docstring with numbers 1 + 2 that is outside the solution region."""
    offset = 3
    ### BEGIN SOLUTION
    kept = np.where(mask, x, 0.0)
    total = kept.sum(axis=axis) - offset
    return total / np.maximum(mask.sum(axis=axis), 1) + x[..., 1:].max() * (x[0] > 0)
    ### END SOLUTION
'''


def _ops(made):
    return {m.operator for m in made}


def test_mutants_change_only_the_solution_region_and_compile():
    made = mutants.make_mutants("masked_mean", STUB)
    assert made, "no mutant made"
    assert all(m.line >= 4 for m in made), "a mutant outside the solution region (the docstring or 'offset = 3')"
    for m in made:
        compile(m.source, m.id, "exec")
        lines = m.diff.splitlines()
        assert any(l.startswith("-") for l in lines) and any(l.startswith("+") for l in lines), m.id
    sources = [m.source for m in made]
    assert len(set(sources)) == len(sources), "two mutants with the same source"
    assert len({m.id for m in made}) == len(made), "mutant ids must be unique (equivalent lists refer to them)"


def test_mutants_cover_the_operators_the_issue_names():
    ops = _ops(mutants.make_mutants("masked_mean", STUB))
    for wanted in ("binop:Sub->Add", "binop:Div->Mult", "binop:Mult->Div", "compare:Gt->GtE", "constant:+1",
                   "constant:changed", "axis:axis moved", "reduction:sum->mean", "reduction:max->min",
                   "reduction:maximum->minimum", "slice:lower+1", "mask:where->first branch"):
        assert wanted in ops, f"no {wanted} mutant (made: {sorted(ops)})"


def test_a_dropped_mask_is_the_first_branch():
    made = {m.operator: m for m in mutants.make_mutants("masked_mean", STUB)}
    assert "kept = x" in made["mask:where->first branch"].source


def test_summary_leaves_out_equivalent_mutants():
    outcomes = [mutants.MutantOutcome("a", "op", 1, killed_by_suite=True),
                mutants.MutantOutcome("b", "op", 2, killed_by_suite=False, equivalent="same for 2-d input"),
                mutants.MutantOutcome("c", "op", 3, killed_by_suite=False, killed_by_check=True)]
    s = mutants.summarise(outcomes)
    assert (s["mutants"], s["equivalent"], s["killed_by_suite"], s["survivors"]) == (3, 1, 1, 1)
    assert s["suite_kill_rate"] == 0.5


def test_stub_tests_are_read_from_the_decorators():
    tests = mutants.stub_tests("hw0_setup")
    assert "test_random_batch_matches_reference" in tests["discounted_returns"]
    assert "test_done_step_belongs_to_its_episode" in tests["episode_returns"]
    assert not set(tests["discounted_returns"]) & set(tests["episode_returns"])


def test_every_equivalent_mutant_file_names_stubs_and_gives_reasons():
    for assignment in course.assignment_ids():
        listed = mutants.equivalent_mutants(assignment)
        for stub, entries in listed.items():
            assert stub in course.stub_names(assignment), f"{assignment}: {stub} is not a stub"
            made = {m.id for m in mutants.make_mutants(stub, mutants._notebook_parts(assignment)[1][stub])}
            for mutant_id, reason in entries.items():
                assert mutant_id in made, f"{assignment}/{stub}: no mutant {mutant_id!r} (stale entry?)"
                assert len(reason.split()) >= 4, f"{assignment}/{stub}: give a reason for {mutant_id!r}"


@pytest.mark.slow
def test_a_run_on_the_worked_example_grades_every_mutant(open_tmp, monkeypatch):
    """The fixture course's softmax and cross-entropy: every mutant graded, a report written, most killed"""
    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))
    results = mutants.run_mutants("ex", out=open_tmp / "report", log=lambda line: None)
    assert set(results) == {"softmax", "cross_entropy"}
    report = json.loads((open_tmp / "report" / "report.json").read_text())
    for stub, outcomes in results.items():
        assert outcomes and len(outcomes) == report[stub]["mutants"] == report[stub]["made"]
        assert all(o.suite_score is not None for o in outcomes), "a mutant was not graded"
    axis = [o for o in results["softmax"] if o.operator == "axis:axis moved"]
    assert axis and all(o.killed_by_suite for o in axis), "the wrong-axis softmax must be killed"
    assert "| `softmax` |" in (open_tmp / "report" / "report.md").read_text()
