"""Sample submissions of an assignment, made from its solution and student notebooks.

Every assignment gets the same kinds, so the demo and the tests can say what
each must score: ``complete`` (full marks), ``partial`` (the first half of the
stubs done: credit on exactly those), ``untouched`` (zero, "not implemented"),
``broken_syntax``, ``broken_exception`` and ``infinite_loop`` (the first stub
broken, the rest done: credit on the rest), and ``cheating`` (every stub tries a
trick: zero). An assignment may add samples of its own in ``EXTRA_SAMPLES`` (say, a
complete solution but for one stub that answers from a shipped file).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import nbformat

from autograder.core import course
from autograder.core.notebook import read_notebook

MARKERS = ("### BEGIN SOLUTION", "### END SOLUTION")

CHEAT = '''
class _AlwaysEqual(float):
    """Claims equality with anything, and looks like an array."""
    shape = property(lambda self: ())
    dtype = property(lambda self: __import__("numpy").dtype(float))
    def __eq__(self, other): return True
    def __ne__(self, other): return False
    __hash__ = float.__hash__

import builtins, glob, sys
for _path in glob.glob("/*/*/autograder/suites/*/*.py") + glob.glob("/*/*/solutions/*/*.ipynb"):
    try:
        print(open(_path).read()[:100])
    except OSError:
        pass
print('{"score": 100, "tests": []}')
import numpy as _np
_np.allclose = lambda *a, **k: True
builtins.isinstance = lambda *a: True

def {name}(*args, **kwargs):
    return _AlwaysEqual(0.0)
'''


# --------------------------------------------------------------------------- assignment-specific samples
# Each: sample name -> {stub: source}; the other stubs are the complete solution's. The stubs named here
# are expected to score zero, the others full marks.
SHIPPED_REWARD_MODEL = '''
def train_reward_model(obs: torch.Tensor, act: torch.Tensor, pairs: np.ndarray, mu: np.ndarray,
                       n_members: int = 3, hidden: tuple = (64, 64), n_steps: int = 500,
                       batch_size: int = 64, lr: float = 1e-3, weight_decay: float = 0.1,
                       seed: int = 0) -> RewardEnsemble:
    """No training: hw4's shipped reward model was fitted to these very Hopper pairs, so hand it back,
    with as many members as asked for and normalised on the segments in `pairs`."""
    from rlcourse.rlhf import load_reward_model

    shipped = load_reward_model()
    ensemble = RewardEnsemble(shipped.obs_dim, shipped.act_dim, n_members, shipped.hidden, seed=seed)
    for k in range(n_members):
        ensemble.members[k].load_state_dict(shipped.members[k % shipped.n_members].state_dict())
    ensemble.in_mean.copy_(shipped.in_mean)
    ensemble.in_std.copy_(shipped.in_std)
    used = np.unique(np.asarray(pairs))
    return ensemble.normalise_(torch.as_tensor(obs)[used], torch.as_tensor(act)[used])
'''

EXTRA_SAMPLES = {
    "hw3_preferences": {"cheating_shipped_model": {"train_reward_model": SHIPPED_REWARD_MODEL}},
}


def solution_sources(assignment: str) -> dict[str, str]:
    """Each stub's solution cell with the solution markers removed (what a perfect student writes)."""
    out = {}
    for cell in read_notebook(course.solution_notebook(assignment)).cells:
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type == "code" and meta.get("solution") and meta.get("grade_id"):
            lines = [l for l in cell.source.splitlines() if l.strip() not in MARKERS]
            out[meta["grade_id"]] = "\n".join(lines)
    return out


def _with_stubs(assignment: str, sources: dict[str, str]) -> nbformat.NotebookNode:
    nb = read_notebook(course.release_notebook(assignment))
    for cell in nb.cells:
        grade_id = cell.metadata.get("nbgrader", {}).get("grade_id")
        if cell.cell_type == "code" and grade_id in sources:
            cell.source = sources[grade_id]
    return nb


def make_samples(assignment: str) -> dict[str, tuple[nbformat.NotebookNode, dict[str, str]]]:
    """Each sample notebook with the outcome expected per stub ("full" or "zero").

    The broken samples break a stub that no other stub calls, so that "the rest is done" means
    full marks on the rest whatever the grader can stand in for (see ``Worker.reference_stand_in``).
    """
    from autograder.core.grader import stub_dependencies

    solved = solution_sources(assignment)
    stubs = list(solved)
    called = {d for deps in stub_dependencies(assignment, stubs).values() for d in deps}
    first = next((s for s in stubs if s not in called), stubs[-1])
    done_half = stubs[: math.ceil(len(stubs) / 2)]
    samples = {
        "complete": (solved, {s: "full" for s in stubs}),
        "partial": ({s: solved[s] for s in done_half}, {s: "full" if s in done_half else "zero" for s in stubs}),
        "untouched": ({}, {s: "zero" for s in stubs}),
        "broken_syntax": ({**solved, first: solved[first] + "\n    return )(\n"},
                          {s: "zero" if s == first else "full" for s in stubs}),
        "broken_exception": ({**solved, first: solved[first] + f"\n\ndef {first}(*args, **kwargs):\n"
                              "    raise ZeroDivisionError('a bug in my code')\n"},
                             {s: "zero" if s == first else "full" for s in stubs}),
        "infinite_loop": ({**solved, first: solved[first] + f"\n\ndef {first}(*args, **kwargs):\n"
                           "    while True:\n        pass\n"},
                          {s: "zero" if s == first else "full" for s in stubs}),
        "cheating": ({s: CHEAT.replace("{name}", s) for s in stubs}, {s: "zero" for s in stubs}),
    }
    for name, cheats in EXTRA_SAMPLES.get(assignment, {}).items():
        samples[name] = ({**solved, **cheats}, {s: "zero" if s in cheats else "full" for s in stubs})
    return {name: (_with_stubs(assignment, sources), expected) for name, (sources, expected) in samples.items()}


def write_samples(assignment: str) -> list[Path]:
    """Write the samples and ``expected.json`` into ``autograder/samples/<id>/``."""
    folder = course.samples_dir(assignment)
    folder.mkdir(parents=True, exist_ok=True)
    written, expected = [], {}
    for name, (nb, outcome) in make_samples(assignment).items():
        path = folder / f"{name}.ipynb"
        nbformat.write(nb, str(path))
        written.append(path)
        expected[name] = outcome
    (folder / "expected.json").write_text(json.dumps(expected, indent=2) + "\n")
    return written
