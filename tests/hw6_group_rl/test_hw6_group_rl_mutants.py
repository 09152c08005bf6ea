"""hw6's hidden suite against mutants of its reference solution: each mutant is a common mistake in one stub.

Every mutant is the complete solution with one text replacement in one stub. Graded by the real grader (sandbox
and all), each must lose points on its own stub and keep full marks elsewhere. The table printed with ``-s`` is the
mutation report quoted in README: killed (lost points) out of non-equivalent mutants, per stub.

    .venv/bin/pytest -q -s tests/test_hw6_group_rl_mutants.py
"""
from __future__ import annotations

import pytest

from conftest import check_hand_mutants

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

ID = "hw6_group_rl"

# stub -> {mutant name: (text in the solution, replacement)}
MUTANTS = {
    "group_advantages": {
        "mean over the batch axis": ("rewards.mean(dim=1", "rewards.mean(dim=0"),
        "population std": ("rewards.std(dim=1, keepdim=True)", "rewards.std(dim=1, keepdim=True, unbiased=False)"),
        "no eps": ("(rewards.std(dim=1, keepdim=True) + eps)", "rewards.std(dim=1, keepdim=True)"),
        "eps inside the square root": ("(rewards.std(dim=1, keepdim=True) + eps)",
                                       "(rewards.var(dim=1, keepdim=True) + eps).sqrt()"),
        "scale ignored": ("    if not scale:\n        return centred\n", ""),
        "never scales": ("    if not scale:\n", "    if True:\n"),
        "sign flipped": ("centred = rewards - rewards.mean(dim=1, keepdim=True)",
                         "centred = rewards.mean(dim=1, keepdim=True) - rewards"),
        "modifies its input": ("centred = rewards - rewards.mean(dim=1, keepdim=True)",
                               "centred = rewards.sub_(rewards.mean(dim=1, keepdim=True))"),
        "float32 always": ("    return centred / (rewards.std(dim=1, keepdim=True) + eps)",
                           "    return (centred / (rewards.std(dim=1, keepdim=True) + eps)).float()"),
        "eps 1e-8 whatever is asked": ("+ eps)", "+ 1e-8)"),
    },
    "rloo_advantages": {
        "group mean baseline": ("others = (rewards.sum(dim=1, keepdim=True) - rewards) / (g - 1)",
                                "others = rewards.mean(dim=1, keepdim=True)"),
        "divides by G": ("/ (g - 1)", "/ g"),
        "batch axis": ("g = rewards.shape[1]\n    others = (rewards.sum(dim=1,", "g = rewards.shape[0]\n    others = (rewards.sum(dim=0,"),
        "sign flipped": ("return rewards - others", "return others - rewards"),
        "self included": ("(rewards.sum(dim=1, keepdim=True) - rewards) / (g - 1)", "rewards.sum(dim=1, keepdim=True) / (g - 1)"),
        "baseline of the next one": ("return rewards - others", "return rewards - others.roll(1, dims=1)"),
    },
    "grpo_token_loss": {
        "no clipping": ("torch.maximum(-ratio * adv, -ratio.clamp(1 - clip_eps, 1 + clip_eps) * adv)", "-ratio * adv"),
        "min for max": ("torch.maximum(-ratio * adv,", "torch.minimum(-ratio * adv,"),
        "k3 of the reversed ratio": ("log_r = logp_ref - logp", "log_r = logp - logp_ref"),
        "k3 without the -1": ("torch.exp(log_r) - log_r - 1", "torch.exp(log_r) - log_r"),
        "k1 instead of k3": ("(torch.exp(log_r) - log_r - 1)", "(-log_r)"),
        "batch token mean for GRPO": ("(per_token.sum(dim=1) / mask.sum(dim=1)).mean()", "per_token.sum() / mask.sum()"),
        "Dr. GRPO by the token count": ("per_token.sum() / mask.numel()", "per_token.sum() / mask.sum()"),
        "Dr. GRPO by the row count": ("per_token.sum() / mask.numel()", "per_token.sum() / mask.shape[0]"),
        "advantages on the wrong axis": ("adv = advantages[:, None]", "adv = advantages[None, :]"),
        "junk not removed": ("torch.where(keep, x, torch.zeros_like(x))", "x"),
        "beta ignored": ("+ beta * (", "+ 0.04 * ("),
        "clip range fixed": ("ratio.clamp(1 - clip_eps, 1 + clip_eps)", "ratio.clamp(0.8, 1.2)"),
        "inverted ratio": ("ratio = torch.exp(logp - logp_old)", "ratio = torch.exp(logp_old - logp)"),
        "length_norm ignored": ("    if length_norm:\n", "    if True:\n"),
        "KL detached": ("log_r = logp_ref - logp", "log_r = logp_ref - logp.detach()"),
    },
    "ipo_loss": {
        "target 1/beta": ("1.0 / (2.0 * beta)", "1.0 / beta"),
        "target beta/2": ("1.0 / (2.0 * beta)", "beta / 2.0"),
        "absolute error": ("((margin - 1.0 / (2.0 * beta)) ** 2).mean()", "(margin - 1.0 / (2.0 * beta)).abs().mean()"),
        "sum over pairs": ("** 2).mean()", "** 2).sum()"),
        "margin flipped": ("margin = (pi_chosen - ref_chosen) - (pi_rejected - ref_rejected)",
                           "margin = (pi_rejected - ref_rejected) - (pi_chosen - ref_chosen)"),
        "beta times the margin": ("((margin - 1.0 / (2.0 * beta)) ** 2)", "((beta * margin - 0.5) ** 2)"),
    },
    "kto_loss": {
        "z0 not detached": ("torch.as_tensor(kl_ref, dtype=pi.dtype).detach()", "torch.as_tensor(kl_ref, dtype=pi.dtype)"),
        "no weight in the first term": ("return (weight - value).mean()", "return (1.0 - value).mean()"),
        "undesirable sign": ("torch.where(desirable, r - z0, z0 - r)", "(r - z0)"),
        "z0 ignored": ("r - z0, z0 - r", "r, -r"),
        "minus v only": ("return (weight - value).mean()", "return (-value).mean()"),
        "weights swapped": ("torch.full_like(r, w_desirable), torch.full_like(r, w_undesirable)",
                            "torch.full_like(r, w_undesirable), torch.full_like(r, w_desirable)"),
        "two means added": ("return (weight - value).mean()",
                            "loss = weight - value\n    return loss[desirable].mean() + loss[~desirable].mean()"),
        "beta ignored": ("torch.sigmoid(beta * torch.where", "torch.sigmoid(torch.where"),
    },
}


def test_every_mutant_loses_points_on_its_own_stub_and_only_there(open_tmp):
    check_hand_mutants(ID, MUTANTS, open_tmp)
