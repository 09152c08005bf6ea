"""Given tools of ``hw7_verifier_rl``: a task with an exact checker, and the loops that learn from it.

**The task.** Add two three-digit numbers. A prompt is ``<bos> a a a + b b b =`` (each operand written with
exactly three digits, leading zeros kept), nine tokens; a well-formed answer is the sum in decimal, most
significant digit first, with no leading zero (``0`` alone for zero), then ``<eos>``. Writing the sum most
significant digit first is hard for a small transformer: the first digit depends on every carry below it.

**The base model** (``datasets/hw7/base.pt``) was pretrained by ``datasets/scripts/make_hw7_models.py`` on a
"web" of such equations: documents of one or two equations, two joined by ``;``, each document ending with
``<eos>``, and one answer in ten altered in one digit (the web has typos). Asked a question, it writes an
answer and then, half the time, ``;`` and another equation instead of stopping: a format failure.

What students write (the checker's reward, pass@k, rejection sampling's filter and loss, the binary group
advantages) lives in the notebook; this module gives the vocabulary, the problems, the worked examples for
SFT, and loops that take the students' functions as arguments:

- :func:`finetune` (maximum likelihood on completions, the loss passed in: SFT and each round of RFT);
- :func:`sample` and :func:`pass_counts` (``n`` samples of each prompt, the number correct);
- :func:`expert_iteration` (sample, filter, fine-tune, repeat);
- :func:`group_rl` (GRPO, Dr. GRPO, RLOO: one on-policy policy-gradient step per batch of groups).

Sequences are right-padded token ids ``(B, T)``: a prompt of :data:`PROMPT_LEN` tokens, then a completion
of at most :data:`MAX_NEW` tokens ending with ``<eos>`` (or not, when the model never stops).
"""
from __future__ import annotations

import copy
import time
from typing import Callable, Optional

import numpy as np
import torch

from rlcourse.completions import completion_log_probs
from rlcourse.lm import LMConfig, TinyLM, completion_mask, generate, load_lm

PAD, BOS, EOS, PLUS, EQUALS, SEMI = 0, 1, 2, 13, 14, 15
DIGIT0 = 3
"""Token id of the digit ``0``; digit ``d`` is ``DIGIT0 + d``."""
VOCAB = ["<pad>", "<bos>", "<eos>", *"0123456789", "+", "=", ";"]
PROMPT_LEN = 9
"""``<bos>``, three digits, ``+``, three digits, ``=``."""
MAX_NEW = 6
"""Tokens a model may write after the prompt (the longest well-formed answer, ``1998<eos>``, has five)."""
CONTEXT = 32
BASE_FILE = "hw7/base.pt"


def config() -> LMConfig:
    """The base model's sizes (vocabulary of 16 tokens, context of 32)."""
    return LMConfig(vocab_size=len(VOCAB), context=CONTEXT, n_layer=2, n_head=4, d_model=64)


def load_base() -> TinyLM:
    """The shipped base model ``datasets/hw7/base.pt``, checksum-verified, in eval mode; ``.metadata`` says how."""
    from rlcourse import data

    return load_lm(data.verify(BASE_FILE))


def digits(n: int) -> list[int]:
    """Token ids of ``n >= 0`` in decimal, no leading zero."""
    return [DIGIT0 + int(ch) for ch in str(int(n))]


def decode(tokens) -> str:
    """Readable text of token ids (padding dropped)."""
    return "".join(VOCAB[int(t)] if int(t) not in (BOS, EOS) else ("" if int(t) == BOS else "$")
                   for t in tokens if int(t) != PAD)


def problems(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` problems ``(a, b)``, each uniform on 0..999, from ``seed``: two int64 arrays."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, 1000, size=n), rng.integers(0, 1000, size=n)


def prompts(a: np.ndarray, b: np.ndarray) -> torch.Tensor:
    """Prompt tokens ``(n, PROMPT_LEN)`` of the problems ``a + b``."""
    rows = [[BOS, *[DIGIT0 + int(c) for c in f"{x:03d}"], PLUS, *[DIGIT0 + int(c) for c in f"{y:03d}"], EQUALS]
            for x, y in zip(np.asarray(a), np.asarray(b))]
    return torch.tensor(rows, dtype=torch.long).reshape(-1, PROMPT_LEN)


def worked_examples(a: np.ndarray, b: np.ndarray) -> torch.Tensor:
    """Prompt, correct answer and ``<eos>`` of each problem, right-padded to ``PROMPT_LEN + MAX_NEW``: the SFT data."""
    out = torch.zeros(len(a), PROMPT_LEN + MAX_NEW, dtype=torch.long)
    out[:, :PROMPT_LEN] = prompts(a, b)
    for i, (x, y) in enumerate(zip(np.asarray(a), np.asarray(b))):
        ans = digits(int(x) + int(y)) + [EOS]
        out[i, PROMPT_LEN:PROMPT_LEN + len(ans)] = torch.tensor(ans)
    return out


def web_documents(n: int, seed: int, typo: float = 0.1, two: float = 0.5) -> torch.Tensor:
    """The pretraining "web": ``n`` documents ``(n, CONTEXT)`` of one equation, or two joined by ``;``
    (probability ``two``), each ending with ``<eos>``; an answer has one digit altered with probability ``typo``."""
    rng = np.random.default_rng(seed)
    out = torch.zeros(n, CONTEXT, dtype=torch.long)
    for i in range(n):
        row = [BOS]
        for j in range(2 if rng.random() < two else 1):
            x, y = (int(v) for v in rng.integers(0, 1000, size=2))
            ans = digits(x + y)
            if rng.random() < typo:
                k = int(rng.integers(len(ans)))
                ans[k] = DIGIT0 + (ans[k] - DIGIT0 + int(rng.integers(1, 10))) % 10
            row += ([SEMI] if j else []) + prompts([x], [y])[0, 1:].tolist() + ans
        row.append(EOS)
        out[i, :len(row)] = torch.tensor(row)
    return out


# --------------------------------------------------------------------------- loops
LossFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
"""``(logp (B, T), mask (B, T)) -> scalar``: a likelihood loss on the completion tokens."""
RewardFn = Callable[[torch.Tensor], torch.Tensor]
"""``tokens (B, T) -> (B,)`` float rewards of sequences (prompt of ``PROMPT_LEN`` tokens, then the completion)."""


def finetune(model: TinyLM, tokens: torch.Tensor, loss_fn: LossFn, *, steps: int, seed: int, batch: int = 64,
             lr: float = 1e-3) -> TinyLM:
    """A fine-tuned copy of ``model``: ``steps`` AdamW steps of ``loss_fn(logp, mask)`` on batches of ``tokens``.

    ``logp`` holds the model's log-probabilities of the completion tokens of the batch (0 on the prompt and
    the padding, :func:`rlcourse.completions.completion_log_probs`) and ``mask`` marks them. ``model`` is left
    alone; the copy is returned in eval mode.
    """
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    policy = copy.deepcopy(model).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    for _ in range(steps):
        x = tokens[torch.randint(len(tokens), (min(batch, len(tokens)),), generator=gen)]
        loss = loss_fn(completion_log_probs(policy, x, PROMPT_LEN), completion_mask(x, PROMPT_LEN))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
        opt.step()
    return policy.eval()


@torch.no_grad()
def sample(model: TinyLM, prompt_tokens: torch.Tensor, n: int, seed: int, temperature: float = 1.0,
           chunk: int = 4096) -> torch.Tensor:
    """``n`` completions of each prompt, rows ``i * n .. i * n + n - 1`` for prompt ``i``: ``(B * n, PROMPT_LEN + MAX_NEW)``."""
    gen = torch.Generator().manual_seed(seed)
    x = prompt_tokens.repeat_interleave(n, dim=0)
    return torch.cat([generate(model, part, MAX_NEW, temperature=temperature, generator=gen)
                      for part in x.split(chunk)])


def completion_lengths(tokens: torch.Tensor) -> torch.Tensor:
    """Number of tokens each row wrote after the prompt (``<eos>`` included), ``(B,)``."""
    return completion_mask(tokens, PROMPT_LEN).sum(1)


@torch.no_grad()
def pass_counts(model: TinyLM, prompt_tokens: torch.Tensor, n: int, reward_fn: RewardFn, seed: int) -> dict:
    """``n`` samples of each prompt at temperature 1, scored by ``reward_fn`` (1 = correct).

    Returns ``c`` ``(B,)`` int, the number correct per prompt; ``n``; ``length``, the mean completion length
    in tokens; and ``tokens``, the samples.
    """
    tokens = sample(model, prompt_tokens, n, seed)
    r = torch.as_tensor(reward_fn(tokens)).float().reshape(len(prompt_tokens), n)
    return {"c": (r > 0.5).sum(1).numpy().astype(int), "n": n,
            "length": float(completion_lengths(tokens).float().mean()), "tokens": tokens}


def expert_iteration(model: TinyLM, prompt_tokens: torch.Tensor, reward_fn: RewardFn, select_fn: Callable,
                     loss_fn: LossFn, *, rounds: int, n_prompts: int, group: int, max_per_prompt: int,
                     steps: int, seed: int, batch: int = 64, lr: float = 1e-3,
                     on_round: Optional[Callable] = None) -> tuple[TinyLM, dict[str, np.ndarray]]:
    """Rejection-sampling fine-tuning (expert iteration, STaR, RFT) from ``model``.

    Each round draws ``n_prompts`` prompts, samples ``group`` completions of each from the current policy,
    keeps the rows ``select_fn(tokens, correct, group, max_per_prompt)`` returns (indices into the samples),
    and fine-tunes the current policy on them with :func:`finetune` (``steps`` steps of ``loss_fn``). A round
    with nothing kept leaves the policy as it was. ``on_round(round, policy, samples_so_far)`` is called
    before the first round and after each. Returns the policy and a log per round: ``samples`` drawn so far,
    ``reward`` (fraction correct of the round's samples), ``kept`` rows, ``equal_groups`` and ``length``.
    """
    gen = torch.Generator().manual_seed(seed)
    policy = copy.deepcopy(model).eval()
    log = {k: [] for k in ("samples", "reward", "kept", "equal_groups", "length", "seconds")}
    drawn, t0 = 0, time.perf_counter()
    if on_round is not None:
        on_round(0, policy, 0)
    for r in range(rounds):
        idx = torch.randint(len(prompt_tokens), (n_prompts,), generator=gen)
        tokens = sample(policy, prompt_tokens[idx], group, seed=seed * 1000 + r)
        correct = torch.as_tensor(reward_fn(tokens)).float()
        drawn += len(tokens)
        keep = torch.as_tensor(select_fn(tokens, correct, group, max_per_prompt), dtype=torch.long)
        if len(keep):
            policy = finetune(policy, tokens[keep], loss_fn, steps=steps, seed=seed * 1000 + r, batch=batch, lr=lr)
        grouped = correct.reshape(n_prompts, group)
        log["samples"].append(drawn)
        log["reward"].append(float(correct.mean()))
        log["kept"].append(len(keep))
        log["equal_groups"].append(float((grouped.max(1).values == grouped.min(1).values).float().mean()))
        log["length"].append(float(completion_lengths(tokens).float().mean()))
        log["seconds"].append(time.perf_counter() - t0)
        if on_round is not None:
            on_round(r + 1, policy, drawn)
    return policy, {k: np.array(v) for k, v in log.items()}


def group_rl(model: TinyLM, prompt_tokens: torch.Tensor, reward_fn: RewardFn, advantage_fn: Callable, *,
             iters: int, n_prompts: int, group: int, seed: int, length_norm: bool, lr: float = 3e-4,
             eval_every: int = 0, on_eval: Optional[Callable] = None) -> tuple[TinyLM, dict[str, np.ndarray]]:
    """Critic-free RL on a pass/fail reward: GRPO (``length_norm=True``), Dr. GRPO and RLOO (``False``).

    Each iteration samples ``group`` completions of each of ``n_prompts`` prompts, counts the correct ones
    per group, ``k`` ``(n_prompts,)``, and gets from ``advantage_fn(k, group)`` an ``(n_prompts, 2)`` table: the
    advantage of a correct and of a wrong completion in each group. Each completion takes its row's entry,
    and one AdamW step (on-policy: the sampling policy is the current one, so no ratio or clipping is needed)
    minimises ``-sum_b A_b * w_b * sum_t log pi(y_bt)`` over the batch, with ``w_b = 1 / (B |y_b|)`` when
    ``length_norm`` (each sequence's tokens averaged, GRPO) and ``w_b = 1 / (B * MAX_NEW)`` otherwise (a constant:
    Dr. GRPO). No KL penalty. ``on_eval(iteration, policy, samples_so_far)`` is called before the first
    iteration and every ``eval_every``. Returns the policy (eval mode) and a log per iteration: ``samples``
    drawn so far, ``reward`` (fraction correct), ``equal_groups`` (fraction of groups all right or all wrong:
    their advantages are 0 and they teach nothing), ``length`` (mean completion tokens) and ``seconds``.
    """
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    policy = copy.deepcopy(model).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    log = {k: [] for k in ("samples", "reward", "equal_groups", "length", "seconds")}
    t0 = time.perf_counter()
    if on_eval is not None:
        on_eval(0, policy.eval(), 0)
    for it in range(iters):
        idx = torch.randint(len(prompt_tokens), (n_prompts,), generator=gen)
        tokens = sample(policy, prompt_tokens[idx], group, seed=seed * 100003 + it)
        correct = torch.as_tensor(reward_fn(tokens)).float().reshape(n_prompts, group) > 0.5
        k = correct.sum(1)
        table = torch.as_tensor(advantage_fn(k, group), dtype=torch.float32)
        adv = torch.where(correct, table[:, :1], table[:, 1:]).reshape(-1)
        mask = completion_mask(tokens, PROMPT_LEN)
        policy.train()
        logp = completion_log_probs(policy, tokens, PROMPT_LEN).sum(1)
        weight = 1.0 / (mask.sum(1).clamp(min=1.0) * len(tokens)) if length_norm else \
            torch.full((len(tokens),), 1.0 / (len(tokens) * MAX_NEW))
        loss = -(adv * weight * logp).sum()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
        opt.step()
        policy.eval()
        log["samples"].append((it + 1) * len(tokens))
        log["reward"].append(float(correct.float().mean()))
        log["equal_groups"].append(float(((k == 0) | (k == group)).float().mean()))
        log["length"].append(float(mask.sum(1).mean()))
        log["seconds"].append(time.perf_counter() - t0)
        if on_eval is not None and eval_every and (it + 1) % eval_every == 0:
            on_eval(it + 1, policy, (it + 1) * len(tokens))
    return policy.eval(), {k: np.array(v) for k, v in log.items()}
