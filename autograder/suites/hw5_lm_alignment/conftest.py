"""Shared helpers of hw5's hidden suite."""
import numpy as np
import pytest
import torch


def _ragged_batch(rng: np.random.Generator, b: int = 4, t: int = 9, v: int = 11, scale: float = 2.0):
    """Random logits (B, T, V) float64, tokens (B, T) int64, and a prompt-then-completion mask with ragged ends."""
    logits = torch.as_tensor(rng.normal(scale=scale, size=(b, t, v)))
    tokens = torch.as_tensor(rng.integers(0, v, size=(b, t)))
    start = rng.integers(1, 4, size=b)
    end = np.minimum(start + rng.integers(1, t, size=b), t)
    end[0] = t                                             # one completion runs to the last column
    pos = np.arange(t)[None]
    mask = torch.as_tensor(((pos >= start[:, None]) & (pos < end[:, None])).astype(np.float64))
    return logits, tokens, mask


@pytest.fixture
def ragged_batch():
    """The batch maker above, for tests that need logits, tokens and a ragged completion mask."""
    return _ragged_batch
