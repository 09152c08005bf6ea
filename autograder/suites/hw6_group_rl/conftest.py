"""Shared helpers of hw6's hidden suite: comparisons whose messages name the mistake, never the expected values."""
import numpy as np
import pytest
import torch


def as_array(got, name: str) -> np.ndarray:
    """The student's torch tensor as a float64 array, after checking it is a plain, finite tensor."""
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    out = got.detach().numpy().astype(np.float64)
    assert np.isfinite(out).all(), f"{name} contains NaN or inf (masked entries or a division by zero?)"
    return out


def expect_close(got, want, name: str, rtol: float = 1e-6, atol: float = 1e-9, shape: tuple | None = None) -> None:
    """``got`` (a torch tensor) matches ``want`` (a numpy array or float); the message names what differs.

    It says which entry is wrong, whether the sign agrees, and the size of the relative error, but never the
    expected value itself.
    """
    want = np.asarray(want, dtype=np.float64)
    g = as_array(got, name)
    expected_shape = want.shape if shape is None else shape
    assert g.shape == expected_shape, f"{name} has shape {tuple(g.shape)}, expected {tuple(expected_shape)}"
    wrong = ~np.isclose(g, want, rtol=rtol, atol=atol)
    if wrong.any():
        idx = tuple(int(i) for i in np.argwhere(wrong)[0]) if g.ndim else ()
        gv, wv = float(g[idx]), float(want[idx])
        where = f" at index {idx}" if idx else ""
        if np.sign(gv) != np.sign(wv) and abs(wv) > atol:
            why = "has the wrong sign"
        else:
            rel = abs(gv - wv) / max(abs(wv), atol)
            why = f"is {'too large' if abs(gv) > abs(wv) else 'too small'} (relative error about 1e{int(np.floor(np.log10(max(rel, 1e-300))))})"
        assert False, f"{name}{where} {why}; {int(wrong.sum())} of {wrong.size} entries are wrong"


def scalar(got, name: str = "the loss") -> float:
    """A 0-dim tensor's value."""
    assert type(got) is torch.Tensor and got.dim() == 0, \
        f"{name} should be a 0-dim torch tensor, got {type(got).__name__} of shape {tuple(getattr(got, 'shape', ()))}"
    value = float(got)
    assert np.isfinite(value), f"{name} is {value}"
    return value


@pytest.fixture
def groups():
    """Random (B, G) rewards with distinct group means and spreads, B != G, float64."""
    def make(rng: np.random.Generator, b: int = 5, g: int = 6) -> np.ndarray:
        loc = rng.normal(scale=3.0, size=(b, 1))
        spread = rng.uniform(0.2, 3.0, size=(b, 1))
        return loc + spread * rng.normal(size=(b, g))
    return make
