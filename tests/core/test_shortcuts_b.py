"""Red-team shortcuts against hw4-hw7b's hidden suites, kept as regression cases.

Each shortcut is a submission a lazy student might write: a function that has some of the right properties (the
right sign, the right value at one point, a gradient consistent with its own value) without being the asked
computation. Graded by the real grader, each must earn nothing on the stub it fakes (or, for a near miss: right
values with part of the gradient detached, or one case the docstring names got wrong, lose the tests that check
it). The other way round, each allowed variant (another dtype, a loop for a vectorised form, torch ops in another
order, a rule that agrees with the docstring's on every input a checker gives) must earn full marks. One grading per
assignment for the shortcuts, one for the variants; each case says what it scored before its suite was fixed (the
commits that fixed them say on how many redraws, where the draw mattered).
"""
from __future__ import annotations

import pytest

from autograder.core.results import Reason
from conftest import graded_stubs

pytestmark = pytest.mark.slow  # a few gradings: make test-fast leaves it out

# assignment -> stub -> (source, the tests it must fail: "all", or the beginnings of their titles)
SHORTCUTS: dict[str, dict[str, tuple[str, object]]] = {
    "hw4_rlhf_dpo": {
        # the right log-likelihoods with the policy's mean detached: only log_std would train [5/5 before]
        "sequence_log_prob": ('''
import math

def sequence_log_prob(policy, obs, actions):
    """Right values; the mean detached."""
    z = (actions - policy(obs).detach()) / policy.log_std.exp()
    return (-0.5 * z ** 2 - policy.log_std - 0.5 * math.log(2 * math.pi)).sum(-1).sum(-1)
''', ["The gradient of the summed log-likelihood"]),
    },
    "hw5_lm_alignment": {
        # a linear "loss" of the margin: its gradient agrees with its own finite differences and has the right
        # signs, and at margin -1000 it is 1000 like DPO's [3/6 before: the gradient and direction tests]
        "dpo_loss": ('''
def dpo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """-beta * mean margin: no log-sigmoid."""
    return -(beta * ((pi_chosen - ref_chosen) - (pi_rejected - ref_rejected))).mean()
''', "all"),
        # a hinge loss ranks pairs like Bradley-Terry and is 500 on gaps of +-1000 [2/5 before]
        "reward_model_loss": ('''
def reward_model_loss(chosen_scores, rejected_scores):
    """A hinge on the score gap: not Bradley-Terry."""
    return torch.relu(rejected_scores - chosen_scores).mean()
''', "all"),
        # rolled logits put the last position's prediction in column 0; the ragged masks never had mask[:, 0] = 1
        # [6/6 before]
        "token_log_probs": ('''
def token_log_probs(logits, tokens, mask):
    """Rolled logits instead of a shift: column 0 scored by the last position where mask[:, 0] is 1."""
    lp = F.log_softmax(logits, -1).roll(1, dims=1).gather(-1, tokens[..., None]).squeeze(-1)
    return torch.where(mask.bool(), lp, torch.zeros_like(lp))
''', ["Random logits and ragged masks"]),
        # right values, no gradient: a detached sequence log-probability [3/3 before], a value term whose values
        # are detached [8/8 before] (a reward-model loss with its rejected side detached, 5/5 before and 4/5 now,
        # is not kept here: the hinge above holds that stub's place in this grading)
        "sequence_log_prob": ('''
def sequence_log_prob(logits, tokens, mask):
    """Right values, detached from the logits."""
    return token_log_probs(logits.detach(), tokens, mask).sum(-1)
''', ["Appending padded columns"]),
        "ppo_token_loss": ('''
def ppo_token_loss(logp, logp_old, advantages, values, returns, mask, clip_eps=0.2, value_coef=0.5):
    """Right value; the value head gets no gradient."""
    mask = mask.float()
    ratio = torch.exp(logp - logp_old)
    pt = torch.maximum(-ratio * advantages, -ratio.clamp(1 - clip_eps, 1 + clip_eps) * advantages)
    return ((pt + value_coef * (values.detach() - returns) ** 2) * mask).sum() / mask.sum()
''', ["Zero advantages: the loss is value_coef"]),
    },
    "hw6_group_rl": {
        # the square of the mean margin's distance to the target: zero at the target and (1/(2 beta))^2 at the
        # reference, like IPO [1/5 before: the target-margin test]
        "ipo_loss": ('''
def ipo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """(mean h - 1/(2 beta))^2, not the mean of the squares."""
    h = (pi_chosen - ref_chosen) - (pi_rejected - ref_rejected)
    return (h.mean() - 1 / (2 * beta)) ** 2
''', "all"),
        # each reward minus the next one of its group: an unbiased, zero-sum baseline, not leave-one-out [2/5
        # before: the unbiasedness test]
        "rloo_advantages": ('''
def rloo_advantages(rewards):
    """r_i - r_(i+1) within the group."""
    return rewards - rewards.roll(-1, dims=1)
''', "all"),
        # each kind averaged apart, then the two means averaged: equal to the asked mean over completions whenever a
        # draw has as many desirable as undesirable completions (a quarter of the draws, and a resubmission redraws
        # them: up to 3/6 in twelve redraws before), never now
        "kto_loss": ('''
def kto_loss(pi, ref, desirable, kl_ref, beta, w_desirable=1.0, w_undesirable=1.0):
    """The mean of the per-kind means."""
    z0 = torch.as_tensor(kl_ref, dtype=pi.dtype).detach()
    r, d = pi - ref, desirable.bool()
    ld = (w_desirable * (1 - torch.sigmoid(beta * (r[d] - z0)))).mean()
    lu = (w_undesirable * (1 - torch.sigmoid(beta * (z0 - r[~d])))).mean()
    return (ld + lu) / 2
''', "all"),
    },
    "hw7_verifier_rl": {
        # the argument check and nothing else: k out of range raises, everything else is 0 [1/7 before: the test that
        # k = 4 with n = [10, 4] does not raise looked at no value]
        "pass_at_k": ('''
def pass_at_k(n, c, k):
    """Only the argument check; zeros otherwise."""
    n = np.asarray(n)
    if not 1 <= k <= n.min():
        raise ValueError("k must be between 1 and n")
    return np.zeros(np.broadcast(n, np.asarray(c)).shape)
''', "all"),
        # the raw reward as the advantage, whatever the kind: plain REINFORCE is unbiased too [1/7 before: the
        # unbiasedness test]
        "binary_group_advantages": ('''
def binary_group_advantages(k, group, kind="grpo", eps=1e-4):
    """1 for a pass, 0 for a fail: no baseline."""
    if group < 2 or kind not in ("grpo", "dr_grpo", "rloo"):
        raise ValueError("bad group or kind")
    out = torch.zeros(len(k), 2, dtype=torch.float64)
    out[:, 0] = 1.0
    return out
''', "all"),
        # a mean per row, then over rows: equal to the token mean when every row keeps as many tokens (about one
        # draw in ten of the 3-row test before), never now
        "rft_loss": ('''
def rft_loss(logp, mask):
    """Per-row means, averaged."""
    keep = mask > 0
    return (-torch.where(keep, logp, torch.zeros_like(logp)).sum(1) / keep.sum(1)).mean()
''', "all"),
        # passing rows up to the cap, no duplicate check: a draw without a passing duplicate could not tell (3/4 on
        # two of four draws before); every draw has one now
        "rft_select": ('''
def rft_select(tokens, correct, group, max_per_prompt):
    """The first passing rows of each group, duplicates kept."""
    keep, ok = [], [bool(x) for x in torch.as_tensor(correct).tolist()]
    for g in range(len(tokens) // group):
        kept = 0
        for i in range(g * group, (g + 1) * group):
            if ok[i] and kept < max_per_prompt:
                keep.append(i)
                kept += 1
    return torch.as_tensor(keep, dtype=torch.int64)
''', "all"),
    },
}

VARIANTS: dict[str, dict[str, str]] = {
    "hw4_rlhf_dpo": {
        "compute_gae": '''
def compute_gae(rewards, values, dones, last_value, gamma, lam):
    """float64 numpy backwards, returned as float64 tensors."""
    r, v, d = (x.double().numpy() for x in (rewards, values, dones))
    nv = np.vstack([v[1:], last_value.double().numpy()[None]])
    delta = r + gamma * (1 - d) * nv - v
    adv, running = np.zeros_like(r), np.zeros(r.shape[1])
    for t in range(len(r) - 1, -1, -1):
        running = delta[t] + gamma * lam * (1 - d[t]) * running
        adv[t] = running
    adv = torch.as_tensor(adv)
    return adv, adv + values.double()
''',
        "ppo_loss": '''
def ppo_loss(new_log_prob, old_log_prob, advantages, new_values, returns, entropy, kl_to_ref, clip_coef=0.2,
             vf_coef=0.5, ent_coef=0.0, kl_coef=0.0):
    """The clip by the advantage's sign, in float32."""
    f = lambda x: x.float()
    log_ratio = f(new_log_prob) - f(old_log_prob)
    ratio, a = torch.exp(log_ratio), f(advantages)
    pg = torch.where(a >= 0, torch.minimum(ratio, torch.tensor(1 + clip_coef)) * a,
                     torch.maximum(ratio, torch.tensor(1 - clip_coef)) * a)
    policy_loss, value_loss = -pg.mean(), ((f(new_values) - f(returns)) ** 2).mean() / 2
    ent, kl = f(entropy).mean(), f(kl_to_ref).mean()
    loss = policy_loss + vf_coef * value_loss - ent_coef * ent + kl_coef * kl
    clipped = ((ratio > 1 + clip_coef) | (ratio < 1 - clip_coef)).float().mean()
    return loss, {"policy_loss": policy_loss.detach(), "value_loss": value_loss.detach(), "entropy": ent.detach(),
                  "kl_ref": kl.detach(), "approx_kl": (ratio - 1 - log_ratio).mean().detach(), "clip_frac": clipped}
''',
        "LearnedRewardWrapper": '''
class LearnedRewardWrapper(gym.vector.VectorWrapper):
    """float32 learned rewards, observations copied, info updated in place."""
    def __init__(self, env, reward_fn, mean=0.0, std=1.0, offset=0.0):
        super().__init__(env)
        self.fn, self.m, self.s, self.o = reward_fn, mean, std, offset
    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.last = np.array(obs, copy=True)
        return obs, info
    def step(self, actions):
        r = ((np.asarray(self.fn(self.last, actions)) - self.m) / self.s + self.o).astype(np.float32)
        obs, reward, terminated, truncated, info = self.env.step(actions)
        info["true_reward"] = reward
        self.last = np.array(obs, copy=True)
        return obs, r, terminated, truncated, info
''',
        "sequence_log_prob": '''
import math

def sequence_log_prob(policy, obs, actions):
    """The Gaussian log-density by hand from the policy's mean and log_std."""
    z = (actions - policy(obs)) / policy.log_std.exp()
    return (-0.5 * z ** 2 - policy.log_std - 0.5 * math.log(2 * math.pi)).sum(-1).sum(-1)
''',
        "dpo_loss": '''
def dpo_loss(policy, reference, chosen, rejected, beta):
    """The reference detached instead of no_grad, softplus, metrics under no_grad."""
    lc = sequence_log_prob(policy, *chosen) - sequence_log_prob(reference, *chosen).detach()
    lr = sequence_log_prob(policy, *rejected) - sequence_log_prob(reference, *rejected).detach()
    m = beta * lc - beta * lr
    with torch.no_grad():
        info = dict(margin=m.mean(), accuracy=(m > 0).double().mean(), chosen_reward=(beta * lc).mean(),
                    rejected_reward=(beta * lr).mean())
    return F.softplus(-m).mean(), info
''',
    },
    "hw5_lm_alignment": {
        "token_log_probs": '''
def token_log_probs(logits, tokens, mask):
    """cross_entropy without reduction, column 0 zeroed by hand."""
    lp = -F.cross_entropy(logits[:, :-1].transpose(1, 2), tokens[:, 1:], reduction="none")
    m = mask.to(lp.dtype).clone()
    m[:, 0] = 0
    out = torch.cat([torch.zeros_like(lp[:, :1]), lp], 1)
    return torch.where(m > 0, out, torch.zeros_like(out))
''',
        "sequence_log_prob": '''
def sequence_log_prob(logits, tokens, mask):
    """A loop over the batch with boolean indexing."""
    rows = []
    for b in range(len(tokens)):
        lp = torch.log_softmax(logits[b, :-1], -1)[torch.arange(tokens.shape[1] - 1), tokens[b, 1:]]
        rows.append(lp[mask[b, 1:].bool()].sum())
    return torch.stack(rows)
''',
        "reward_model_loss": '''
def reward_model_loss(chosen_scores, rejected_scores):
    """Binary cross-entropy with logits on the gap."""
    d = chosen_scores - rejected_scores
    return F.binary_cross_entropy_with_logits(d, torch.ones_like(d))
''',
        "best_of_n": '''
def best_of_n(generate, reward_model, prompts, n):
    """Tiled copies (the prompts repeat as a block), reshaped the same way."""
    b = prompts.shape[0]
    c = generate(prompts.repeat(n, 1))
    s = torch.as_tensor(reward_model(c)).reshape(n, b)
    return c.reshape(n, b, -1)[s.argmax(0), torch.arange(b)]
''',
        "kl_penalised_rewards": '''
def kl_penalised_rewards(score, logp, logp_ref, mask, beta):
    """scatter_add at the last masked index, found with cumsum."""
    m = mask.to(logp.dtype)
    out = -beta * (logp - logp_ref) * m
    last = (m.cumsum(1) * m).argmax(1)
    return out.scatter_add(1, last[:, None], score[:, None].to(out.dtype))
''',
        "ppo_token_loss": '''
def ppo_token_loss(logp, logp_old, advantages, values, returns, mask, clip_eps=0.2, value_coef=0.5):
    """-min(...) and torch.where masked means."""
    keep = mask.bool()
    ratio = torch.exp(logp - logp_old)
    pol = -torch.min(ratio * advantages, torch.clamp(ratio, 1 - clip_eps, 1 + clip_eps) * advantages)
    z, n = torch.zeros_like(pol), keep.sum()
    return torch.where(keep, pol, z).sum() / n + value_coef * torch.where(keep, (values - returns) ** 2, z).sum() / n
''',
        "dpo_loss": '''
def dpo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """softplus of the negated margin, terms regrouped."""
    return F.softplus(-beta * ((pi_chosen - pi_rejected) - (ref_chosen - ref_rejected))).mean()
''',
    },
    "hw6_group_rl": {
        "group_advantages": '''
def group_advantages(rewards, scale=True, eps=1e-4):
    """Bessel's std written out."""
    g = rewards.shape[1]
    c = rewards - rewards.sum(1, keepdim=True) / g
    if scale:
        c = c / (torch.sqrt((c ** 2).sum(1, keepdim=True) / (g - 1)) + eps)
    return c
''',
        "rloo_advantages": '''
def rloo_advantages(rewards):
    """G / (G - 1) times the group-mean advantage (the same thing)."""
    g = rewards.shape[1]
    return g / (g - 1) * (rewards - rewards.mean(1, keepdim=True))
''',
        "grpo_token_loss": '''
def grpo_token_loss(logp, logp_old, logp_ref, advantages, mask, clip_eps=0.2, beta=0.04, length_norm=True):
    """Row by row with boolean indexing, in float32 (the docstring fixes no dtype) [9/11 on 4 of 8 redraws before:
    the k3 gradient compared at rtol 1e-6]."""
    logp, logp_old, logp_ref, advantages = (x.float() for x in (logp, logp_old, logp_ref, advantages))
    rows, total = [], 0.0
    for b in range(logp.shape[0]):
        k = mask[b].bool()
        lp, lo, lr = logp[b][k], logp_old[b][k], logp_ref[b][k]
        ratio = torch.exp(lp - lo)
        a = advantages[b]
        surrogate = torch.max(-ratio * a, -torch.clamp(ratio, 1 - clip_eps, 1 + clip_eps) * a)
        per_token = surrogate + beta * (torch.exp(lr - lp) - (lr - lp) - 1)
        rows.append(per_token.mean())
        total = total + per_token.sum()
    return torch.stack(rows).mean() if length_norm else total / (mask.shape[0] * mask.shape[1])
''',
        "ipo_loss": '''
def ipo_loss(pi_chosen, pi_rejected, ref_chosen, ref_rejected, beta):
    """pow and mean, the margin regrouped, in float32 (the docstring fixes no dtype) [3/5 before: the gradient
    test compared at rtol 1e-6]."""
    h = (pi_chosen.float() - pi_rejected.float()) - (ref_chosen.float() - ref_rejected.float())
    return (h - 0.5 / beta).pow(2).mean()
''',
        "kto_loss": '''
def kto_loss(pi, ref, desirable, kl_ref, beta, w_desirable=1.0, w_undesirable=1.0):
    """z0 as a float, the two kinds summed apart, in float32 [4/6 on a redraw before: rtol 1e-6]."""
    z0, r, d = float(kl_ref), pi.float() - ref.float(), desirable.bool()
    loss_d = w_desirable * (1 - torch.sigmoid(beta * (r[d] - z0)))
    loss_u = w_undesirable * (1 - torch.sigmoid(beta * (z0 - r[~d])))
    return (loss_d.sum() + loss_u.sum()) / len(r)
''',
    },
    "hw7_verifier_rl": {
        "verifier_reward": '''
def verifier_reward(tokens):
    """Vectorised: the first <eos> by argmax, digit masks."""
    B = tokens.shape[0]
    d = tokens - 3
    a = d[:, 1] * 100 + d[:, 2] * 10 + d[:, 3]
    b = d[:, 5] * 100 + d[:, 6] * 10 + d[:, 7]
    comp = tokens[:, 9:]
    is_eos = comp == 2
    has = is_eos.any(1)
    n = torch.where(has, is_eos.float().argmax(1), torch.full((B,), comp.shape[1]))
    before = torch.arange(comp.shape[1])[None] < n[:, None]
    digit = (comp >= 3) & (comp <= 12)
    ok = has & (n >= 1) & (n <= 4) & (digit | ~before).all(1) & ((comp[:, 0] != 3) | (n == 1))
    val = torch.zeros(B, dtype=torch.long)
    for j in range(min(4, comp.shape[1])):
        val = torch.where(before[:, j], val * 10 + (comp[:, j] - 3).clamp(0, 9), val)
    return ok.float(), (ok & (val == a + b)).float()
''',
        "pass_at_k": '''
def pass_at_k(n, c, k):
    """-expm1 of a sum of log1p terms, one problem at a time."""
    n, c = np.broadcast_arrays(np.asarray(n), np.asarray(c))
    if not 1 <= k <= n.min():
        raise ValueError("k must be between 1 and every n")
    flat = [1.0 if ni - ci < k else -np.expm1(np.log1p(-k / np.arange(ni - ci + 1, ni + 1)).sum())
            for ni, ci in zip(n.ravel(), c.ravel())]
    return np.array(flat, dtype=np.float64).reshape(n.shape)
''',
        "rft_loss": '''
def rft_loss(logp, mask):
    """Boolean indexing, in float32 (the docstring fixes no dtype)."""
    return -logp.float()[mask > 0].mean()
''',
        "rft_select": '''
def rft_select(tokens, correct, group, max_per_prompt):
    """Skips every row seen before in its group, passing or not: the docstring's rule whenever identical rows get the
    same verdict, as a checker's do [4/4 on 8 of 10 draws before, when verdicts were drawn row by row]."""
    keep, ok = [], [bool(x) for x in torch.as_tensor(correct).tolist()]
    for g in range(len(tokens) // group):
        seen, kept = set(), 0
        for i in range(g * group, (g + 1) * group):
            key = tuple(tokens[i].tolist())
            if key in seen:
                continue
            seen.add(key)
            if ok[i] and kept < max_per_prompt:
                keep.append(i)
                kept += 1
    return torch.as_tensor(keep, dtype=torch.int64)
''',
        "binary_group_advantages": '''
def binary_group_advantages(k, group, kind="grpo", eps=1e-4):
    """The group's rewards written out row by row with torch.ones / torch.zeros (float32), the table cast to float64
    at the end [1/7 before: tables compared at rtol 1e-9]."""
    if group < 2 or kind not in ("grpo", "dr_grpo", "rloo"):
        raise ValueError("bad group or kind")
    out = torch.zeros(len(k), 2)
    for i, kk in enumerate(torch.as_tensor(k).tolist()):
        if kk in (0, group):
            continue
        r = torch.cat([torch.ones(kk), torch.zeros(group - kk)])
        if kind == "grpo":
            a = (r - r.mean()) / (r.std() + eps)
        elif kind == "dr_grpo":
            a = r - r.mean()
        else:
            a = r - (r.sum() - r) / (group - 1)
        out[i] = torch.stack([a[0], a[-1]])
    return out.double()
''',
    },
    "hw7b_ai_feedback": {
        "online_dpo_round": '''
def online_dpo_round(policy, ref, prompts, annotator, optimizer, beta, generator, sampler=None):
    """zero_grad first, the pairs gathered by index, the margin regrouped, softplus."""
    optimizer.zero_grad()
    p = prompts.shape[1]
    src = sampler if sampler is not None else policy
    toks = generate(src, prompts.repeat_interleave(2, dim=0), src.cfg.context - p, generator=generator)
    a, b = toks[0::2], toks[1::2]
    v = torch.as_tensor(annotator(a, b)).double()
    aw, bw = v > 0.5, v < 0.5
    order = torch.argsort(torch.cat([torch.nonzero(aw)[:, 0], torch.nonzero(bw)[:, 0]]))
    chosen, rejected = torch.cat([a[aw], b[bw]])[order], torch.cat([b[aw], a[bw]])[order]
    if len(chosen) == 0:
        return {"loss": float("nan"), "chosen": chosen, "rejected": rejected}
    ref_diff = (completion_log_prob_sums(ref, chosen, p) - completion_log_prob_sums(ref, rejected, p)).detach()
    pol_diff = completion_log_prob_sums(policy, chosen, p) - completion_log_prob_sums(policy, rejected, p)
    loss = F.softplus(-beta * (pol_diff - ref_diff)).mean()
    loss.backward()
    optimizer.step()
    return {"loss": loss.item(), "chosen": chosen, "rejected": rejected}
''',
        "rule_critic": '''
def rule_critic(rules, a, b, weights=None):
    """Votes as differences of comparisons, the weights as torch.tensor(weights) (float32) [3/5 before: verdicts
    compared at rtol 1e-9]."""
    w = torch.ones(len(rules)) if weights is None else torch.tensor(weights)
    votes = torch.stack([(r(a) > r(b)).double() - (r(a) < r(b)).double() for r in rules], dim=1)
    return 0.5 + 0.5 * (votes * w).sum(1) / w.sum()
''',
        "position_swap": '''
def position_swap(judge, a, b):
    """The swapped order asked first; consistency as a product of signs."""
    ba = torch.as_tensor(judge(b, a)).double()
    ab = torch.as_tensor(judge(a, b)).double()
    return 0.5 * (ab - ba) + 0.5, ((ab - 0.5) * (ba - 0.5)) < 0
''',
    },
}




@pytest.mark.parametrize("assignment", sorted(SHORTCUTS), scope="module")  # grouped by assignment: one grader each
def test_shortcuts_lose_their_points(assignment, open_tmp):
    cases = SHORTCUTS[assignment]
    stubs = graded_stubs(assignment, {name: source for name, (source, _) in cases.items()}, open_tmp / "shortcuts.ipynb")
    for name, (_, must_fail) in cases.items():
        passed = [t.name for t in stubs[name].tests if t.passed]
        assert any(t.reason == Reason.WRONG for t in stubs[name].tests), \
            f"{assignment}: the shortcut for {name} did not run to a wrong answer (a typo in the case?)"
        if must_fail == "all":
            assert not passed, f"{assignment}: the shortcut for {name} passed {passed}"
        else:
            titles = [t.name for t in stubs[name].tests]
            for start in must_fail:
                assert any(t.startswith(start) for t in titles), f"{assignment}: no test of {name} is titled {start!r}"
                assert not any(t.startswith(start) for t in passed), \
                    f"{assignment}: the near miss for {name} passed {start!r}"


@pytest.mark.parametrize("assignment", sorted(VARIANTS), scope="module")
def test_allowed_variants_earn_full_marks(assignment, open_tmp):
    stubs = graded_stubs(assignment, VARIANTS[assignment], open_tmp / "variants.ipynb")
    for name in VARIANTS[assignment]:
        failed = {t.name: t.message for t in stubs[name].tests if not t.passed}
        assert not failed, f"{assignment}: an allowed variant of {name} lost {failed}"
