"""A language model's log-probabilities of the completion tokens of sequences, computed by running it.

Given code of the LM assignments after hw5 (hw6's losses, hw7's fine-tuning and group RL, hw7b's DPO rounds).
It is a module of its own so that an assignment that needs only these imports no more of the library: what
the sandbox shows while an assignment is graded is the closure of its imports, and
:mod:`rlcourse.group_rl`'s other tools (best-of-``n`` from a pool, say) would answer a stub of a later
assignment (hw7's ``pass_at_k`` is best-of-``k`` with pass indicators as scores). Both functions take a model
and a prompt length, never logits and a mask, so neither is hw5's ``token_log_probs`` under another name.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from rlcourse.lm import TinyLM, completion_mask


def completion_log_probs(model: TinyLM, tokens: torch.Tensor, prompt_len: int) -> torch.Tensor:
    """``(B, T)`` log-probabilities under ``model`` of each completion token of ``tokens``, 0 elsewhere.

    ``tokens`` ``(B, T)`` are prompts of ``prompt_len >= 1`` tokens followed by completions padded with 0
    (as :func:`rlcourse.lm.generate` returns them). Entry ``[b, t]`` is the log-probability the model gives
    ``tokens[b, t]`` after ``tokens[b, :t]`` on the completion tokens (:func:`rlcourse.lm.completion_mask`)
    and exactly 0 on the prompt and the padding. Differentiable in the model's parameters. The model must
    be a :class:`~rlcourse.lm.TinyLM`: the helper runs it, and takes no logits.
    """
    if not isinstance(model, TinyLM):
        raise TypeError(f"completion_log_probs runs a TinyLM on the tokens; got {type(model).__name__}")
    if prompt_len < 1:
        raise ValueError(f"prompt_len = {prompt_len}: a completion follows a prompt of at least one token")
    scores = F.log_softmax(model(tokens)[:, :-1], dim=-1).gather(-1, tokens[:, 1:, None]).squeeze(-1)
    scores = F.pad(scores, (1, 0))
    return torch.where(completion_mask(tokens, prompt_len).bool(), scores, torch.zeros_like(scores))


def completion_log_prob_sums(model: TinyLM, tokens: torch.Tensor, prompt_len: int) -> torch.Tensor:
    """``(B,)`` log-probability of each sequence's completion given its prompt: :func:`completion_log_probs` summed."""
    return completion_log_probs(model, tokens, prompt_len).sum(dim=1)
