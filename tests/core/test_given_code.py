"""Given code never answers a stub, under its own name or behind an adapter.

The student library holds, for one assignment's experiments, code that computes another assignment's stubs
(hw3's feedback-spectrum fitters fit Bradley-Terry, hw6's helpers run hw5's ``token_log_probs`` on a model).
A worker grading an assignment therefore sees only the library modules that grading it needs
(``course.library_modules``: what its trusted cells, its reference's stubs and its suite's helpers import, and
what those import) and only its own release notebook; compiled caches are masked too.

Each attack below is a complete sample whose target stubs are a few lines of adapter around given code. Graded
with the assignment's view, every target earns nothing; graded with a view of the whole library (the control,
the grader as it was), the same adapters earn points, so the check can fail.
"""
from __future__ import annotations

import textwrap

import pytest

from autograder.core import course
from autograder.core.grader import Grader
from autograder.core.notebook import imported_names
from autograder.sandbox.config import SpawnConfig
from conftest import with_cells

# hw3: Bradley-Terry utilities from hw3's own feedback-spectrum fitter (a linear model on one-hot features),
# and the Plackett-Luce loss read out of the closure that the Plackett-Luce fitter hands to the optimiser.
BT_ADAPTER = """
import numpy as np
from rlcourse.feedback_spectrum import fit_bradley_terry_linear as _fit

def {name}(n_items, i, j, mu, *args, **kwargs):
    w = _fit(np.eye(n_items), np.stack([np.asarray(i), np.asarray(j)], 1), np.asarray(mu, float), l2=0.0)
    return w - w.mean()
"""
PL_ADAPTER = """
import numpy as np
import rlcourse.feedback_spectrum as _fs

def plackett_luce_loss(scores, rankings):
    scores = np.asarray(scores, float)
    B, K = scores.shape
    seen = {}

    def grab(f, x0, **kwargs):
        seen["f"] = f
        return type("R", (), {"x": x0})

    _fs.minimize, keep = grab, _fs.minimize
    try:
        _fs.fit_plackett_luce_linear(np.eye(B * K), np.arange(B * K).reshape(B, K), np.asarray(rankings), l2=0.0)
    finally:
        _fs.minimize = keep
    return float(seen["f"](scores.reshape(-1))[0])
"""
# hw5: hw6's helper runs a TinyLM and gathers the log-probabilities; a TinyLM whose forward returns the given
# logits makes it hw5's token_log_probs (token ids shifted by one so that no masked token is the padding id).
LOGPROB_ADAPTER = """
import torch
import torch.nn.functional as F
from rlcourse.group_rl import completion_log_probs as _given
from rlcourse.lm import TinyLM

class _Fixed(TinyLM):
    def __init__(self, logits):
        torch.nn.Module.__init__(self)
        self.logits = logits
    def forward(self, tokens):
        return self.logits

def token_log_probs(logits, tokens, mask):
    shifted = F.pad(logits, (1, 0), value=-1e9)                      # token v is now v + 1: never the padding id
    out = _given(_Fixed(shifted), tokens + 1, 1)
    keep = mask.bool().clone()
    keep[:, 0] = False
    return torch.where(keep, out, torch.zeros_like(out))
"""
# hw7: pass@k is best-of-k with the pass indicators as both score and value, which hw6's pool estimator computes
# (rlcourse.group_rl, once in hw7's view because rlcourse.verifier_rl imported a log-probability helper from it).
POOL_ADAPTER = """
import numpy as np

def pass_at_k(n, c, k):
    from rlcourse.group_rl import best_of_n_from_pool
    n, c = np.broadcast_arrays(np.asarray(n, dtype=np.int64), np.asarray(c, dtype=np.int64))
    if k < 1 or k > n.min():
        raise ValueError("k must be between 1 and n")
    out = np.empty(n.shape)
    for idx in np.ndindex(n.shape):
        hits = (np.arange(n[idx]) < c[idx]).astype(float)[None]
        out[idx] = 1.0 if n[idx] - c[idx] < k else best_of_n_from_pool(hits, hits, k)[0]
    return out
"""
# Any assignment: another assignment's release notebook, whose given cells would run as code; the stub is
# right only where that file could be read (so a point means the file was in the view).
OTHER_RELEASE = """
import json
try:
    _given = [c for c in json.load(open({path!r}))["cells"] if c["cell_type"] == "code"]
except OSError:
    _given = []
{solution}
if not _given:
    del episode_returns
"""

ATTACKS = {
    "hw3_preferences": {"fit_bradley_terry": BT_ADAPTER.format(name="fit_bradley_terry"),
                        "fit_bradley_terry_mm": BT_ADAPTER.format(name="fit_bradley_terry_mm"),
                        "plackett_luce_loss": PL_ADAPTER},
    "hw5_lm_alignment": {"token_log_probs": LOGPROB_ADAPTER},
    "hw7_verifier_rl": {"pass_at_k": POOL_ADAPTER},
}


def _grade(assignment: str, notebook, whole_library: bool) -> dict[str, tuple[float, float]]:
    grader = Grader(assignment)
    try:
        if whole_library:  # the control: every module and every release notebook in the view, as before
            grader.config = SpawnConfig(course.sandbox_view(()), grader.limits)
        result = grader.grade(notebook)
    finally:
        grader.close()
    assert result.status == "graded", result.error
    return {s.name: (s.score, s.max_score) for s in result.stubs}


@pytest.mark.slow
@pytest.mark.parametrize("assignment", sorted(ATTACKS))
def test_adapters_around_given_code_earn_nothing_and_would_without_the_assignments_view(assignment, open_tmp):
    targets = ATTACKS[assignment]
    notebook = with_cells(course.samples_dir(assignment) / "complete.ipynb", open_tmp / f"{assignment}.ipynb",
                          {stub: textwrap.dedent(src) for stub, src in targets.items()})
    graded = _grade(assignment, notebook, whole_library=False)
    earned = {stub: graded[stub] for stub in targets if graded[stub][0] > 0}
    assert not earned, f"given code answered {earned} behind an adapter"
    control = _grade(assignment, notebook, whole_library=True)
    assert sum(control[stub][0] for stub in targets) > 0, f"the control earned nothing: {control}"


@pytest.mark.slow
def test_another_assignments_release_notebook_is_not_in_the_view(open_tmp):
    """The given cells of another assignment's release notebook are code a stub could run: not in the view."""
    import nbformat

    complete = course.samples_dir("hw0_setup") / "complete.ipynb"
    solution = next(c.source for c in nbformat.read(str(complete), as_version=4).cells
                    if c.metadata.get("nbgrader", {}).get("grade_id") == "episode_returns")
    attack = OTHER_RELEASE.format(path=str(course.release_notebook("hw6_group_rl")), solution=solution)
    notebook = with_cells(complete, open_tmp / "peek.ipynb", {"episode_returns": attack})
    assert _grade("hw0_setup", notebook, whole_library=False)["episode_returns"][0] == 0
    assert _grade("hw0_setup", notebook, whole_library=True)["episode_returns"][0] > 0  # the control


def test_each_view_shows_its_own_release_and_the_library_it_needs_only():
    for assignment in course.assignment_ids():
        if not course.suite_dir(assignment).is_dir():
            continue
        view = course.sandbox_view((), assignment)
        notebooks = [p for p in view.expose if p.endswith(".ipynb")]
        assert notebooks == [str(course.release_notebook(assignment))], (assignment, notebooks)
        needed = course.library_modules(assignment)
        library = sorted((course.REPO / course.LIBRARY).glob("*.py"))
        masked = {p for p in view.mask}
        for module in library:
            assert (str(module) in masked) != (module in needed), (assignment, module.name)
        assert all(str(p) in masked and str(p) in view.secret
                   for p in (course.REPO / course.LIBRARY).rglob("__pycache__")), assignment
    # what the arrows of the library say: hw5 needs its loops but not hw6's helpers, hw3 not the spectrum's fitters
    names = {a: {p.stem for p in course.library_modules(a)}
             for a in ("hw3_preferences", "hw5_lm_alignment", "hw7_verifier_rl")}
    assert {"preferences", "__init__"} <= names["hw3_preferences"] and "feedback_spectrum" not in names["hw3_preferences"]
    assert {"lm_training", "lm"} <= names["hw5_lm_alignment"] and not {"group_rl", "completions"} & names["hw5_lm_alignment"]
    assert {"verifier_rl", "completions"} <= names["hw7_verifier_rl"] and "group_rl" not in names["hw7_verifier_rl"]


def test_imports_are_read_from_the_ast_with_relative_and_nested_ones():
    source = textwrap.dedent("""
        import rlcourse.lm as L
        from rlcourse import reviews
        from . import seeding
        from .data import load
        def f():
            from rlcourse.group_rl import x
        """)
    names = imported_names(source, package="rlcourse")
    assert {"rlcourse", "rlcourse.lm", "rlcourse.reviews", "rlcourse.seeding", "rlcourse.data",
            "rlcourse.group_rl"} <= names
    assert imported_names("def broken(:\n") == set()
    assert "rlcourse.seeding" not in imported_names("from . import seeding")  # no package: not resolvable
