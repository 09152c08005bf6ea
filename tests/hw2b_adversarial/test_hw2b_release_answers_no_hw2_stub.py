"""hw2b's given code answers none of hw2's stubs: hw2's hidden suite, run against each of hw2b's given functions.

Since the sandbox shows hw2 only the library modules grading it needs (``course.library_modules``), the imports
below fail there; this test stays as the design's second wall, for a view that would show more.
``rlcourse.adversarial`` (what hw2b gives) must not plan, compute visitation frequencies or fit MaxEnt weights
by itself: hw2b's students write the backward and forward passes (``soft_policy``, ``state_distributions``) and the module takes them as arguments. Each
submission here is hw2's complete sample with every stub cell replaced by an import of one
``rlcourse.adversarial`` function under that stub's name; over the submissions, every function stands in for
every stub once. Graded by the real grader, each must score 0 on every stub. A control (an exact soft backward
pass like the one this module had before it took the planner as an argument) shows the check can fail.

    .venv/bin/pytest -q -s tests/hw2b_adversarial/test_hw2b_release_answers_no_hw2_stub.py
"""
from __future__ import annotations

import inspect

import pytest

from autograder.core import course
from autograder.outputs.files import grade_folder
from conftest import with_cells
from rlcourse import adversarial as A

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

HW2 = "hw2_maxent_irl"

FORMER_PLANNER = '''import numpy as np


def soft_value_iteration(P, reward, horizon, temperature=1.0):
    n_states, n_actions = P.shape[:2]
    reward = np.broadcast_to(np.asarray(reward, dtype=float)[:, None], (horizon, n_states, n_actions))
    policy, v = np.empty((horizon, n_states, n_actions)), np.zeros(n_states)
    for t in reversed(range(horizon)):
        q = (reward[t] + (P.reshape(-1, n_states) @ v).reshape(n_states, n_actions)) / temperature
        m = q.max(axis=1, keepdims=True)
        log_z = m + np.log(np.exp(q - m).sum(axis=1, keepdims=True))
        policy[t] = np.exp(q - log_z)
        v = temperature * log_z[:, 0]
    return policy
'''


def helpers() -> list[str]:
    """The public functions ``rlcourse.adversarial`` defines (what hw2b's release gives)."""
    return sorted(name for name, f in inspect.getmembers(A, inspect.isfunction)
                  if f.__module__ == A.__name__ and not name.startswith("_"))


def test_no_hw2b_helper_earns_a_point_on_any_hw2_stub_and_a_planner_would(open_tmp):
    stubs, names = course.stub_names(HW2), helpers()
    assert "train_adversarial" in names
    complete = course.samples_dir(HW2) / "complete.ipynb"
    folder, plan = open_tmp / "aliases", {}
    for k in range(max(len(names), len(stubs))):     # submission k: stub j is helper (k + j) mod H
        chosen = {stub: names[(k + j) % len(names)] for j, stub in enumerate(stubs)}
        plan[f"aliases_{k:02d}"] = chosen
        with_cells(complete, folder / f"aliases_{k:02d}.ipynb",
                   {stub: f"from rlcourse.adversarial import {helper} as {stub}\n" for stub, helper in chosen.items()})
    with_cells(complete, folder / "control.ipynb", {"soft_value_iteration": FORMER_PLANNER})
    results = {r.submission: r for r in grade_folder(HW2, folder, open_tmp / "out", jobs=2, progress=False)}

    control = {s.name: (s.score, s.max_score) for s in results["control"].stubs}
    assert control["soft_value_iteration"][0] == control["soft_value_iteration"][1] > 0, control
    earned = [f"{helper} as {stub}: {got}/{top}"
              for name, chosen in plan.items()
              for s in results[name].stubs
              for stub, helper in chosen.items() if s.name == stub
              for got, top in [(s.score, s.max_score)] if got > 0]
    print(f"\n{len(names)} helpers x {len(stubs)} stubs graded; points earned: {earned or 'none'}")
    assert not earned, earned
