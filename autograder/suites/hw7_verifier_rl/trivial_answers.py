"""Trivial answers to hw7_verifier_rl's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"verifier_reward": '''
def verifier_reward(tokens):
    """Everything passes: ones of the right shape and dtype."""
    ones = torch.ones(tokens.shape[0])
    return ones, ones.clone()
''',
"pass_at_k": '''
def pass_at_k(n, c, k):
    """The plug-in estimate 1 - (1 - c/n)^k: plausible, biased, and not the estimator asked for."""
    n, c = np.asarray(n, dtype=float), np.asarray(c, dtype=float)
    return np.asarray(1.0 - (1.0 - c / n) ** k, dtype=np.float64)
''',
"rft_loss": '''
def rft_loss(logp, mask):
    """A constant that keeps the graph."""
    return (logp * 0).sum()
''',
"rft_select": '''
def rft_select(tokens, correct, group, max_per_prompt):
    """Every row, filtered by nothing."""
    return torch.arange(len(tokens))
''',
"binary_group_advantages": '''
def binary_group_advantages(k, group, kind="grpo", eps=1e-4):
    """Zeros: an all-equal group gets these, so only the values can tell."""
    return torch.zeros(len(k), 2, dtype=torch.float64)
''',
}
