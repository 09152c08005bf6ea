"""Trivial answers to hw6_group_rl's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"group_advantages": '''
def group_advantages(rewards, scale=True, eps=1e-4):
    """Zeros: a group of equal rewards gets these, so only the values can tell."""
    return torch.zeros_like(rewards)
''',
"rloo_advantages": '''
def rloo_advantages(rewards):
    """The rewards handed back unchanged."""
    return rewards.clone()
''',
"grpo_token_loss": '''
def grpo_token_loss(logp, logp_old, logp_ref, advantages, mask, clip_eps=0.2, beta=0.04, length_norm=True):
    """A constant that keeps the graph."""
    return (logp * 0).sum()
''',
"ipo_loss": '''
def ipo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """The loss at h = 0 for every pair, whatever the inputs: 1 / (4 beta^2), keeping the graph."""
    return (pi_chosen * 0).sum() + 1.0 / (4 * beta ** 2)
''',
"kto_loss": '''
def kto_loss(pi, ref, desirable, kl_ref, beta, w_desirable=1.0, w_undesirable=1.0):
    """The loss at r = z0 (every value 1/2): a constant that keeps the graph."""
    return (pi * 0).sum() + 0.5 * (w_desirable + w_undesirable) / 2
''',
}
