"""Shared helpers of hw7b's hidden suite (run in the grader, like the tests): trusted tiny models and comparisons."""
import numpy as np
import torch

from rlcourse.lm import LMConfig, TinyLM

TINY = dict(vocab_size=13, context=8, n_layer=1, n_head=2, d_model=16)


def trusted_lm(seed: int) -> TinyLM:
    """The grader's own copy of the tiny model ``sandbox_helpers.tiny_lm(seed)`` builds."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return TinyLM(LMConfig(**TINY))


def as_float_tensor(got, name: str, shape: tuple) -> np.ndarray:
    """The student's value as a float64 array, after checking it is a finite torch tensor of ``shape``."""
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    assert tuple(got.shape) == tuple(shape), f"{name} has shape {tuple(got.shape)}, expected {tuple(shape)}"
    out = got.detach().double().numpy()
    assert np.isfinite(out).all(), f"{name} contains NaN or inf"
    return out


def same_rows(got, want, name: str) -> None:
    """``got`` is an integer tensor equal to ``want`` (both (N, T)); the message says which row differs."""
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    assert tuple(got.shape) == tuple(want.shape), f"{name} has shape {tuple(got.shape)}, expected {tuple(want.shape)}"
    rows = np.flatnonzero(~(got.long() == want.long()).all(1).numpy())
    assert len(rows) == 0, f"{name}: row {int(rows[0])} is not the pair the docstring's steps give ({len(rows)} rows differ)"
