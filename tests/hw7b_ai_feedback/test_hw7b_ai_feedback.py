"""hw7b's given tools (rlcourse.ai_feedback), its shipped models and its recorded benchmark."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from conftest import REPO
from rlcourse import ai_feedback as A
from rlcourse import reviews as R
from rlcourse.lm import LMConfig, TinyLM


def _reviews(texts):
    return torch.as_tensor(np.stack([np.pad(R.encode(["<bos>", *t.split()]), (0, 32 - len(t.split()) - 1))
                                     for t in texts]))


def test_review_length_counts_every_token_but_padding():
    x = _reviews(["this film was good . <eos>", "this film was"])
    assert A.review_length(x).tolist() == [7.0, 4.0]


def test_simulated_person_draws_bradley_terry_verdicts_on_the_gold_reward():
    good, bad = _reviews(["this film was great . <eos>"] * 4000), _reviews(["this film was dull . <eos>"] * 4000)
    gap = float(A.gold(good[:1]) - A.gold(bad[:1]))
    person = A.SimulatedPerson(seed=0)
    v = person(good, bad)
    assert set(np.unique(v.numpy())) <= {0.0, 1.0} and person.labels == 4000
    want = 1 / (1 + math.exp(-gap / A.PERSON_TEMPERATURE))
    assert abs(float(v.mean()) - want) < 4 * math.sqrt(want * (1 - want) / 4000) + 1e-9
    assert torch.equal(A.SimulatedPerson(seed=3)(good, bad), A.SimulatedPerson(seed=3)(good, bad))


def test_the_constitution_scores_the_gold_rewards_terms():
    x = _reviews(["this film was great . <eos>", "this film was great great . <eos>", "this film was film . <eos>",
                  "this film was great ."])
    scores = {text: f(x).numpy() for text, f in A.CONSTITUTION}
    finished, grammatical, repeats, praise = scores.values()
    assert finished.tolist() == [1, 1, 1, 0]
    assert repeats[1] < repeats[0] == 0
    assert grammatical[2] < grammatical[0] == 0
    assert praise[1] > praise[0] > 0


def _tiny_judge(seed=0, position=0.7, slope=0.0):
    from rlcourse.lm import ScalarHeadLM

    torch.manual_seed(seed)
    rm = ScalarHeadLM(TinyLM(LMConfig()))
    torch.nn.init.normal_(rm.head.weight, std=0.5)
    return A.Judge(rm.eval(), position, 0.0, 1.0, slope)


def test_judge_is_a_sigmoid_of_score_differences_plus_the_position_offset():
    j = _tiny_judge()
    a = torch.randint(4, 169, (10, 12))
    b = torch.randint(4, 169, (10, 12))
    d = j.raw(a) - j.raw(b)
    assert torch.allclose(j(a, b), torch.sigmoid(d + 0.7))
    assert torch.allclose(j(a, b) + j(b, a), torch.sigmoid(d + 0.7) + torch.sigmoid(-d + 0.7))
    assert float((j(a, a) - torch.sigmoid(torch.tensor(0.7, dtype=torch.float64))).abs().max()) < 1e-12


def test_length_control_removes_the_judges_length_slope_on_the_samples_it_is_fitted_on():
    j = _tiny_judge()
    rng = np.random.default_rng(0)
    x = torch.as_tensor(np.stack([np.r_[rng.integers(4, 169, n), np.zeros(32 - n, int)] for n in rng.integers(6, 32, 80)]))
    biased = A.Judge(j.model, j.position, 0.0, 1.0, -0.5)            # adds 0.5 per token
    assert np.polyfit(A.review_length(x).numpy(), biased.raw(x).numpy(), 1)[0] > 0.3
    lc = biased.length_controlled(x)
    assert abs(np.polyfit(A.review_length(x).numpy(), lc.raw(x).numpy(), 1)[0]) < 1e-9
    assert lc.position == biased.position


def test_gold_at_kl_interpolates_between_the_bracketing_points_and_is_nan_beyond_the_run():
    ev = [{"kl": 0.0, "gold": 0.0}, {"kl": 1.0, "gold": 0.4}, {"kl": 3.0, "gold": 0.8}, {"kl": 2.5, "gold": 0.1}]
    assert math.isclose(A.gold_at_kl(ev, 0.5), 0.2)
    assert math.isclose(A.gold_at_kl(ev, 2.0), 0.6)
    assert math.isnan(A.gold_at_kl(ev, 3.5))


@pytest.mark.parametrize("sync_every", [None, 1, 3])
def test_preference_rounds_draws_pairs_from_sft_a_snapshot_or_the_policy(sync_every):
    torch.manual_seed(0)
    sft = TinyLM(LMConfig(vocab_size=11, context=8, n_layer=1, n_head=2, d_model=16))
    seen = []

    def round_fn(policy, ref, x, annotator, opt, beta, gen, sampler=None):
        assert ref is sft and x.shape == (4, 2) and beta == 0.3
        seen.append(sampler)
        loss = policy(x).sum() * 0 + sum(p.sum() for p in policy.parameters()) * 1e-3
        opt.zero_grad(); loss.backward(); opt.step()
        return {"loss": float(loss.detach()), "chosen": x[:2], "rejected": x[2:]}

    prompts = torch.randint(1, 11, (20, 2))
    policy, log = A.preference_rounds(sft, round_fn, None, prompts, rounds=6, batch=4, beta=0.3, seed=0,
                                      sync_every=sync_every, eval_every=0)
    assert log["pairs"] == [2] * 6 and len(log["loss"]) == 6
    if sync_every is None:
        assert all(s is sft for s in seen)
    elif sync_every == 1:
        assert all(s is None for s in seen)
    else:
        assert all(s is not None and s is not sft for s in seen)
        assert seen[0] is seen[2] and seen[3] is seen[5] and seen[2] is not seen[3]
        before = {k: v.clone() for k, v in seen[3].state_dict().items()}
        assert any(not torch.equal(before[k], v) for k, v in sft.state_dict().items())   # the snapshot is the trained policy
    assert not any(torch.equal(a, b) for a, b in zip(policy.parameters(), sft.parameters()) if a.numel() > 16)


def test_the_shipped_judge_learned_the_planted_position_bias_and_ppo_curve_loads():
    judge = A.load_judge()
    m = judge.metadata
    assert m["planted_length_bias"] == 0.25 and m["planted_position_bias"] == 1.0
    assert 0.3 < judge.position < 1.5 and m["length_slope_on_pairs"] > 0.05
    assert m["test_inconsistent_fraction"] > 0.1
    curve = A.load_ppo_curve()
    assert sorted(curve) == [6, 12, 18, 24, 30] and all(p.metadata["kl_coef"] == 0.05 for p in curve.values())


def test_hw7bs_release_computes_no_log_sigmoid():
    """hw5's DPO and Bradley-Terry losses are a log-sigmoid of a difference: no hw7b release file computes one (the
    students' round is passed to the given loop)."""
    import nbformat

    nb = nbformat.read(REPO / "assignments" / "hw7b_ai_feedback" / "hw7b_ai_feedback.ipynb", as_version=4)
    texts = {"rlcourse/ai_feedback.py": (REPO / "rlcourse" / "ai_feedback.py").read_text()}
    texts.update({f"cell {i}": c.source for i, c in enumerate(nb.cells) if c.cell_type == "code"})
    for where, text in texts.items():
        assert "logsigmoid" not in text and "log_sigmoid" not in text and "binary_cross_entropy" not in text, where


def test_the_recorded_benchmark_has_three_seeds_of_every_method_and_annotator():
    path = REPO / "bench" / "results" / "hw7b_ai_feedback.json"
    if not path.exists():
        pytest.skip("bench/results/hw7b_ai_feedback.json not recorded yet: python bench/bench_hw7b_ai_feedback.py")
    result = json.loads(path.read_text())
    assert {"commit", "date", "load", "machine"} <= set(result["meta"])
    seeds = result["seeds"]
    assert len(seeds) >= 3
    for seed, run in seeds.items():
        assert {"offline DPO", "iterative DPO", "online DPO", "PPO"} == set(run["matched"]), seed
        assert {"SFT", "judge, one order", "judge, both orders", "judge, consistent verdicts only",
                "length-controlled judge, both orders", "rule-list critic"} <= set(run["judge_table"]), seed
        for name, curve in run["curves"].items():
            assert curve[0]["kl"] == pytest.approx(0.0, abs=1e-6) and all(math.isfinite(e["gold"]) for e in curve), name
        assert run["notebook_s"] < 20 * 60, "the full notebook exceeds its 20-minute budget"


def test_the_notebooks_figures_are_the_recorded_ones():
    """Every figure the solution notebook quotes from the benchmark (its budget line and the findings paragraph) is
    the recorded file's, formatted as the notebook prints it (mean ± population sd over the seeds)."""
    import nbformat

    result = json.loads((REPO / "bench" / "results" / "hw7b_ai_feedback.json").read_text())
    seeds = list(result["seeds"].values())

    def ms(values, digits=3):
        v = np.asarray(values, dtype=float)
        return f"{v.mean():.{digits}f} \\pm {v.std():.{digits}f}"

    def mean(values, digits):
        return f"{np.mean(values):.{digits}f}"

    matched = {m: ms([s["matched"][m]["2.0"] for s in seeds]) for m in ("online DPO", "iterative DPO", "offline DPO",
                                                                         "PPO")}
    table = lambda m, k: [s["judge_table"][m][k] for s in seeds]  # noqa: E731
    agree = lambda m: f"{100 * np.mean([s['agreement'][m]['agreement'] for s in seeds]):.1f}%"  # noqa: E731
    seconds = [s["notebook_s"] for s in seeds]
    want = [*matched.values(), f"from {mean(table('SFT', 'length'), 1)} to {mean(table('judge, one order', 'length'), 1)} tokens",
            f"policy's: {mean(table('simulated person (online DPO above)', 'length'), 1)}",
            ms(table("judge, one order", "gold")), ms(table("simulated person (online DPO above)", "gold")),
            f"${mean(table('judge, both orders', 'gold'), 3)}$", f"${mean(table('judge, consistent verdicts only', 'gold'), 3)}$",
            f"{mean(table('length-controlled judge, both orders', 'length'), 1)} tokens",
            ms(table("length-controlled judge, both orders", "gold")), agree("judge, both orders"),
            agree("judge, one order"), agree("judge, consistent verdicts only"),
            f"({min(seconds):.0f} to {max(seconds):.0f} s)"]
    nb = nbformat.read(REPO / "solutions" / "hw7b_ai_feedback" / "hw7b_ai_feedback.ipynb", as_version=4)
    text = " ".join(c.source.replace("\n", " ") for c in nb.cells if c.cell_type == "markdown")
    missing = [w for w in want if w not in text]
    assert not missing, f"figures of bench/results/hw7b_ai_feedback.json the notebook does not quote: {missing}"
