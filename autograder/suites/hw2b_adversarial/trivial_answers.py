"""Trivial answers to hw2b_adversarial's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"soft_policy": '''
def soft_policy(P, reward, horizon):
    """The uniform policy: right at the last step of an action-independent reward, and nowhere else."""
    return np.full((horizon, P.shape[0], P.shape[1]), 1.0 / P.shape[1])
''',
"state_distributions": '''
def state_distributions(P, policy, p0):
    """The start distribution at every step."""
    return np.tile(np.asarray(p0, dtype=float), (policy.shape[0], 1))
''',
"discriminator_loss": '''
def discriminator_loss(expert_logits, policy_logits):
    """The loss of a discriminator that says 1/2 everywhere, 2 log 2, keeping the graph."""
    return (expert_logits * 0).sum() + (policy_logits * 0).sum() + 2 * 0.6931471805599453
''',
"airl_logits": '''
def airl_logits(g, h, h_next, log_pi, gamma, done):
    """The reward term handed back: g."""
    return g + 0 * (h + h_next + log_pi + done)
''',
"policy_reward": '''
def policy_reward(logits, kind):
    """The logits handed back, whatever the kind."""
    return logits
''',
}
