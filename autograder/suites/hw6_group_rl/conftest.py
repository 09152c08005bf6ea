"""Shared helpers of hw6's hidden suite: comparisons whose messages name the mistake, never the expected values."""
import numpy as np
import pytest

from autograder.suite import expect_close as check_close, tensor_scalar, tensor_values


NAN_HINT = "masked entries or a division by zero?"
scalar = tensor_scalar


def as_array(got, name: str) -> np.ndarray:
    return tensor_values(got, name, NAN_HINT)


def expect_close(got, want, name: str, rtol: float = 1e-6, atol: float = 1e-9, shape: tuple | None = None) -> None:
    check_close(got, want, name, rtol, atol, shape, NAN_HINT)


@pytest.fixture
def groups():
    """Random (B, G) rewards with distinct group means and spreads, B != G, float64."""
    def make(rng: np.random.Generator, b: int = 5, g: int = 6) -> np.ndarray:
        loc = rng.normal(scale=3.0, size=(b, 1))
        spread = rng.uniform(0.2, 3.0, size=(b, 1))
        return loc + spread * rng.normal(size=(b, g))
    return make
