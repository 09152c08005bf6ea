"""Issue 27, part 6: hidden tests that cannot be passed trivially, rebuilt from the release, or replayed.

Each assignment is graded once with every stub replaced by a trivial answer (the input handed back, a
uniform policy, the initial distribution times the horizon, a constant probability, a constant loss with
zero metrics, zeros, a made-up history) or a shortcut through the release (hw2's ``maxent_irl`` regenerates
the test's MDP by searching ``random_mdp`` seeds and returns its true weights): every stub must score 0,
so every hidden test pairs its invariance with a value that such an answer gets wrong.
"""
from __future__ import annotations

import zlib

import nbformat
import numpy as np
import pytest

from autograder.core import course
from autograder.core.grader import Grader
from autograder.authoring.samples import _with_stubs

pytestmark = pytest.mark.slow  # one grading per assignment: make test-fast leaves it out

HW1 = {
"bc_loss": '''
def bc_loss(policy, obs, actions):
    """A constant that keeps the graph: 0.5 log(2 pi) per action dimension."""
    return (policy(obs) * 0).sum() + policy.log_std.sum() * 0 + 0.5 * np.log(2 * np.pi) * actions.shape[-1]
''',
"train_bc": '''
def train_bc(policy, obs, actions, n_epochs=20, batch_size=256, lr=1e-3, val_fraction=0.1, seed=0):
    """No training, a made-up falling history."""
    return {"train": [float(n_epochs - e) for e in range(n_epochs)],
            "val": [float(n_epochs - e) + 0.5 for e in range(n_epochs)]}
''',
"relabel_with_expert": '''
def relabel_with_expert(expert, obs):
    """Zero actions of the Hopper's size."""
    obs = np.asarray(obs, dtype=np.float32)
    return np.zeros(obs.shape[:-1] + (3,), dtype=np.float32)
''',
"dagger": '''
def dagger(env_id, expert, policy, n_iterations, beta_schedule, demo_obs, demo_actions, episodes_per_iter=2, seed=0,
           **train_kwargs):
    """The untrained learner, the demonstrations as the data set, a made-up history."""
    n = len(demo_obs)
    return policy, {"returns": np.zeros(n_iterations), "dataset_sizes": np.full(n_iterations, n, dtype=np.int64),
                    "obs": np.asarray(demo_obs, dtype=np.float32), "actions": np.asarray(demo_actions, dtype=np.float32)}
''',
}
HW0 = {
"discounted_returns": '''
def discounted_returns(rewards, gamma):
    """The input handed back."""
    return np.array(rewards, dtype=float)
''',
"episode_returns": '''
def episode_returns(rewards, dones):
    """The rewards of the done steps only."""
    return np.asarray(rewards, dtype=float)[np.asarray(dones, dtype=bool)]
''',
}
HW2 = {
"feature_expectations": '''
def feature_expectations(trajectories, features):
    """Zeros."""
    return np.zeros(np.shape(features)[1])
''',
"soft_value_iteration": '''
def soft_value_iteration(P, reward, horizon):
    """A uniform policy."""
    S, A = np.shape(P)[:2]
    return np.full((horizon, S, A), 1.0 / A)
''',
"state_visitation_frequency": '''
def state_visitation_frequency(P, policy, p0, horizon):
    """The initial distribution times the horizon."""
    return horizon * np.asarray(p0, dtype=float)
''',
"maxent_irl": '''
def maxent_irl(P, features, p0, trajectories, horizon, actions=None, lr=1.0, n_iters=500, tol=1e-4):
    """No inverse RL: regenerate the test's MDP by searching random_mdp seeds for these features, return its
    true weights and a made-up rising history."""
    S, A = np.shape(P)[:2]
    for seed in range(200):
        m = random_mdp(S, A, np.shape(features)[1], horizon, seed=seed)
        if m.features.shape == np.shape(features) and np.allclose(m.features, features):
            return np.array(m.true_weights, dtype=float), {"grad_norm": np.array([1.0, 0.0]),
                                                           "log_likelihood": np.array([-1.0, 0.0])}
    return np.zeros(np.shape(features)[1]), {"grad_norm": np.array([1.0, 0.0]), "log_likelihood": np.array([-1.0, 0.0])}
''',
"deep_maxent_irl": '''
def deep_maxent_irl(P, features, p0, trajectories, horizon, actions=None, hidden=32, lr=0.01, n_iters=200,
                    weight_decay=1e-4, seed=0):
    """A zero reward and a constant history."""
    S = np.shape(P)[0]
    return np.zeros(S), {"grad_norm": np.ones(n_iters), "log_likelihood": -np.ones(n_iters)}
''',
"route_log_partition": '''
def route_log_partition(w, net, origins, destinations, horizon):
    """Zero log-partition (one route of reward 0) per trip, differentiable."""
    return w.sum() * 0 + torch.zeros(len(origins), dtype=w.dtype)
''',
"fit_route_weights": '''
def fit_route_weights(net, route_features, origins, destinations, horizon, n_iters=50):
    """The mean route features as weights and a made-up history."""
    return np.asarray(route_features, dtype=float).mean(0), np.array([-1.0, 0.0])
''',
}
HW3 = {
"bt_probability": '''
def bt_probability(r_i, r_j):
    """A constant probability of one half."""
    return np.full(np.broadcast(np.asarray(r_i), np.asarray(r_j)).shape, 0.5)
''',
"bt_loss": '''
def bt_loss(utilities, i, j, mu):
    """log 2, the loss at equal utilities."""
    return float(np.log(2))
''',
"bt_gradient": '''
def bt_gradient(utilities, i, j, mu):
    """Zeros."""
    return np.zeros(np.shape(utilities))
''',
"fit_bradley_terry": '''
def fit_bradley_terry(n_items, i, j, mu, lr=None, n_steps=5000, tol=1e-9):
    """Zero utilities."""
    return np.zeros(n_items)
''',
"fit_bradley_terry_mm": '''
def fit_bradley_terry_mm(n_items, i, j, mu, n_iters=5000, tol=1e-10):
    """Centred win counts."""
    w = np.bincount(np.asarray(i), np.asarray(mu, dtype=float), minlength=n_items)
    return w - w.mean()
''',
"plackett_luce_loss": '''
def plackett_luce_loss(scores, rankings):
    """A constant."""
    return 1.0
''',
"condorcet_winner": '''
def condorcet_winner(P):
    """Never a winner."""
    return None
''',
"copeland_winner": '''
def copeland_winner(P):
    """Arm 0."""
    return 0
''',
"borda_winner": '''
def borda_winner(P):
    """Arm 0."""
    return 0
''',
"rucb": '''
def rucb(env, horizon, alpha=0.51, rng=None):
    """Uniform random duels."""
    rng = np.random.default_rng(0) if rng is None else rng
    pairs = rng.integers(0, env.n_arms, size=(horizon, 2))
    for c, d in pairs:
        env.duel(int(c), int(d))
    return pairs.astype(np.int64)
''',
"segment_return": '''
def segment_return(reward_model, obs, act):
    """Zero returns that keep the graph."""
    r = reward_model(obs, act)
    return r.sum(-1) * 0
''',
"preference_loss": '''
def preference_loss(returns_a, returns_b, mu):
    """log 2 whatever the returns."""
    return (returns_a * 0).sum() + (returns_b * 0).sum() + float(np.log(2))
''',
"train_reward_model": '''
def train_reward_model(obs, act, pairs, mu, n_members=3, hidden=(64, 64), n_steps=500, batch_size=64, lr=1e-3,
                       weight_decay=0.1, seed=0):
    """An untrained ensemble, normalised."""
    obs, act = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)
    used = np.unique(np.asarray(pairs))
    ensemble = RewardEnsemble(obs.shape[-1], act.shape[-1], n_members, hidden, seed=seed)
    ensemble.set_input_scaling(obs[used], act[used])
    return ensemble.normalise_(obs[used], act[used])
''',
"select_queries": '''
def select_queries(ensemble, obs, act, candidates, k):
    """The first k candidates."""
    return np.arange(k)
''',
}
HW4 = {
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
HW5 = {
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

HW1B = {
"chunked_rollout": '''
def chunked_rollout(plan, env, execute):
    """Zero actions until every episode ends, plan never called."""
    obs = np.asarray(env.reset(), dtype=np.float32)
    n = len(obs)
    rec, done = [], np.zeros(n, dtype=bool)
    while not done.all():
        a = np.zeros((n, 1), dtype=np.float32)
        nxt, r, te, tr = env.step(a)
        rec.append((obs, a, np.asarray(r), ~done))
        done = done | te | tr
        obs = np.asarray(nxt, dtype=np.float32)
    o, a, r, m = (np.stack(x, axis=1) for x in zip(*rec))
    return Episodes(o * m[..., None], a, r * m, m, m.sum(1), np.zeros(n, dtype=bool))
''',
"mode_coverage": '''
def mode_coverage(sides, expert_sides):
    """A constant."""
    if len(sides) == 0 or len(expert_sides) == 0:
        raise ValueError("empty")
    return {"left": 0.5, "right": 0.5, "not_passed": 0.0, "coverage": 1.0}
''',
"mixture_nll": '''
def mixture_nll(logits, means, log_stds, targets):
    """A constant that keeps the graph."""
    return (logits * 0).sum() + (means * 0).sum() + (log_stds * 0).sum() + float(np.log(2 * np.pi))
''',
"flow_matching_loss": '''
def flow_matching_loss(velocity, obs, chunks, noise, t):
    """The velocity's mean square, without a target."""
    v = velocity(noise, t, obs)
    return (v ** 2).sum(dim=tuple(range(1, v.dim()))).mean()
''',
"euler_sample": '''
def euler_sample(velocity, obs, noise, n_steps):
    """Noise only."""
    return noise.clone()
''',
}

HW6 = {
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

TRIVIAL = {"hw0_setup": HW0, "hw1_imitation": HW1, "hw1b_multimodal": HW1B, "hw2_maxent_irl": HW2,
           "hw3_preferences": HW3, "hw4_rlhf_dpo": HW4, "hw5_lm_alignment": HW5, "hw6_group_rl": HW6}


def test_every_stub_has_a_trivial_answer_here():
    for assignment, answers in TRIVIAL.items():
        assert set(answers) == set(course.stub_names(assignment)), assignment


@pytest.mark.parametrize("assignment", sorted(TRIVIAL))
def test_trivial_answers_and_seed_search_earn_nothing(assignment, open_tmp):
    path = open_tmp / f"trivial_{assignment}.ipynb"
    nbformat.write(_with_stubs(assignment, TRIVIAL[assignment]), str(path))
    grader = Grader(assignment)
    try:
        result = grader.grade(path)
    finally:
        grader.close()
    assert result.has_score, result.error
    earned = {s.name: [t.name for t in s.tests if t.passed] for s in result.stubs if s.score > 0}
    assert not earned, f"trivial answers earned points on {assignment}: {earned}"


def _discounted(rewards, gamma):
    out, running = np.zeros_like(rewards), np.zeros(rewards.shape[0])
    for t in reversed(range(rewards.shape[1])):
        running = rewards[:, t] + gamma * running
        out[:, t] = running
    return out


def test_feedback_over_two_submissions_holds_no_hidden_expected_value(open_tmp):
    """Hidden inputs are the same at every submission (the rng is seeded by the test's name): a student who hands in
    zeros, then ones, and reads both feedbacks must find no expected entry of the hidden instances there."""
    wrong = {"zeros": "def discounted_returns(rewards, gamma):\n    return np.zeros(np.shape(rewards))\n",
             "ones": "def discounted_returns(rewards, gamma):\n    return np.ones(np.shape(rewards))\n"}
    messages = []
    grader = Grader("hw0_setup")
    try:
        for name, source in wrong.items():
            path = open_tmp / f"{name}.ipynb"
            nbformat.write(_with_stubs("hw0_setup", {"discounted_returns": source}), str(path))
            result = grader.grade(path)
            messages += [t.message for s in result.stubs if s.name == "discounted_returns" for t in s.tests]
    finally:
        grader.close()
    text = "\n".join(messages)
    assert "wrong" in text or "too" in text, "the feedback should still say what is wrong"
    hidden = []  # the suite's own instances, rebuilt here as the grader's rng fixture draws them
    rng = np.random.default_rng(zlib.crc32(b"test_random_batch_matches_reference"))
    hidden.append(_discounted(rng.normal(size=(5, 13)), 0.9))
    rng = np.random.default_rng(zlib.crc32(b"test_edge_discounts"))
    rewards = rng.normal(size=(2, 7))
    hidden += [_discounted(rewards, 0.0), _discounted(rewards, 1.0)]
    renderings = {r for want in hidden for v in want.ravel() if abs(v) > 1e-3
                  for r in [repr(float(v))] + [f"{v:.{d}g}" for d in range(3, 9)] if len(r.strip("-0.")) >= 3}
    leaked = sorted(r for r in renderings if r in text)
    assert not leaked, f"the feedback holds hidden expected values: {leaked[:5]}"
    assert "np." not in text, "plain numbers only (not np.float64(...))"
