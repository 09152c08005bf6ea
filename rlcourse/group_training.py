"""hw6's given training loops: critic-free RL and the offline pairwise and KTO updates; hw6's functions come in
as arguments, as hw5's do in :mod:`rlcourse.lm_training`.

* :func:`critic_free_train` (an advantage function and ``grpo_token_loss``: GRPO, Dr. GRPO, RLOO);
* :func:`pairwise_train` (any loss of a batch of pairs: IPO, DPO);
* :func:`kto_train` (``kto_loss``).

They score completions with :func:`rlcourse.group_rl.completion_log_probs`, which is hw5's ``token_log_probs``
run on a model; they live apart from hw5's loops so that grading hw5 never puts that helper in the sandbox.
Sequences are right-padded token ids ``(B, T)``, as in :mod:`rlcourse.lm_training`.
"""
from __future__ import annotations

import copy
import time
from typing import Callable, Optional

import numpy as np
import torch

from rlcourse import reviews as R
from rlcourse.group_rl import completion_log_prob_sums, completion_log_probs
from rlcourse.lm import TinyLM, completion_mask, generate
from rlcourse.lm_training import Scores, gold_fn


def critic_free_train(sft: TinyLM, reward_fn: Scores, prompts: torch.Tensor, advantage_fn: Callable,
                      grpo_token_loss: Callable, *, iters: int, n_prompts: int, group: int, seed: int,
                      length_norm: bool = True, beta: float = 0.0, lr: float = 2e-4, epochs: int = 2,
                      clip_eps: float = 0.2, proxy_fn: Optional[Scores] = None) -> tuple[TinyLM, dict[str, np.ndarray]]:
    """Critic-free RL (GRPO, Dr. GRPO, RLOO) from ``sft`` on ``reward_fn``: ``n_prompts * group`` samples an iteration.

    Each iteration draws ``n_prompts`` prompts, samples ``group`` completions of each, turns the rewards,
    shaped ``(n_prompts, group)``, into advantages with ``advantage_fn`` (one per sequence), and takes ``epochs``
    AdamW steps on ``grpo_token_loss(logp, logp_old, logp_ref, adv, mask, clip_eps, beta, length_norm)``. No
    value network. Returns the policy (eval mode) and a log per iteration: the batch's mean ``reward``, ``gold``
    reward, ``proxy`` reward (``proxy_fn``; NaN without one), ``kl`` from ``sft`` (sampled), the fraction of
    groups whose rewards were all equal (``equal_groups``: they teach nothing) and the ``seconds`` so far.
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    policy = copy.deepcopy(sft).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    log = {k: [] for k in ("reward", "gold", "proxy", "kl", "equal_groups", "seconds")}
    p, t0 = prompts.shape[1], time.perf_counter()
    for _ in range(iters):
        x = prompts[torch.randint(len(prompts), (n_prompts,), generator=gen)].repeat_interleave(group, dim=0)
        tokens = generate(policy, x, R.MAX_LEN - p, generator=gen)
        mask = completion_mask(tokens, p)
        with torch.no_grad():
            logp_old = completion_log_probs(policy, tokens, p)
            logp_ref = completion_log_probs(sft, tokens, p)
            rewards = torch.as_tensor(reward_fn(tokens), dtype=torch.float32).reshape(n_prompts, group)
            adv = advantage_fn(rewards).reshape(-1)
        for _ in range(epochs):
            logp = completion_log_probs(policy, tokens, p)
            loss = grpo_token_loss(logp, logp_old, logp_ref, adv, mask, clip_eps, beta, length_norm)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
            opt.step()
        log["reward"].append(float(rewards.mean()))
        log["gold"].append(float(gold_fn(tokens).mean()))
        log["proxy"].append(float(proxy_fn(tokens).mean()) if proxy_fn is not None else float("nan"))
        log["kl"].append(float(((logp_old - logp_ref) * mask).sum(1).mean()))
        log["equal_groups"].append(float((rewards.std(dim=1) == 0).float().mean()))
        log["seconds"].append(time.perf_counter() - t0)
    return policy.eval(), {k: np.array(v) for k, v in log.items()}


def pairwise_train(sft: TinyLM, chosen: torch.Tensor, rejected: torch.Tensor, prompt_len: int, loss_fn: Callable,
                   steps: int, seed: int, batch: int = 64, lr: float = 2e-4) -> TinyLM:
    """Offline preference optimisation from ``sft`` (also the reference): ``loss_fn(pi_c, pi_r, ref_c, ref_r)``.

    The arguments are ``(batch,)`` completion log-probabilities of the chosen and rejected rows under the
    policy (differentiable) and the reference (computed once). Returns the policy in eval mode.
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        ref_c = torch.cat([completion_log_prob_sums(sft, x, prompt_len) for x in chosen.split(512)])
        ref_r = torch.cat([completion_log_prob_sums(sft, x, prompt_len) for x in rejected.split(512)])
    policy = copy.deepcopy(sft).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    for _ in range(steps):
        i = torch.randint(len(chosen), (batch,), generator=gen)
        loss = loss_fn(completion_log_prob_sums(policy, chosen[i], prompt_len),
                       completion_log_prob_sums(policy, rejected[i], prompt_len), ref_c[i], ref_r[i])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
        opt.step()
    return policy.eval()


def kto_train(sft: TinyLM, tokens: torch.Tensor, desirable: torch.Tensor, prompt_len: int, kto_loss: Callable, *,
              beta: float, steps: int, seed: int, batch: int = 64, lr: float = 2e-4) -> TinyLM:
    """KTO from ``sft`` on single completions ``tokens`` ``(N, T)`` labelled ``desirable`` ``(N,)`` bool.

    Each step minimises ``kto_loss(pi, ref, desirable, z0, beta)`` on ``batch`` rows; the reference point
    ``z0`` is the batch's mean log-ratio to ``sft`` of mismatched sequences (prompt ``b`` with the completion
    of row ``b - 1``), clamped at 0 and computed without gradient. Returns the policy in eval mode.
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        ref = torch.cat([completion_log_prob_sums(sft, x, prompt_len) for x in tokens.split(512)])
    policy = copy.deepcopy(sft).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    for _ in range(steps):
        i = torch.randint(len(tokens), (batch,), generator=gen)
        x = tokens[i]
        mismatched = torch.cat([x[:, :prompt_len], x.roll(1, dims=0)[:, prompt_len:]], dim=1)
        with torch.no_grad():
            z0 = (completion_log_prob_sums(policy, mismatched, prompt_len)
                  - completion_log_prob_sums(sft, mismatched, prompt_len)).mean().clamp(min=0.0)
        loss = kto_loss(completion_log_prob_sums(policy, x, prompt_len), ref[i], desirable[i], z0, beta)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
        opt.step()
    return policy.eval()
