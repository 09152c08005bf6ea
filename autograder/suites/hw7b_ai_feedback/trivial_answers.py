"""Trivial answers to hw7b_ai_feedback's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"online_dpo_round": '''
def online_dpo_round(policy, ref, prompts, annotator, optimizer, beta, generator, sampler=None):
    """The prompts handed back as both halves of every pair, no step, the loss of a policy equal to its reference."""
    return {"loss": 0.6931471805599453, "chosen": prompts.clone(), "rejected": prompts.clone()}
''',
"rule_critic": '''
def rule_critic(rules, a, b, weights=None):
    """No preference on any pair."""
    return torch.full((a.shape[0],), 0.5, dtype=torch.float64)
''',
"position_swap": '''
def position_swap(judge, a, b):
    """No preference, every verdict called consistent."""
    return torch.full((a.shape[0],), 0.5, dtype=torch.float64), torch.ones(a.shape[0], dtype=torch.bool)
''',
}
