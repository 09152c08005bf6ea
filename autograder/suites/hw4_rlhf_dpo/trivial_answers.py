"""Trivial answers to hw4_rlhf_dpo's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"compute_gae": '''
def compute_gae(rewards, values, dones, last_value, gamma, lam):
    """The input handed back: rewards as advantages."""
    return rewards.clone(), rewards + values
''',
"ppo_loss": '''
def ppo_loss(new_log_prob, old_log_prob, advantages, new_values, returns, entropy, kl_to_ref, clip_coef=0.2,
             vf_coef=0.5, ent_coef=0.0, kl_coef=0.0):
    """A constant loss with zero metrics."""
    zero = torch.zeros(())
    terms = {k: zero.clone() for k in ("policy_loss", "value_loss", "entropy", "kl_ref", "approx_kl", "clip_frac")}
    return (new_log_prob * 0).sum() + (new_values * 0).sum(), terms
''',
"LearnedRewardWrapper": '''
class LearnedRewardWrapper(gym.vector.VectorWrapper):
    """The environment's own reward passed through."""
    def __init__(self, env, reward_fn, mean=0.0, std=1.0, offset=0.0):
        super().__init__(env)
    def reset(self, **kwargs):
        return self.env.reset(**kwargs)
    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        return obs, reward, terminated, truncated, {**info, "true_reward": reward}
''',
"sequence_log_prob": '''
def sequence_log_prob(policy, obs, actions):
    """Zero log-likelihood for every segment."""
    return policy(obs).sum(-1).sum(-1) * 0
''',
"dpo_loss": '''
def dpo_loss(policy, reference, chosen, rejected, beta):
    """log 2 (the loss at the reference) and zero metrics."""
    zero = torch.zeros(())
    loss = sum((p * 0).sum() for p in policy.parameters()) + float(np.log(2))
    return loss, {"margin": zero, "accuracy": zero, "chosen_reward": zero, "rejected_reward": zero}
''',
}
