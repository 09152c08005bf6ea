"""Shared helpers of hw7's hidden suite: the trusted checker, sequence builders and comparisons whose messages
name the mistake, never the expected values."""
import numpy as np
import pytest
import torch

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


def as_array(got, name: str) -> np.ndarray:
    """The student's torch tensor as a float64 array, after checking it is a plain, finite tensor."""
    assert type(got) is torch.Tensor, f"{name} should be a torch tensor, got {type(got).__name__}"
    out = got.detach().numpy().astype(np.float64)
    assert np.isfinite(out).all(), f"{name} contains NaN or inf (a division by zero?)"
    return out


def expect_close(got, want, name: str, rtol: float = 1e-6, atol: float = 1e-9, shape: tuple | None = None) -> None:
    """``got`` (a torch tensor) matches ``want``; the message says which entry differs and how, not the value."""
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
    assert type(got) is torch.Tensor and got.dim() == 0, \
        f"{name} should be a 0-dim torch tensor, got {type(got).__name__} of shape {tuple(getattr(got, 'shape', ()))}"
    value = float(got)
    assert np.isfinite(value), f"{name} is {value}"
    return value


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
