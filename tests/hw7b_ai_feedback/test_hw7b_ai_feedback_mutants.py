"""hw7b's hidden suite against hand-written mutants of its reference solution: each a common mistake in one stub.

Every mutant is the complete solution with one text replacement in one stub. Graded by the real grader (sandbox and
all), each must lose points on its own stub and keep full marks elsewhere. The automatic mutation figures quoted in
README come from ``python -m autograder mutants hw7b_ai_feedback``; these are the mistakes a student is likely to make.

    .venv/bin/pytest -q -s tests/hw7b_ai_feedback/test_hw7b_ai_feedback_mutants.py
"""
from __future__ import annotations

import pytest

from conftest import check_hand_mutants

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
    check_hand_mutants(ID, MUTANTS, open_tmp)
