"""Trivial answers to hw5_lm_alignment's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"token_log_probs": '''
def token_log_probs(logits, tokens, mask):
    """Zero wherever the mask is on (the padding test's answer)."""
    return (logits[:, :-1, 0] * 0) * mask[:, 1:].to(logits.dtype)
''',
"sequence_log_prob": '''
def sequence_log_prob(logits, tokens, mask):
    """Zero for every sequence."""
    return logits.sum((1, 2)) * 0
''',
"reward_model_loss": '''
def reward_model_loss(chosen_scores, rejected_scores):
    """log 2 whatever the scores."""
    return (chosen_scores * 0).sum() + (rejected_scores * 0).sum() + float(np.log(2))
''',
"best_of_n": '''
def best_of_n(generate, reward_model, prompts, n):
    """The first sample for every prompt, no scoring."""
    return generate(prompts)
''',
"kl_penalised_rewards": '''
def kl_penalised_rewards(score, logp, logp_ref, mask, beta):
    """All zero."""
    return torch.zeros_like(logp)
''',
"ppo_token_loss": '''
def ppo_token_loss(logp, logp_old, advantages, values, returns, mask, clip_eps=0.2, value_coef=0.5):
    """A constant zero loss that keeps the graph."""
    return (logp * 0).sum() + (values * 0).sum()
''',
"dpo_loss": '''
def dpo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """log 2, the loss at the reference."""
    return (pi_chosen * 0).sum() + (pi_rejected * 0).sum() + float(np.log(2))
''',
}
