"""Shared helpers of hw7's hidden suite: the trusted checker, sequence builders and comparisons whose messages
name the mistake, never the expected values."""
import numpy as np
import pytest
import torch

from autograder.suite import expect_close as check_close, tensor_scalar, tensor_values

DIGIT0, EOS, BOS, PLUS, EQUALS, SEMI = 3, 2, 1, 13, 14, 15


def prompt(a: int, b: int) -> list[int]:
    return [BOS, *[DIGIT0 + int(c) for c in f"{a:03d}"], PLUS, *[DIGIT0 + int(c) for c in f"{b:03d}"], EQUALS]


def number_tokens(n: int) -> list[int]:
    return [DIGIT0 + int(c) for c in str(n)]


def rows(items, width: int = 15) -> torch.Tensor:
    """(B, width) int64 from [(a, b, completion tokens)], right-padded with 0."""
    out = torch.zeros(len(items), width, dtype=torch.long)
    for i, (a, b, comp) in enumerate(items):
        seq = (prompt(a, b) + list(comp))[:width]
        out[i, :len(seq)] = torch.tensor(seq)
    return out


def trusted_check(tokens: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """The grader's own checker, written from the contract (strings, not arithmetic on token ids)."""
    fmt, cor = [], []
    for row in tokens.tolist():
        a = int("".join(str(t - DIGIT0) for t in row[1:4]))
        b = int("".join(str(t - DIGIT0) for t in row[5:8]))
        comp = row[9:]
        if EOS not in comp:
            fmt.append(0.0); cor.append(0.0); continue
        ans = comp[:comp.index(EOS)]
        s = "".join(str(t - DIGIT0) if DIGIT0 <= t <= DIGIT0 + 9 else "?" for t in ans)
        ok = 1 <= len(s) <= 4 and s.isdigit() and (len(s) == 1 or s[0] != "0")
        fmt.append(float(ok))
        cor.append(float(ok and int(s) == a + b))
    return np.array(fmt), np.array(cor)


scalar = tensor_scalar


def as_array(got, name: str) -> np.ndarray:
    return tensor_values(got, name)


expect_close = check_close


@pytest.fixture
def random_answers():
    """Random prompts with completions: right answers, off-by-one digits, and the base model's habits."""
    def make(rng: np.random.Generator, n: int = 40, width: int = 15):
        items = []
        for _ in range(n):
            a, b = (int(v) for v in rng.integers(0, 1000, size=2))
            s = a + b
            kind = rng.integers(6)
            if kind == 0:
                comp = number_tokens(s) + [EOS]
            elif kind == 1:
                comp = number_tokens(s + int(rng.choice([-10, -1, 1, 100]))) + [EOS] if s > 100 else number_tokens(s + 1) + [EOS]
            elif kind == 2:
                comp = number_tokens(s) + [SEMI] + prompt(int(rng.integers(1000)), 5)[1:]
            elif kind == 3:
                comp = number_tokens(s) + [EOS] + list(rng.integers(0, 16, size=3))
            elif kind == 4:
                comp = [DIGIT0] + number_tokens(s) + [EOS]
            else:
                comp = list(rng.integers(3, 16, size=int(rng.integers(1, 6)))) + [EOS]
            items.append((a, b, [int(t) for t in comp]))
        return rows(items, width)
    return make


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
