"""hw6's given code answers none of hw5's stubs: hw5's hidden suite, run against each of hw6's given helpers.

A helper that hw6 gives (``rlcourse.group_rl``) must not be one of hw5's stubs under another name. (The sandbox
now shows hw5 only the library modules grading it needs, so these imports fail there; the test stays as the
second wall, for a view that would show more; ``tests/core/test_given_code.py`` grades adapters with controls.) Each submission here is hw5's complete sample with every
stub cell replaced by an import of one ``rlcourse.group_rl`` function under that stub's name; over the
submissions, every helper stands in for every stub once. Graded by the real grader, each must score 0 on
every stub. A control (hw6's former helper, which took logits and a mask) shows the check can fail: it
earns hw5's ``token_log_probs`` its full points.

    .venv/bin/pytest -q -s tests/test_hw6_release_answers_no_hw5_stub.py
"""
from __future__ import annotations

import inspect

import pytest

from autograder.core import course
from autograder.outputs.files import grade_folder
from conftest import with_cells
from rlcourse import group_rl as G

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

HW5 = "hw5_lm_alignment"

# hw6's helper before this design: hw5's token_log_probs under another name (the control).
FORMER_HELPER = '''import torch
import torch.nn.functional as F


def token_log_probs(logits, tokens, mask):
    logp = F.log_softmax(logits[:, :-1], dim=-1).gather(-1, tokens[:, 1:, None]).squeeze(-1)
    logp = F.pad(logp, (1, 0))
    keep = mask.bool().clone()
    keep[:, 0] = False
    return torch.where(keep, logp, torch.zeros_like(logp))
'''


def helpers() -> list[str]:
    """The public functions ``rlcourse.group_rl`` gives (what hw6's release gives): its own and the log-probability
    helpers it takes from ``rlcourse.completions``."""
    return sorted(name for name, f in inspect.getmembers(G, inspect.isfunction)
                  if f.__module__ in (G.__name__, "rlcourse.completions") and not name.startswith("_"))


def test_no_hw6_helper_earns_a_point_on_any_hw5_stub_and_the_former_helper_would(open_tmp):
    stubs, names = course.stub_names(HW5), helpers()
    assert "completion_log_probs" in names and len(names) >= len(stubs)
    complete = course.samples_dir(HW5) / "complete.ipynb"
    folder, plan = open_tmp / "aliases", {}
    for k in range(len(names)):                      # submission k: stub j is helper (k + j) mod H
        chosen = {stub: names[(k + j) % len(names)] for j, stub in enumerate(stubs)}
        plan[f"aliases_{k:02d}"] = chosen
        with_cells(complete, folder / f"aliases_{k:02d}.ipynb",
                   {stub: f"from rlcourse.group_rl import {helper} as {stub}\n" for stub, helper in chosen.items()})
    with_cells(complete, folder / "control.ipynb", {"token_log_probs": FORMER_HELPER})
    results = {r.submission: r for r in grade_folder(HW5, folder, open_tmp / "out", jobs=2, progress=False)}

    control = {s.name: (s.score, s.max_score) for s in results["control"].stubs}
    assert control["token_log_probs"][0] == control["token_log_probs"][1] > 0, control
    earned = [f"{helper} as {stub}: {got}/{top}"
              for name, chosen in plan.items()
              for s in results[name].stubs
              for stub, helper in chosen.items() if s.name == stub
              for got, top in [(s.score, s.max_score)] if got > 0]
    print(f"\n{len(names)} helpers x {len(stubs)} stubs graded; points earned: {earned or 'none'}")
    assert not earned, earned
