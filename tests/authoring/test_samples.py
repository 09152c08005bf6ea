"""Every assignment's sample submissions grade as their expected.json says (the demo's promise)."""
from __future__ import annotations

import json

import pytest

from autograder.core import course
from autograder.outputs.files import grade_folder
from conftest import FIXTURE_COURSE, with_cells

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

WITH_SAMPLES = [i for i in course.assignment_ids() if (course.samples_dir(i) / "expected.json").exists()]


def _check(assignment, results):
    expected = json.loads((course.samples_dir(assignment) / "expected.json").read_text())
    results = {r.submission: r for r in results}
    assert set(results) == set(expected)
    for sample, outcome in expected.items():
        for stub in results[sample].stubs:
            want = stub.max_score if outcome[stub.name] == "full" else 0
            assert stub.max_score > 0 and stub.score == want, \
                (sample, stub.name, [t.message for t in stub.tests if not t.passed][:2])


@pytest.fixture(scope="module")
def graded(request, open_module_tmp):
    """The samples of every assignment whose test was selected (``-k hw3`` grades hw3's alone), graded as ``make
    demo`` grades them: one batch over all of them, whose processes pay the grader's imports once."""
    selected = {item.callspec.params["assignment"] for item in request.session.items
                if item.originalname == "test_samples_score_as_expected"}
    return grade_folder([a for a in WITH_SAMPLES if a in selected], course.samples_root(), open_module_tmp,
                        jobs=2, progress=False)


@pytest.mark.parametrize("assignment", WITH_SAMPLES)
def test_samples_score_as_expected(assignment, graded):
    _check(assignment, graded[assignment])


def test_the_worked_example_of_contributing_scores_as_expected(open_tmp, monkeypatch):
    """CONTRIBUTING.md's two-stub example (``ex`` in the fixture course) passes the same check."""
    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))  # for the spawned grading processes
    _check("ex", grade_folder("ex", course.samples_dir("ex"), open_tmp / "out", jobs=2, progress=False))


MUTANTS = {  # CONTRIBUTING.md's table: each mutant of the worked example and its (softmax, cross_entropy) score
    "no_max": ({"softmax": "def softmax(logits):\n    e = np.exp(logits)\n    return e / e.sum(axis=-1, keepdims=True)"},
               (2, 3)),
    "wrong_axis": ({"softmax": "def softmax(logits):\n    z = logits - logits.max(axis=-1, keepdims=True)\n"
                               "    e = np.exp(z)\n    return e / e.sum(axis=0, keepdims=True)"}, (0, 3)),
    "sum": ({"cross_entropy": "def cross_entropy(logits, labels):\n    p = softmax(logits)\n"
                              "    return float(-np.sum(np.log(p[np.arange(len(labels)), labels])))"}, (3, 0)),
    "sign": ({"cross_entropy": "def cross_entropy(logits, labels):\n    p = softmax(logits)\n"
                               "    return float(np.mean(np.log(p[np.arange(len(labels)), labels])))"}, (3, 0)),
}


def test_the_worked_examples_mutants_lose_points_where_contributing_says(open_tmp, monkeypatch):
    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))
    folder = open_tmp / "mutants"
    for name, (cells, _) in MUTANTS.items():
        with_cells(FIXTURE_COURSE / "autograder/samples/ex/complete.ipynb", folder / f"{name}.ipynb", cells)
    results = {r.submission: r for r in grade_folder("ex", folder, open_tmp / "out", jobs=2, progress=False)}
    got = {name: tuple(s.score for s in results[name].stubs) for name in MUTANTS}
    assert got == {name: want for name, (_, want) in MUTANTS.items()}


def test_committed_samples_equal_a_fresh_regeneration():
    """Every sample notebook is the current release with its stubs filled in (``python -m autograder samples ID``):
    a sample left from an older release grades setup cells a student no longer has, and the demo proves nothing."""
    import nbformat

    from autograder.authoring.samples import make_samples

    stale = []
    for assignment in WITH_SAMPLES:
        made = make_samples(assignment)
        for name, (notebook, _) in made.items():
            path = course.samples_dir(assignment) / f"{name}.ipynb"
            if not path.exists() or [c.source for c in nbformat.read(str(path), as_version=4).cells] != \
                    [c.source for c in notebook.cells]:
                stale.append(f"{assignment}/{name}")
        expected = json.loads((course.samples_dir(assignment) / "expected.json").read_text())
        if expected != {name: outcome for name, (_, outcome) in made.items()}:
            stale.append(f"{assignment}/expected.json")
    assert not stale, f"samples out of date with the release: {stale}; run `make assignments` (or `python -m autograder samples ID`)"
