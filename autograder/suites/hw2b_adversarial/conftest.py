"""Shared helpers of hw2b's hidden suite: comparisons whose messages name the mistake, never the expected values."""
import numpy as np
import torch


def as_array(got, name: str) -> np.ndarray:
    """The student's torch tensor as a float64 array, after checking it is a plain, finite tensor."""
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    out = got.detach().numpy().astype(np.float64)
    assert np.isfinite(out).all(), f"{name} contains NaN or inf (log of a sigmoid that underflowed, or exp that overflowed?)"
    return out


def expect_close(got, want, name: str, rtol: float = 1e-7, atol: float = 1e-10) -> None:
    """``got`` (a torch tensor) matches ``want`` in shape and values; the message says which entry is wrong,
    whether its sign agrees and how large the relative error is, never the expected value."""
    want = np.asarray(want, dtype=np.float64)
    g = as_array(got, name)
    assert g.shape == want.shape, f"{name} has shape {tuple(g.shape)}, expected {tuple(want.shape)}"
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


def softplus(x) -> np.ndarray:
    """log(1 + exp(x)), stable."""
    return np.logaddexp(0.0, np.asarray(x, dtype=np.float64))


def sigmoid(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return np.exp(-softplus(-x))


def raised(call, *args, **kwargs) -> str:
    """The type name of the exception the submission's code raised in ``call`` (a call into the sandbox), or
    "no error"; any other failure (a timeout, a lost worker, a grader fault) is not caught."""
    try:
        call(*args, **kwargs)
    except Exception as error:  # noqa: BLE001 - only the submission's own errors carry a `kind`
        if not isinstance(getattr(error, "kind", None), str):
            raise
        return error.kind
    return "no error"
