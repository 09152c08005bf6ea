"""hw7b's hidden suite against hand-written mutants of its reference solution: each a common mistake in one stub.

Every mutant is the complete solution with one text replacement in one stub. Graded by the real grader (sandbox and
all), each must lose points on its own stub and keep full marks elsewhere. The automatic mutation figures quoted in
README come from ``python -m autograder mutants hw7b_ai_feedback``; these are the mistakes a student is likely to make.

    .venv/bin/pytest -q -s tests/hw7b_ai_feedback/test_hw7b_ai_feedback_mutants.py
"""
from __future__ import annotations

import pytest

from autograder.authoring.samples import solution_sources
from autograder.core import course
from autograder.outputs.files import grade_folder
from conftest import with_cells

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

ID = "hw7b_ai_feedback"

MUTANTS = {
    "online_dpo_round": {
        "pairs from the reference": ("source = policy if sampler is None else sampler",
                                     "source = ref if sampler is None else sampler"),
        "sampler ignored": ("source = policy if sampler is None else sampler", "source = policy"),
        "repeat instead of repeat_interleave": ("prompts.repeat_interleave(2, dim=0)", "prompts.repeat(2, 1)"),
        "ties kept as wins of a": ("keep = verdict != 0.5", "keep = verdict == verdict"),
        "chosen and rejected swapped": ("a_wins = (verdict > 0.5)[:, None]", "a_wins = (verdict < 0.5)[:, None]"),
        "no reference": ("loss = -F.logsigmoid(beta * ((pi_c - ref_c) - (pi_r - ref_r))).mean()",
                         "loss = -F.logsigmoid(beta * (pi_c - pi_r)).mean()"),
        "beta ignored": ("F.logsigmoid(beta * (", "F.logsigmoid(0.1 * ("),
        "sum over pairs": ("- (pi_r - ref_r))).mean()", "- (pi_r - ref_r))).sum()"),
        "stale gradients": ("    optimizer.zero_grad()\n", ""),
        "no generator": (", generator=generator)", ")"),
    },
    "rule_critic": {
        "share of the rules, weights ignored": ("/ w.sum()", "/ len(rules)"),
        "a minus b reversed": ("torch.sign(torch.as_tensor(rule(a), dtype=torch.float64)\n                                    - torch.as_tensor(rule(b), dtype=torch.float64))",
                               "torch.sign(torch.as_tensor(rule(b), dtype=torch.float64)\n                                    - torch.as_tensor(rule(a), dtype=torch.float64))"),
        "differences, not votes": ("torch.sign(torch.as_tensor(rule(a), dtype=torch.float64)\n                                    - torch.as_tensor(rule(b), dtype=torch.float64))",
                                   "(torch.as_tensor(rule(a), dtype=torch.float64)\n                                    - torch.as_tensor(rule(b), dtype=torch.float64))"),
        "no half-range": ("return 0.5 + 0.5 * (votes @ w) / w.sum()", "return 0.5 + (votes @ w) / w.sum()"),
    },
    "position_swap": {
        "one order only": ("p = (p_ab + 1.0 - p_ba) / 2.0", "p = p_ab"),
        "swapped answer not inverted": ("p = (p_ab + 1.0 - p_ba) / 2.0", "p = (p_ab + p_ba) / 2.0"),
        "ties count as a pick": ("consistent = ((p_ab > 0.5) & (p_ba < 0.5)) | ((p_ab < 0.5) & (p_ba > 0.5))",
                                 "consistent = (p_ab > 0.5) != (p_ba > 0.5)"),
        "the same position twice": ("consistent = ((p_ab > 0.5) & (p_ba < 0.5)) | ((p_ab < 0.5) & (p_ba > 0.5))",
                                    "consistent = (p_ab > 0.5) == (p_ba > 0.5)"),
    },
}


def test_every_mutant_loses_points_on_its_own_stub_and_only_there(open_tmp):
    solved = solution_sources(ID)
    complete = course.samples_dir(ID) / "complete.ipynb"
    folder = open_tmp / "mutants"
    names = {}
    for stub, mutants in MUTANTS.items():
        for i, (label, (old, new)) in enumerate(mutants.items()):
            assert solved[stub].count(old) >= 1, f"{stub} / {label}: the text to mutate is not in the solution"
            name = f"{stub}__{i}"
            names[name] = (stub, label)
            with_cells(complete, folder / f"{name}.ipynb", {stub: solved[stub].replace(old, new)})
    results = {r.submission: r for r in grade_folder(ID, folder, open_tmp / "out", jobs=2, progress=False)}
    survivors, leaks, report = [], [], {}
    for name, (stub, label) in names.items():
        scores = {s.name: (s.score, s.max_score) for s in results[name].stubs}
        killed = scores[stub][0] < scores[stub][1]
        report.setdefault(stub, []).append(killed)
        if not killed:
            survivors.append(f"{stub}: {label}")
        leaks += [f"{stub}: {label} cost {other}" for other, (got, top) in scores.items() if other != stub and got < top]
    print("\n| stub | mutants | killed |\n|---|---:|---:|")
    for stub, kills in report.items():
        print(f"| `{stub}` | {len(kills)} | {sum(kills)} ({sum(kills) / len(kills):.0%}) |")
    assert not leaks, leaks
    assert not survivors, f"mutants the suite does not catch: {survivors}"
