"""hw6's given tools (rlcourse.group_rl) and its recorded benchmark."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from conftest import REPO
from rlcourse import group_rl as G
from rlcourse import group_training as GT
from rlcourse import lm_training as L
from rlcourse.lm import LMConfig, TinyLM


def _tiny_lm(seed: int = 0) -> TinyLM:
    torch.manual_seed(seed)
    return TinyLM(LMConfig(vocab_size=11, context=8, n_layer=1, n_head=2, d_model=16))


def test_completion_log_probs_runs_the_model_and_scores_only_completion_tokens():
    model = _tiny_lm()
    tokens = torch.tensor([[5, 6, 7, 3, 2, 0, 0, 0], [4, 4, 9, 8, 1, 6, 2, 0], [7, 3, 2, 0, 0, 0, 0, 0]])
    out = G.completion_log_probs(model, tokens, prompt_len=2)
    with torch.no_grad():
        logp = torch.log_softmax(model(tokens), -1)
    for b in range(3):
        for t in range(8):
            want = float(logp[b, t - 1, tokens[b, t]]) if t >= 2 and tokens[b, t] != 0 else 0.0
            assert math.isclose(float(out[b, t].detach()), want, rel_tol=1e-6, abs_tol=1e-7), (b, t)
    assert torch.allclose(G.completion_log_prob_sums(model, tokens, 2), out.sum(1))
    out.sum().backward()                                             # differentiable in the model's parameters
    assert model.tok_emb.weight.grad is not None and float(model.tok_emb.weight.grad.abs().sum()) > 0


def test_completion_log_probs_takes_a_model_not_logits():
    """The helper's contract is not hw5's ``token_log_probs(logits, tokens, mask)``: it refuses logits."""
    tokens = torch.tensor([[5, 6, 7, 2]])
    with pytest.raises(TypeError, match="TinyLM"):
        G.completion_log_probs(torch.zeros(1, 4, 11), tokens, 1)
    with pytest.raises(TypeError, match="TinyLM"):
        G.completion_log_probs(lambda x: torch.zeros(1, 4, 11), tokens, 1)
    with pytest.raises(ValueError, match="prompt_len"):
        G.completion_log_probs(_tiny_lm(), tokens, 0)


def test_the_script_fits_a_reward_model_standardised_on_its_pairs():
    import sys

    sys.path.insert(0, str(REPO / "datasets" / "scripts"))
    from make_hw6_models import fit_reward_model

    body = _tiny_lm()
    chosen = torch.randint(1, 11, (40, 8))
    rejected = torch.randint(1, 11, (40, 8))
    before = [p.detach().clone() for p in body.parameters()]
    rm = fit_reward_model(body, chosen, rejected, steps=3, seed=0, batch=8)
    s = G.proxy_score(rm, torch.cat([chosen, rejected]))
    assert s.shape == (80,) and abs(float(s.mean())) < 1e-4 and abs(float(s.std()) - 1) < 1e-4
    assert all(torch.equal(a, b) for a, b in zip(before, body.parameters()))      # the SFT model itself is left alone
    assert not any(torch.equal(a, b) for a, b in zip(body.parameters(), rm.body.parameters()) if a.numel() > 16)


def test_the_shipped_models_load_and_the_reward_model_beats_chance_on_held_out_pairs():
    from rlcourse import reviews as R

    rm, dpo = G.load_reward_model(), G.load_dpo_policy()
    assert rm.metadata["test_accuracy"] > 0.6 and dpo.metadata["beta"] == 0.1 and dpo.metadata["steps"] == 90
    prefs = R.load_preferences()
    test = np.flatnonzero(prefs["test"])[:200]
    c, r = torch.as_tensor(prefs["chosen"][test]), torch.as_tensor(prefs["rejected"][test])
    accuracy = float((G.proxy_score(rm, c) > G.proxy_score(rm, r)).float().mean())
    assert accuracy > 0.6, accuracy


def test_hw6s_release_carries_no_bradley_terry_or_dpo_loss():
    """hw5's ``reward_model_loss`` and ``dpo_loss`` are a log-sigmoid of a difference: no hw6 release file computes one
    (the given loops of ``rlcourse.lm_training`` take the losses as arguments)."""
    import nbformat

    nb = nbformat.read(REPO / "assignments" / "hw6_group_rl" / "hw6_group_rl.ipynb", as_version=4)
    texts = {f"rlcourse/{name}": (REPO / "rlcourse" / name).read_text() for name in ("group_rl.py", "lm_training.py")}
    texts.update({f"cell {i}": c.source for i, c in enumerate(nb.cells) if c.cell_type == "code"})
    for where, text in texts.items():
        assert "logsigmoid" not in text and "log_sigmoid" not in text, where


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


@pytest.mark.slow
def test_the_notebook_with_the_shipped_models_is_the_benchmarks_seed_0():
    """SFT's and DPO's rows, and the first iterations of GRPO's curves, equal seed 0 of the recorded benchmark."""
    import sys

    from rlcourse import reviews as R
    from rlcourse.lm import load_sft

    path = REPO / "bench" / "results" / "hw6_group_rl.json"
    if not path.exists():
        pytest.skip("bench/results/hw6_group_rl.json not recorded yet: python bench/bench_hw6_group_rl.py")
    seed0 = json.loads(path.read_text())["seeds"]["0"]["methods"]
    sys.path.insert(0, str(REPO / "bench"))
    from bench_hw6_group_rl import HW6, solution_namespace

    torch.set_num_threads(1)
    ns = solution_namespace(HW6)
    ns["seed_everything"](0)
    sft, prefs, rm = load_sft(), R.load_preferences(), G.load_reward_model()
    eval_prompts = torch.as_tensor(prefs["eval_prompts"])[:64]
    proxy_fn = lambda s: G.proxy_score(rm, s)  # noqa: E731
    for name, policy in (("SFT", sft), ("DPO beta=0.1", G.load_dpo_policy())):
        e = L.evaluate(policy, sft, proxy_fn, eval_prompts, 0, log_prob_sums=G.completion_log_prob_sums)
        assert all(math.isclose(e[k], seed0[name][k], abs_tol=1e-5) for k in ("gold", "proxy", "kl")), (name, e)
    prompts = torch.as_tensor(prefs["chosen"])[np.flatnonzero(~prefs["test"])[:3000], :prefs["prompt_len"]]
    for name, reward_fn in (("GRPO (gold)", L.gold_fn), ("GRPO (proxy)", proxy_fn)):
        _, log = GT.critic_free_train(sft, reward_fn, prompts, ns["group_advantages"], ns["grpo_token_loss"], iters=2,
                                     n_prompts=8, group=8, seed=0, beta=0.0, proxy_fn=proxy_fn)
        for k in ("gold", "proxy", "kl"):
            assert np.allclose(log[k], seed0[name]["curve"][k][:2], atol=1e-6), (name, k, log[k])
