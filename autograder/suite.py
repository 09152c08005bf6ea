"""What hidden suites import: the ``stub`` marker and strict comparisons.

Comparisons fail with messages written for the student, since those messages
are the feedback. They are strict on purpose: the type must be exactly right
(an ``ndarray`` subclass or an object that claims equality with everything is
not an array), shapes and dtype kinds must match, and NaN or inf never pass.

A message says what is wrong (the type, the shape, which entry, the student's own
value there, a flipped sign, and how far off to an order of magnitude) but never
the hidden expected value, nor the difference it could be recovered from: the
hidden inputs are the same at every submission, and students may resubmit.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
import pytest

_REAL_TYPES = (int, float, np.integer, np.floating)


def stub(name: str, points: float, hint: str | None = None) -> Callable:
    """Mark a test as checking stub ``name`` and worth ``points``; ``hint`` is shown when it fails."""
    return pytest.mark.stub(name=name, points=points, hint=hint)


def lend(obj: Any, methods: Sequence[str], attrs: Sequence[str] = ()) -> Any:
    """Pass ``obj`` to student code without letting it in: the object stays in the grader.

    In the sandbox, student code sees a stand-in with only the named ``methods`` (each call runs
    here, on plain data, and its answer goes back) and ``attrs`` (plain values copied now). Use it
    for an environment whose hidden parameters a stub must learn through its interface (a dueling
    bandit's preference matrix), so that no attribute or memory of the sandbox holds the answer.
    """
    from autograder.core.session import Lend

    return Lend(obj, tuple(methods), tuple(attrs))


def describe(value: Any) -> str:
    """A short description of a value for feedback messages."""
    if isinstance(value, np.ndarray):
        return f"{type(value).__name__} of shape {value.shape} and dtype {value.dtype}"
    text = repr(value)
    return f"{type(value).__name__} {text[:60]}{'…' if len(text) > 60 else ''}"


def _fail(message: str) -> None:
    raise AssertionError(message)


def number(x: Any) -> str:
    """A number as a person writes it: ``3``, ``0.25``, ``-1.5e-07``, ``(1+2j)``; never ``np.float64(0.25)``."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (complex, np.complexfloating)):
        return f"({complex(x).real:.4g}{complex(x).imag:+.4g}j)"
    return f"{float(x):.4g}"


def how_far(got: complex, want: complex) -> str:
    """How a wrong value differs from the right one, without the right one: the sign, and the size of the
    error relative to the right value's size, to an order of magnitude."""
    got, want = complex(got), complex(want)
    if got.imag == 0 and want.imag == 0 and got.real * want.real < 0:
        return "it has the wrong sign"
    if want == 0:
        return "it should be zero"
    if got == 0:
        return "it is zero, and should not be"
    ratio = abs(got) / abs(want)
    if ratio >= 1.5 or ratio <= 1 / 1.5:
        decades = abs(np.log10(ratio))
        size = "about twice" if decades < 0.5 else f"about 10^{round(decades)} times"
        return f"it is {size} too {'large' if ratio > 1 else 'small'}"
    relative = abs(got - want) / abs(want)
    return f"it is off by about 10^{round(np.log10(relative))} of its size"


def check_array(got: Any, want: Any, rtol: float = 1e-6, atol: float = 1e-8, name: str = "the result") -> None:
    """``got`` is a plain numpy array like ``want``: same shape, dtype kind, finite where ``want`` is, close."""
    want = np.asarray(want)
    if type(got) is not np.ndarray:
        _fail(f"{name} should be a numpy array, got {describe(got)}")
    if got.shape != want.shape:
        _fail(f"{name} has shape {got.shape}, expected {want.shape}")
    kinds = {"f": "floating-point", "i": "integer", "u": "unsigned integer", "b": "boolean", "c": "complex"}
    same_kind = got.dtype.kind == want.dtype.kind or {got.dtype.kind, want.dtype.kind} <= {"i", "u"}
    if not same_kind:
        _fail(f"{name} has dtype {got.dtype}; expected {kinds.get(want.dtype.kind, want.dtype.kind)} values")
    if got.dtype.kind in "fc":
        bad = ~np.isfinite(got) & np.isfinite(want)
        if bad.any():
            index = tuple(int(i) for i in np.argwhere(bad)[0])
            _fail(f"{name} contains NaN or inf at {int(bad.sum())} position(s), e.g. index {index}")
    if got.dtype.kind == "b" or want.dtype.kind == "b":
        wrong = got != want
    else:
        wrong = ~np.isclose(got, want, rtol=rtol, atol=atol, equal_nan=True)
    if wrong.any():
        index = tuple(int(i) for i in np.argwhere(wrong)[0]) if got.ndim else ()
        where = f"at index {index}" if got.ndim else ""
        if got.dtype.kind == "b" or want.dtype.kind == "b":
            detail = f"{where} it is {number(got[index])}"
        else:
            detail = f"{where} it is {number(got[index])}: {how_far(got[index], want[index])}"
        _fail(f"{name} is wrong at {int(wrong.sum())} of {wrong.size} position(s); e.g. {detail.strip()}")


def check_scalar(got: Any, want: float, rtol: float = 1e-6, atol: float = 1e-8, name: str = "the result") -> None:
    """``got`` is one finite real number (Python or numpy, not bool, not an array) close to ``want``."""
    if isinstance(got, bool) or not isinstance(got, _REAL_TYPES) or type(got).__module__ not in ("builtins", "numpy"):
        _fail(f"{name} should be a number, got {describe(got)}")
    value = float(got)
    if not np.isfinite(value):
        _fail(f"{name} is {value}, expected a finite number")
    if not np.isclose(value, float(want), rtol=rtol, atol=atol):
        _fail(f"{name} is {number(value)}: {how_far(value, float(want))}")


def check_tensor(got: Any, want: Any, rtol: float = 1e-5, atol: float = 1e-7, name: str = "the result") -> None:
    """``got`` is a torch tensor (not a subclass) matching ``want`` as :func:`check_array` would."""
    import torch

    if type(got) is not torch.Tensor:
        _fail(f"{name} should be a torch tensor, got {describe(got)}")
    want_np = want.detach().numpy() if isinstance(want, torch.Tensor) else np.asarray(want)
    check_array(got.detach().numpy(), want_np, rtol, atol, name)


def tensor_values(got: Any, name: str, nan_hint: str = "a division by zero?") -> np.ndarray:
    """The student's torch tensor (not a subclass) as a float64 array, after checking it is finite; ``nan_hint``
    says, in the message, where a NaN most likely came from."""
    import torch

    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    out = got.detach().numpy().astype(np.float64)
    assert np.isfinite(out).all(), f"{name} contains NaN or inf ({nan_hint})"
    return out


def expect_close(got: Any, want: Any, name: str, rtol: float = 1e-6, atol: float = 1e-9, shape: tuple | None = None,
                 nan_hint: str = "a division by zero?") -> None:
    """``got`` (a torch tensor) matches ``want`` (a numpy array or float) in shape (``shape``, if given) and values.

    The message says which entry is wrong, whether the sign agrees, and the size of the relative error, but never
    the expected value itself.
    """
    want = np.asarray(want, dtype=np.float64)
    g = tensor_values(got, name, nan_hint)
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
            why = (f"is {'too large' if abs(gv) > abs(wv) else 'too small'} "
                   f"(relative error about 1e{int(np.floor(np.log10(max(rel, 1e-300))))})")
        raise AssertionError(f"{name}{where} {why}; {int(wrong.sum())} of {wrong.size} entries are wrong")


def tensor_scalar(got: Any, name: str = "the loss") -> float:
    """A 0-dim torch tensor's finite value."""
    import torch

    assert type(got) is torch.Tensor and got.dim() == 0, \
        f"{name} should be a 0-dim torch tensor, got {type(got).__name__} of shape {tuple(getattr(got, 'shape', ()))}"
    value = float(got)
    assert np.isfinite(value), f"{name} is {value}"
    return value
