"""A tiny decoder-only transformer for ``hw5_lm_alignment``, in plain torch.

The model reads right-padded token ids ``(B, T)`` and returns next-token logits ``(B, T, V)``:
``logits[:, t]`` is the distribution of ``tokens[:, t + 1]``. Attention is causal, so padding
after a sequence's ``<eos>`` never changes the logits of the tokens before it, and no attention
mask is needed. Positions are learned embeddings; the output layer shares the token embedding.

:class:`ScalarHeadLM` puts a linear head on the same body: one number per token, used as a
reward model (read at the last token) or as a value function (read at every token).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from rlcourse.checkpoint import load_model, save_model


@dataclass
class LMConfig:
    """Sizes of the transformer."""

    vocab_size: int = 169
    """Number of token ids (``len(rlcourse.reviews.VOCAB)``)."""
    context: int = 32
    """Longest sequence the model reads, in tokens."""
    n_layer: int = 3
    """Number of transformer blocks."""
    n_head: int = 4
    """Attention heads per block (``d_model`` must be a multiple)."""
    d_model: int = 96
    """Width of the residual stream."""
    dropout: float = 0.0
    """Dropout on attention weights and residual branches (0 for the course's runs)."""


class CausalSelfAttention(nn.Module):
    """Multi-head self-attention in which position ``t`` sees positions ``<= t`` only."""

    def __init__(self, cfg: LMConfig):
        super().__init__()
        assert cfg.d_model % cfg.n_head == 0, "d_model must be a multiple of n_head"
        self.n_head, self.dropout = cfg.n_head, cfg.dropout
        self.qkv = nn.Linear(cfg.d_model, 3 * cfg.d_model)
        self.proj = nn.Linear(cfg.d_model, cfg.d_model)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, t, d = x.shape
        q, k, v = self.qkv(x).split(d, dim=-1)                                   # each (B, T, D)
        q, k, v = (z.view(b, t, self.n_head, d // self.n_head).transpose(1, 2) for z in (q, k, v))  # (B, H, T, D/H)
        y = F.scaled_dot_product_attention(q, k, v, is_causal=True, dropout_p=self.dropout if self.training else 0.0)
        return self.proj(y.transpose(1, 2).reshape(b, t, d))


class Block(nn.Module):
    """Pre-norm transformer block: attention then a two-layer MLP, each on a residual branch."""

    def __init__(self, cfg: LMConfig):
        super().__init__()
        self.ln1, self.ln2 = nn.LayerNorm(cfg.d_model), nn.LayerNorm(cfg.d_model)
        self.attn = CausalSelfAttention(cfg)
        self.mlp = nn.Sequential(nn.Linear(cfg.d_model, 4 * cfg.d_model), nn.GELU(),
                                 nn.Linear(4 * cfg.d_model, cfg.d_model), nn.Dropout(cfg.dropout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.attn(self.ln1(x))
        return x + self.mlp(self.ln2(x))


class TinyLM(nn.Module):
    """Decoder-only language model: ``forward(tokens (B, T)) -> logits (B, T, V)``."""

    def __init__(self, cfg: LMConfig):
        super().__init__()
        self.cfg = cfg
        self.tok_emb = nn.Embedding(cfg.vocab_size, cfg.d_model)
        self.pos_emb = nn.Embedding(cfg.context, cfg.d_model)
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.n_layer))
        self.ln_f = nn.LayerNorm(cfg.d_model)
        self.apply(self._init)
        for name, p in self.named_parameters():   # scaled init of the residual projections (GPT-2)
            if name.endswith(("proj.weight", "mlp.2.weight")):
                nn.init.normal_(p, std=0.02 / math.sqrt(2 * cfg.n_layer))

    @staticmethod
    def _init(module: nn.Module) -> None:
        if isinstance(module, (nn.Linear, nn.Embedding)):
            nn.init.normal_(module.weight, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            nn.init.zeros_(module.bias)

    def hidden(self, tokens: torch.Tensor) -> torch.Tensor:
        """The final hidden states ``(B, T, D)`` of token ids ``(B, T)``, ``T <= context``."""
        t = tokens.shape[1]
        if t > self.cfg.context:
            raise ValueError(f"sequence of {t} tokens is longer than the model's context of {self.cfg.context}")
        x = self.tok_emb(tokens) + self.pos_emb(torch.arange(t, device=tokens.device))
        for block in self.blocks:
            x = block(x)
        return self.ln_f(x)

    def unembed(self, hidden: torch.Tensor) -> torch.Tensor:
        """Logits ``(B, T, V)`` from hidden states ``(B, T, D)`` (the output layer is the token embedding)."""
        return hidden @ self.tok_emb.weight.T

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Next-token logits ``(B, T, V)``: ``logits[:, t]`` scores ``tokens[:, t + 1]``."""
        return self.unembed(self.hidden(tokens))

    def n_params(self) -> int:
        return sum(p.numel() for p in self.parameters())


class ScalarHeadLM(nn.Module):
    """A transformer body with a linear head giving one number per token ``(B, T)``.

    As a reward model, read it at each sequence's last real token (:meth:`score`); as a value
    function, read it at every token.
    """

    def __init__(self, body: TinyLM):
        super().__init__()
        self.body = body
        self.head = nn.Linear(body.cfg.d_model, 1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        return self.head(self.body.hidden(tokens)).squeeze(-1)

    def score(self, tokens: torch.Tensor, pad_id: int = 0) -> torch.Tensor:
        """One score per sequence ``(B,)``: the head at the last non-padding token."""
        last = (tokens != pad_id).long().cumsum(1).argmax(1)          # index of the last non-pad token
        return self(tokens).gather(1, last[:, None]).squeeze(1)


@torch.no_grad()
def generate(model: TinyLM, prompts: torch.Tensor, max_new_tokens: int, temperature: float = 1.0,
             eos_id: int = 2, pad_id: int = 0, generator: torch.Generator | None = None) -> torch.Tensor:
    """Sample continuations of ``prompts`` ``(B, P)`` (no padding inside a prompt).

    Returns ``(B, P + max_new_tokens)`` ids: each row is its prompt, the sampled tokens up to
    and including the first ``<eos>``, then ``pad_id``. ``P + max_new_tokens`` must fit the
    context. No key-value cache: every step re-reads the whole prefix (cheap at this size).
    """
    was_training = model.training
    model.eval()
    tokens = prompts.clone()
    done = torch.zeros(prompts.shape[0], dtype=torch.bool, device=prompts.device)
    for _ in range(max_new_tokens):
        logits = model(tokens)[:, -1] / max(temperature, 1e-8)
        nxt = torch.multinomial(F.softmax(logits, dim=-1), 1, generator=generator).squeeze(1)
        nxt = torch.where(done, torch.full_like(nxt, pad_id), nxt)
        tokens = torch.cat([tokens, nxt[:, None]], dim=1)
        done |= nxt == eos_id
        if bool(done.all()):
            tokens = torch.cat([tokens, tokens.new_full((tokens.shape[0], prompts.shape[1] + max_new_tokens
                                                         - tokens.shape[1]), pad_id)], dim=1)
            break
    model.train(was_training)
    return tokens


def completion_mask(tokens: torch.Tensor, prompt_len: int, pad_id: int = 0) -> torch.Tensor:
    """``(B, T)`` float mask of the generated tokens: after the prompt, and not padding (``<eos>`` included)."""
    mask = (tokens != pad_id).float()
    mask[:, :prompt_len] = 0.0
    return mask


def save_lm(model: TinyLM, path: str | Path, **metadata: float | int | str) -> None:
    """Save a :class:`TinyLM` as a checkpoint (its :class:`LMConfig`, ``state_dict``, metadata), atomically."""
    save_model(model, path, asdict(model.cfg), **metadata)


def load_lm(path: str | Path) -> TinyLM:
    """A :class:`TinyLM` saved by :func:`save_lm`, in eval mode, with its ``.metadata``."""
    return load_model(path, lambda **config: TinyLM(LMConfig(**config)))


def load_sft() -> TinyLM:
    """The shipped SFT model ``datasets/lm/sft.pt``, checksum-verified, in eval mode."""
    from rlcourse import data

    return load_lm(data.verify("lm/sft.pt"))
