"""hw6's given tools (rlcourse.group_rl) and its recorded benchmark."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from conftest import REPO
from rlcourse import group_rl as G
from rlcourse.lm import LMConfig, TinyLM


def test_completion_log_probs_is_the_masked_gather_of_log_softmax():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(3, 6, 5, generator=g, dtype=torch.float64)
    tokens = torch.randint(0, 5, (3, 6), generator=g)
    mask = torch.tensor([[1, 1, 1, 0, 0, 0], [0, 0, 1, 1, 1, 1], [0, 1, 0, 1, 0, 1]], dtype=torch.float64)
    out = G.completion_log_probs(logits, tokens, mask)
    logp = torch.log_softmax(logits, -1)
    for b in range(3):
        for t in range(6):
            want = float(logp[b, t - 1, tokens[b, t]]) if t > 0 and mask[b, t] else 0.0
            assert math.isclose(float(out[b, t]), want, abs_tol=1e-12)
    junk = logits.clone()
    junk[0, 3:] = 1e6                         # logits that only score masked tokens
    assert torch.allclose(G.completion_log_probs(junk, tokens, mask), out)


def test_reward_model_is_standardised_on_its_pairs():
    torch.manual_seed(0)
    body = TinyLM(LMConfig(vocab_size=11, context=8, n_layer=1, n_head=2, d_model=16))
    chosen = torch.randint(1, 11, (40, 8))
    rejected = torch.randint(1, 11, (40, 8))
    before = [p.detach().clone() for p in body.parameters()]
    rm = G.fit_reward_model(body, chosen, rejected, steps=3, seed=0, batch=8)
    s = G.proxy_score(rm, torch.cat([chosen, rejected]))
    assert s.shape == (80,) and abs(float(s.mean())) < 1e-4 and abs(float(s.std()) - 1) < 1e-4
    assert all(torch.equal(a, b) for a, b in zip(before, body.parameters()))      # the SFT model itself is left alone
    assert not any(torch.equal(a, b) for a, b in zip(body.parameters(), rm.body.parameters()) if a.numel() > 16)


def test_best_of_n_from_pool_limits_and_errors():
    rng = np.random.default_rng(0)
    select, value = rng.normal(size=(3, 10)), rng.normal(size=(3, 10))
    assert np.allclose(G.best_of_n_from_pool(select, value, 1), value.mean(1))
    assert np.allclose(G.best_of_n_from_pool(select, value, 10), value[np.arange(3), select.argmax(1)])
    with pytest.raises(ValueError, match="pool size"):
        G.best_of_n_from_pool(select, value, 11)


def test_fits_recover_coefficients_from_noisy_points_and_peaks_are_infinite_without_a_turn():
    rng = np.random.default_rng(1)
    d = np.linspace(0.2, 2.5, 40)
    a, b = G.fit_bon_law(d, G.bon_law(d, 0.6, 0.15) + rng.normal(scale=0.01, size=40))
    assert abs(a - 0.6) < 0.05 and abs(b - 0.15) < 0.05
    a, b = G.fit_rl_law(np.r_[0.0, d], np.r_[0.0, G.rl_law(d, 0.4, 0.2)])         # d = 0 is dropped
    assert np.allclose((a, b), (0.4, 0.2))
    assert G.bon_law_peak(0.5, -0.1) == math.inf and G.rl_law_peak(0.5, 0.0) == math.inf
    assert G.n_for_kl(0.0) == 1.0 and math.isclose(G.bon_kl_formula(G.n_for_kl(4.55)), 4.55, rel_tol=1e-9)


def test_exact_best_of_n_kl_is_below_the_formula_and_zero_for_one_atom():
    rng = np.random.default_rng(2)
    scores = rng.integers(0, 4, size=50).astype(float)
    for n in (2, 8, 64):
        assert G.best_of_n_kl(scores, n) <= G.bon_kl_formula(n) + 1e-12
    assert G.best_of_n_kl(np.ones(7), 16) == 0.0


def test_the_recorded_benchmark_has_gold_proxy_kl_and_wall_time_per_method_and_seed():
    path = REPO / "bench" / "results" / "hw6_group_rl.json"
    if not path.exists():
        pytest.skip("bench/results/hw6_group_rl.json not recorded yet: python bench/bench_hw6_group_rl.py")
    result = json.loads(path.read_text())
    methods = result["methods"]
    assert {"GRPO (gold)", "PPO (gold)", "GRPO (proxy)", "IPO beta=0.1", "KTO beta=0.1", "DPO beta=0.1"} <= set(methods)
    for method, seeds in methods.items():
        assert len(seeds) >= 3, f"{method}: {len(seeds)} seeds"
        for seed, row in seeds.items():
            assert set(row) == {"gold", "proxy", "kl", "wall_s"}, (method, seed)
            assert all(math.isfinite(v) for v in row.values()), (method, seed)
