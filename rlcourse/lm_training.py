"""The given training loops of hw5 (and what hw6 shares with it); the students' functions come in as arguments.

Each loop is the one its notebook used to define in a locked cell, moved here unchanged in what it computes:
the same seeds, the same order of random draws, the same updates. What a notebook asks its students to
write is never here but passed in (as :func:`rlcourse.ppo.ppo` takes hw4's ``compute_gae`` and ``ppo_loss``):

* hw5: :func:`fit_reward_model` (calls ``reward_model_loss``), :func:`ppo_train` (``token_log_probs``,
  ``kl_penalised_rewards``, ``ppo_token_loss``), :func:`dpo_train` (``sequence_log_prob``, ``dpo_loss``);
* hw5 and hw6: :func:`evaluate` (gold reward, proxy reward and the sampled KL of a policy's completions) and
  :func:`gold_fn` (the gold reward of :mod:`rlcourse.reviews` as a tensor).

hw6's loops are in :mod:`rlcourse.group_training`. This module never computes a completion's log-probabilities
itself (hw5's ``token_log_probs`` and ``sequence_log_prob`` are stubs), so it imports nothing that does: grading
hw5, the sandbox holds only the library modules hw5 needs.

Sequences are right-padded token ids ``(B, T)``: a prompt of ``P`` tokens, then a completion ending with
``<eos>`` or at ``T``. ``reward_fn`` and ``proxy_fn`` map such a batch to ``(B,)`` scores.
"""
from __future__ import annotations

import copy
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import reviews as R
from rlcourse.lm import ScalarHeadLM, TinyLM, completion_mask, generate

Scores = Callable[[torch.Tensor], torch.Tensor]
"""A function of a batch of sequences ``(B, T)`` returning one score per sequence ``(B,)``."""
LogProbSums = Callable[[TinyLM, torch.Tensor, int], torch.Tensor]
"""``(model, tokens (B, T), prompt_len) -> (B,)``: log-probability of each completion given its prompt."""


def gold_fn(tokens: torch.Tensor) -> torch.Tensor:
    """The gold reward of each sequence, a program: ``(B,)`` float32."""
    return torch.as_tensor(R.gold_reward(tokens.numpy()), dtype=torch.float32)


@torch.no_grad()
def evaluate(policy: TinyLM, ref: TinyLM, proxy_fn: Scores, prompts: torch.Tensor, seed: int,
             log_prob_sums: LogProbSums) -> dict:
    """Gold reward, proxy reward and ``KL(policy || ref)`` of one completion of each prompt, sampled at temperature 1.

    The KL is the Monte-Carlo estimate, the mean over samples of ``log pi(y|x) - log pi_ref(y|x)``
    (the k1 estimator: unbiased, but its sample mean can come out negative when the policies are close);
    ``kl_se`` is its standard error. ``tokens`` holds the samples ``(B, T)``.
    """
    tokens = generate(policy, prompts, R.MAX_LEN - prompts.shape[1], generator=torch.Generator().manual_seed(seed))
    p = prompts.shape[1]
    kl = log_prob_sums(policy, tokens, p) - log_prob_sums(ref, tokens, p)
    return {"gold": float(gold_fn(tokens).mean()), "proxy": float(proxy_fn(tokens).mean()),
            "kl": float(kl.mean()), "kl_se": float(kl.std() / np.sqrt(len(kl))) if len(kl) > 1 else float("nan"),
            "tokens": tokens}


# --------------------------------------------------------------------------- hw5
def fit_reward_model(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, reward_model_loss: Callable,
                       steps: int, seed: int, batch: int = 64, lr: float = 3e-4) -> ScalarHeadLM:
    """Fit a scalar-head copy of ``sft`` to preference pairs (row ``i`` of ``chosen`` beat row ``i`` of ``rejected``).

    ``reward_model_loss(chosen_scores (N,), rejected_scores (N,)) -> scalar`` is minimised with AdamW on
    ``steps`` batches of ``batch`` pairs. ``rm.shift`` and ``rm.scale`` of the returned model (in eval mode)
    are the mean and standard deviation of its raw scores on both halves of the pairs.
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    rm = ScalarHeadLM(copy.deepcopy(sft)).train()
    opt = torch.optim.AdamW(rm.parameters(), lr=lr, weight_decay=0.01)
    for _ in range(steps):
        idx = torch.randint(len(chosen), (batch,), generator=gen)
        loss = reward_model_loss(rm.score(chosen[idx]), rm.score(rejected[idx]))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    rm.eval()
    with torch.no_grad():
        raw = torch.cat([rm.score(x) for x in torch.cat([chosen, rejected]).split(512)])
    rm.shift, rm.scale = float(raw.mean()), float(raw.std())
    return rm


def gae(rewards: torch.Tensor, values: torch.Tensor, mask: torch.Tensor, lam: float = 0.95) -> torch.Tensor:
    """Generalised advantage estimates (gamma = 1) over the masked (contiguous) completion, shape ``(B, T)``.

    ``delta_t = r_t + V_{t+1} - V_t`` inside the completion (``V`` after the last token is 0), and
    ``A_t = sum_{k >= t} lam^(k - t) delta_k``, as one product with an upper-triangular matrix.
    """
    t = torch.arange(rewards.shape[1])
    deltas = (rewards + F.pad(values[:, 1:] * mask[:, 1:], (0, 1)) - values) * mask
    decay = torch.where(t[:, None] >= t[None, :], lam ** (t[:, None] - t[None, :]).clamp(min=0).float(), 0.0)
    return (deltas @ decay) * mask


def ppo_train(sft: TinyLM, reward_fn: Scores, prompts: torch.Tensor, token_log_probs: Callable,
              kl_penalised_rewards: Callable, ppo_token_loss: Callable, *, beta: float, iters: int, batch: int,
              seed: int, lr: float = 2e-4, epochs: int = 4, clip_eps: float = 0.2,
              value_coef: float = 0.1) -> tuple[TinyLM, dict[str, np.ndarray]]:
    """RLHF with PPO from ``sft`` on ``reward_fn`` with a per-token KL penalty of coefficient ``beta`` to ``sft``.

    Each iteration samples one completion of each of ``batch`` prompts drawn from ``prompts``, builds the
    rewards with ``kl_penalised_rewards(score, logp_old, logp_ref, mask, beta)``, the advantages with
    :func:`gae` (normalised over the batch's completion tokens) from a value head on the policy's body (read
    before each token), then takes ``epochs`` AdamW steps on ``ppo_token_loss(logp, logp_old, adv, values,
    returns, mask, clip_eps, value_coef)``; ``token_log_probs(logits, tokens, mask)`` scores the tokens.
    Returns the policy (eval mode) and a log, per iteration: the batch's mean ``reward`` (``reward_fn``),
    ``gold`` reward, ``kl`` from ``sft`` (sampled) and ``clipfrac`` (fraction of tokens outside the clip).
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    policy = copy.deepcopy(sft).train()
    value_head = torch.nn.Linear(sft.cfg.d_model, 1)
    torch.nn.init.zeros_(value_head.weight); torch.nn.init.zeros_(value_head.bias)
    opt = torch.optim.AdamW(list(policy.parameters()) + list(value_head.parameters()), lr=lr, weight_decay=0.0)

    def policy_and_values(tokens: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        hidden = policy.hidden(tokens)                                           # one forward pass for both
        values = F.pad(value_head(hidden).squeeze(-1)[:, :-1], (1, 0))           # V_t read before token t
        return token_log_probs(policy.unembed(hidden), tokens, mask), values

    log = {k: [] for k in ("reward", "gold", "kl", "clipfrac")}
    p = prompts.shape[1]
    for _ in range(iters):
        x = prompts[torch.randint(len(prompts), (batch,), generator=gen)]
        tokens = generate(policy, x, R.MAX_LEN - p, generator=gen)
        mask = completion_mask(tokens, p)
        with torch.no_grad():
            logp_old, values_old = policy_and_values(tokens, mask)
            logp_ref = token_log_probs(sft(tokens), tokens, mask)
            score = reward_fn(tokens)
            rewards = kl_penalised_rewards(score, logp_old, logp_ref, mask, beta)
            adv = gae(rewards, values_old, mask)
            returns = adv + values_old
            mean = adv.sum() / mask.sum()
            std = (((adv - mean) * mask) ** 2).sum().div(mask.sum()).sqrt()
            adv = (adv - mean) / (std + 1e-8) * mask
        for _ in range(epochs):
            logp, values = policy_and_values(tokens, mask)
            loss = ppo_token_loss(logp, logp_old, adv, values, returns, mask, clip_eps, value_coef)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
            opt.step()
        with torch.no_grad():
            clipped = ((torch.exp(logp - logp_old) - 1).abs() > clip_eps).float()
        log["reward"].append(float(score.mean()))
        log["gold"].append(float(gold_fn(tokens).mean()))
        log["kl"].append(float(((logp_old - logp_ref) * mask).sum(1).mean()))
        log["clipfrac"].append(float((clipped * mask).sum() / mask.sum()))
    return policy.eval(), {k: np.array(v) for k, v in log.items()}


def dpo_train(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, prompt_len: int, sequence_log_prob: Callable,
              dpo_loss: Callable, *, beta: float, steps: int, seed: int, batch: int = 64,
              lr: float = 2e-4) -> tuple[TinyLM, dict[str, np.ndarray]]:
    """DPO from ``sft`` (also the frozen reference) on preference pairs; it never samples from the policy.

    The reference's ``sequence_log_prob(logits, tokens, mask)`` of every pair is computed once; each of the
    ``steps`` AdamW steps minimises ``dpo_loss(pi_c, pi_r, ref_c, ref_r, beta)`` on ``batch`` pairs. Returns
    the policy (eval mode) and a log per step: the ``loss`` and the implicit-reward ``accuracy`` (the fraction
    of the batch's pairs whose log-ratio to the reference is larger for the chosen completion).
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    mask_c, mask_r = completion_mask(chosen, prompt_len), completion_mask(rejected, prompt_len)
    with torch.no_grad():
        ref_c = torch.cat([sequence_log_prob(sft(x), x, m) for x, m in zip(chosen.split(512), mask_c.split(512))])
        ref_r = torch.cat([sequence_log_prob(sft(x), x, m) for x, m in zip(rejected.split(512), mask_r.split(512))])
    policy = copy.deepcopy(sft).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    log = {"loss": [], "accuracy": []}
    for _ in range(steps):
        i = torch.randint(len(chosen), (batch,), generator=gen)
        pi_c = sequence_log_prob(policy(chosen[i]), chosen[i], mask_c[i])
        pi_r = sequence_log_prob(policy(rejected[i]), rejected[i], mask_r[i])
        loss = dpo_loss(pi_c, pi_r, ref_c[i], ref_r[i], beta)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
        opt.step()
        log["loss"].append(loss.item())
        log["accuracy"].append(float(((pi_c - ref_c[i]) > (pi_r - ref_r[i])).float().mean()))
    return policy.eval(), {k: np.array(v) for k, v in log.items()}
