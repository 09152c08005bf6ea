"""``python -m autograder new ID``: a new assignment's skeleton that the whole kit already accepts.

It writes a solution notebook with two stubs (one calls the other, so the grader's stand-ins show), their
public checks, a parameters cell, an experiment and a written answer, all with the metadata nbgrader and
the grader expect (CONTRIBUTING.md, "The solution notebook"); a hidden suite of two test files; the trivial
answers every assignment ships (tests/test_adversarial_suites.py grades them and requires zero); then it
regenerates the student notebook with nbgrader and the sample submissions with their ``expected.json``.
Replace the two stubs, keep the shape.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from autograder.core import course

ID_PATTERN = re.compile(r"hw\d+[a-z]?_[a-z][a-z0-9_]*")


def _nbgrader(grade_id: str, *, solution: bool, locked: bool, grade: bool = False, points: float | None = None) -> dict:
    meta = {"grade": grade, "grade_id": grade_id, "locked": locked, "schema_version": 3, "solution": solution}
    if points is not None:
        meta["points"] = points
    return {"nbgrader": meta}


def _setup(grade_id: str, source: str) -> nbformat.NotebookNode:
    return new_code_cell(source, metadata={"tags": ["setup"], **_nbgrader(grade_id, solution=False, locked=True)})


def _stub(grade_id: str, source: str) -> nbformat.NotebookNode:
    return new_code_cell(source, metadata=_nbgrader(grade_id, solution=True, locked=False))


def _check(stub: str, source: str) -> nbformat.NotebookNode:
    return new_code_cell(source, metadata={"tags": ["check"], **_nbgrader(f"check_{stub}", solution=False, locked=True)})


def solution_notebook(assignment: str, title: str) -> nbformat.NotebookNode:
    """The skeleton's instructor notebook: every kind of cell the kit knows, once."""
    cells = [
        new_markdown_cell(f"# {assignment}: {title}\n\n"
                          "What this chapter teaches, why it matters, and which lecture it follows: "
                          "[the lectures](../../lectures/intro.md#What-the-course-covers). Each stub below links "
                          "the section and equation it implements."),
        new_code_cell("FAST = False", metadata={"tags": ["parameters"]}),
        _setup("setup_imports", "import numpy as np\n\nEPISODES = 3 if FAST else 100"),
        new_markdown_cell("## Returns to go\n\nThe return from step $t$ on is $G_t = \\sum_{k \\ge t} "
                          "\\gamma^{k-t} r_k$, computed backwards as $G_t = r_t + \\gamma G_{t+1}$ "
                          "([lecture 6, advantages as the notebooks compute them](../../lectures/06_rlhf.md#Advantages-as-the-notebooks-compute-them); a stub links the section it implements)."),
        _stub("returns_to_go", '''def returns_to_go(rewards, gamma):
    """G_t for every step of each episode.

    rewards: array of shape (episodes, T); gamma: a float in [0, 1].
    Returns a float array of the same shape, G[:, t] = sum over k >= t of gamma**(k - t) * rewards[:, k].
    """
    ### BEGIN SOLUTION
    rewards = np.asarray(rewards, dtype=float)
    out = np.zeros_like(rewards)
    running = np.zeros(rewards.shape[:-1])
    for t in range(rewards.shape[-1] - 1, -1, -1):
        running = rewards[..., t] + gamma * running
        out[..., t] = running
    return out
    ### END SOLUTION'''),
        _check("returns_to_go", 'G = returns_to_go(np.array([[1.0, 1.0, 1.0]]), 0.5)\n'
                                'assert G.shape == (1, 3), f"returns_to_go should keep the shape (1, 3), got {G.shape}"\n'
                                'assert np.allclose(G, [[1.75, 1.5, 1.0]]), f"expected [[1.75, 1.5, 1.0]], got {G}"'),
        new_markdown_cell("## The mean return\n\nThe value of the start state, estimated from episodes: the mean of "
                          "$G_0$ over them ([lecture 6, advantages as the notebooks compute them](../../lectures/06_rlhf.md#Advantages-as-the-notebooks-compute-them))."),
        _stub("mean_return", '''def mean_return(rewards, gamma):
    """The mean over episodes of G_0 (uses returns_to_go).

    rewards: array of shape (episodes, T). Returns a Python float.
    """
    ### BEGIN SOLUTION
    return float(returns_to_go(rewards, gamma)[:, 0].mean())
    ### END SOLUTION'''),
        _check("mean_return", 'm = mean_return(np.array([[1.0, 1.0], [0.0, 2.0]]), 1.0)\n'
                              'assert type(m) is float, f"mean_return should return a float, got {type(m).__name__}"\n'
                              'assert np.isclose(m, 2.0), f"expected 2.0, got {m}"'),
        new_markdown_cell("## Experiment\n\nHow the estimate's spread shrinks with the number of episodes "
                          "(`FAST` runs 3; the full budget 100, in well under a second)."),
        new_code_cell('rng = np.random.default_rng(0)\nrewards = rng.normal(1.0, 1.0, size=(EPISODES, 20))\n'
                      'print(f"mean return over {EPISODES} episodes: {mean_return(rewards, 0.9):.3f}")',
                      metadata={"tags": ["experiment"]}),
        new_markdown_cell("**Question.** Why does a discount below one make the estimate less noisy?"),
        new_markdown_cell("### BEGIN SOLUTION\nLater rewards, each noisy, are weighted by powers of gamma, so the "
                          "variance of G_0 is a geometric sum that stays bounded as the horizon grows.\n"
                          "### END SOLUTION", metadata=_nbgrader("q_discount", solution=True, locked=False,
                                                                  grade=True, points=1)),
    ]
    return new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                                              "language": "python"}})


SUITE = {
    "test_returns_to_go.py": '''"""Hidden tests of returns_to_go."""
import numpy as np

from autograder.suite import check_array, stub


@stub("returns_to_go", points=2, hint="Go backwards: G_t = r_t + gamma * G_{t+1}, with G after the last step 0.")
def test_matches_the_reference_on_random_episodes(student, reference, rng):
    rewards = rng.normal(size=(4, 7))
    check_array(student.returns_to_go(rewards, 0.9), reference.returns_to_go(rewards, 0.9))


@stub("returns_to_go", points=1, hint="The last step's return is its own reward; gamma multiplies what follows.")
def test_a_hand_computed_case(student):
    check_array(student.returns_to_go(np.array([[0.0, 0.0, 4.0]]), 0.5), np.array([[1.0, 2.0, 4.0]]))
''',
    "test_mean_return.py": '''"""Hidden tests of mean_return (returns_to_go runs as the reference while it is tested)."""
from autograder.suite import check_scalar, stub


@stub("mean_return", points=1, hint="Average G_0, the first column of returns_to_go, over the episodes.")
def test_matches_the_reference(student, reference, rng):
    rewards = rng.normal(size=(5, 6))
    check_scalar(student.mean_return(rewards, 0.8), reference.mean_return(rewards, 0.8))
''',
}

TRIVIAL = '''"""Trivial answers to {assignment}'s stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {{
"returns_to_go": \'\'\'
def returns_to_go(rewards, gamma):
    """The rewards handed back: right for the last step only."""
    return np.asarray(rewards, dtype=float).copy()
\'\'\',
"mean_return": \'\'\'
def mean_return(rewards, gamma):
    """The mean reward: the right type, the wrong value."""
    return float(np.mean(rewards))
\'\'\',
}}
'''


def create(assignment: str, title: str = "a new assignment") -> list[Path]:
    """Write the skeleton of ``assignment`` (refusing to overwrite one), its student notebook, samples and
    per-test limits (so that its looping sample costs seconds, not ``call_seconds`` a stub)."""
    from autograder.authoring.limits import write_limits
    from autograder.authoring.release import generate_assignments
    from autograder.authoring.samples import write_samples

    if not ID_PATTERN.fullmatch(assignment):
        raise SystemExit(f"an assignment id looks like hw7_verifiers (hw, a number, _, lower-case words), "
                         f"not {assignment!r}")
    solution, suite = course.solution_notebook(assignment), course.suite_dir(assignment)
    for path in (solution.parent, suite, course.release_notebook(assignment).parent, course.samples_dir(assignment)):
        if path.exists():
            raise SystemExit(f"{path} exists already: `new` never overwrites an assignment")
    solution.parent.mkdir(parents=True)
    nbformat.write(solution_notebook(assignment, title), str(solution))
    suite.mkdir(parents=True)
    written = [solution]
    for name, text in SUITE.items():
        (suite / name).write_text(text)
        written.append(suite / name)
    (suite / "trivial_answers.py").write_text(TRIVIAL.format(assignment=assignment))
    (suite / "equivalent_mutants.json").write_text(json.dumps({}, indent=2) + "\n")
    written += [suite / "trivial_answers.py", suite / "equivalent_mutants.json"]
    written += generate_assignments([assignment])
    written += write_samples(assignment)
    write_limits(assignment)
    written.append(course.suite_dir(assignment) / "limits.json")
    return written
