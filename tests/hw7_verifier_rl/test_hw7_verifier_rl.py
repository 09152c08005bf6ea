"""hw7's given tools (rlcourse.verifier_rl), its base-model script, the shipped base model and its recorded benchmark."""
from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest
import torch

from conftest import REPO
from rlcourse import verifier_rl as V
from rlcourse.lm import LMConfig, TinyLM

sys.path.insert(0, str(REPO / "datasets" / "scripts"))
sys.path.insert(0, str(REPO / "bench"))


def _tiny(seed: int = 0) -> TinyLM:
    torch.manual_seed(seed)
    return TinyLM(LMConfig(vocab_size=len(V.VOCAB), context=V.CONTEXT, n_layer=1, n_head=2, d_model=16))


@pytest.fixture(scope="module")
def solution():
    from bench_hw6_group_rl import solution_namespace

    return solution_namespace(REPO / "solutions" / "hw7_verifier_rl" / "hw7_verifier_rl.ipynb")


def test_prompts_and_worked_examples_have_the_documented_layout():
    a, b = np.array([7, 999, 0]), np.array([450, 999, 0])
    x = V.worked_examples(a, b)
    assert x.shape == (3, V.PROMPT_LEN + V.MAX_NEW)
    assert [V.decode(r) for r in x] == ["007+450=457$", "999+999=1998$", "000+000=0$"]
    assert torch.equal(x[:, :V.PROMPT_LEN], V.prompts(a, b)) and bool((x[:, 0] == V.BOS).all())
    pa, pb = V.problems(500, seed=4)
    assert pa.min() >= 0 and pa.max() <= 999 and not np.array_equal(pa, pb)


def test_web_documents_end_with_eos_and_join_equations_with_a_semicolon():
    docs = V.web_documents(400, seed=0)
    texts = [V.decode(r) for r in docs]
    assert all(t.endswith("$") and t.count("$") == 1 for t in texts)
    two = np.mean([";" in t for t in texts])
    assert 0.4 < two < 0.6, two
    wrong = 0
    for t in texts:
        for eq in t[:-1].split(";"):
            lhs, rhs = eq.split("=")
            x, y = lhs.split("+")
            wrong += int(x) + int(y) != int(rhs)
    n_eq = sum(t.count("=") for t in texts)
    assert 0.05 < wrong / n_eq < 0.15, wrong / n_eq            # typo = 0.1


def test_the_scripts_checker_agrees_with_the_reference_solution(solution):
    from make_hw7_models import _check

    rng = np.random.default_rng(0)
    p = V.prompts(*V.problems(300, seed=5))
    right = V.worked_examples(*V.problems(300, seed=5))[:, V.PROMPT_LEN:]
    noise = torch.as_tensor(rng.integers(0, 16, size=right.shape))
    pick = torch.as_tensor(rng.random(right.shape) < 0.15)
    tokens = torch.cat([p, torch.where(pick, noise, right)], dim=1)
    fmt, cor = _check(tokens)
    f2, c2 = solution["verifier_reward"](tokens)
    assert np.array_equal(fmt, f2.numpy() > 0.5) and np.array_equal(cor, c2.numpy() > 0.5)
    assert 0.2 < cor.mean() < 0.9 and (fmt & ~cor).any() and (~fmt).any()


def test_finetune_leaves_the_model_alone_and_lowers_the_loss(solution):
    model = _tiny()
    data = V.worked_examples(*V.problems(64, seed=1))
    before = [p.detach().clone() for p in model.parameters()]
    tuned = V.finetune(model, data, solution["rft_loss"], steps=30, seed=0, lr=3e-3)
    assert all(torch.equal(a, b) for a, b in zip(before, model.parameters()))
    from rlcourse.group_rl import completion_log_probs
    from rlcourse.lm import completion_mask

    m = completion_mask(data, V.PROMPT_LEN)
    with torch.no_grad():
        l0 = solution["rft_loss"](completion_log_probs(model, data, V.PROMPT_LEN), m)
        l1 = solution["rft_loss"](completion_log_probs(tuned, data, V.PROMPT_LEN), m)
    assert float(l1) < float(l0) - 0.3, (float(l0), float(l1))


def test_group_rl_uses_the_advantage_table_and_logs_all_equal_groups(solution):
    calls = []

    def adv(k, g):
        calls.append((k.clone(), g))
        return solution["binary_group_advantages"](k, g, "dr_grpo")

    reward = lambda t: torch.as_tensor(np.random.default_rng(int(t.sum())).random(len(t)) < 0.5, dtype=torch.float32)  # noqa: E731
    prompts = V.prompts(*V.problems(20, seed=0))
    evals = []
    _, log = V.group_rl(_tiny(), prompts, reward, adv, iters=4, n_prompts=3, group=4, seed=0, length_norm=False,
                        eval_every=2, on_eval=lambda i, p, n: evals.append((i, n)))
    assert [g for _, g in calls] == [4] * 4 and all(k.shape == (3,) for k, _ in calls)
    assert evals == [(0, 0), (2, 24), (4, 48)] and list(log["samples"]) == [12, 24, 36, 48]
    for (k, _), eq in zip(calls, log["equal_groups"]):
        assert math.isclose(eq, float(((k == 0) | (k == 4)).float().mean()))
    zero = lambda k, g: torch.zeros(len(k), 2)  # noqa: E731
    model = _tiny()
    policy, _ = V.group_rl(model, prompts, reward, zero, iters=2, n_prompts=2, group=2, seed=0, length_norm=True)
    assert all(torch.equal(a, b) for a, b in zip(model.parameters(), policy.parameters()))    # no advantage, no step


def test_expert_iteration_trains_only_on_what_the_filter_keeps(solution):
    prompts = V.prompts(*V.problems(20, seed=0))
    model = _tiny()
    never = lambda t: torch.zeros(len(t))  # noqa: E731
    policy, log = V.expert_iteration(model, prompts, never, solution["rft_select"], solution["rft_loss"], rounds=2,
                                     n_prompts=3, group=4, max_per_prompt=1, steps=2, seed=0)
    assert list(log["kept"]) == [0, 0] and list(log["samples"]) == [12, 24] and list(log["equal_groups"]) == [1.0, 1.0]
    assert all(torch.equal(a, b) for a, b in zip(model.parameters(), policy.parameters()))
    always = lambda t: torch.ones(len(t))  # noqa: E731
    _, log = V.expert_iteration(model, prompts, always, solution["rft_select"], solution["rft_loss"], rounds=1,
                                n_prompts=3, group=4, max_per_prompt=2, steps=1, seed=0)
    assert 3 <= log["kept"][0] <= 6


def test_the_shipped_base_model_fails_the_format_about_half_the_time(solution):
    base = V.load_base()
    meta = base.metadata
    assert meta["steps"] == 3000 and meta["horizon"] == 8000 and meta["params"] == base.n_params()
    x = V.prompts(*V.problems(300, seed=7))
    fmt, cor = solution["verifier_reward"](V.sample(base, x, 1, seed=0))
    assert 0.35 < float(fmt.mean()) < 0.65, float(fmt.mean())         # the web stops after one equation half the time
    assert float(cor.mean()) > 0.1 and float(cor.sum()) <= float(fmt.sum())


def test_the_recorded_benchmark_has_every_stage_and_three_seeds():
    path = REPO / "bench" / "results" / "hw7_verifier_rl.json"
    if not path.exists():
        pytest.skip("bench/results/hw7_verifier_rl.json not recorded yet: python bench/bench_hw7_verifier_rl.py")
    result = json.loads(path.read_text())
    assert {"commit", "date", "load", "machine"} <= set(result["meta"])
    assert set(result["stages"]) == {"zero-shot", "SFT", "expert iteration", "GRPO", "Dr. GRPO", "RLOO"}
    ks = [str(k) for k in result["budget"]["KS"]]
    assert ks[-1] == "64"
    for name, per_seed in result["stages"].items():
        assert len(per_seed) == (1 if name == "zero-shot" else 3), name
        for row in per_seed.values():
            assert set(row["pass"]) == set(ks)
            values = [row["pass"][k] for k in ks]
            assert all(0 <= v <= 1 for v in values) and values == sorted(values), (name, values)   # pass@k rises with k
    for name, per_seed in result["curves"].items():
        for row in per_seed.values():
            assert row["eval_samples"][0] == 0 and row["eval_samples"][-1] == row["samples"][-1]
            assert all(0 <= x <= 1 for x in row["equal_groups"])


def test_the_notebooks_budget_line_quotes_the_recorded_times():
    """The solution notebook's budget paragraph quotes the recorded full-budget times (the benchmark's run of every
    cell, and the notebook under a Jupyter kernel) with their loads, and the FAST run's, as the results file has them."""
    import nbformat

    result = json.loads((REPO / "bench" / "results" / "hw7_verifier_rl.json").read_text())
    budgets = result["budgets"]
    want = [f"{result['exec_seconds']:,.0f} s", f"{budgets['notebook_full']['seconds']:,.0f} s",
            f"load {budgets['notebook_full']['load_before'][0]:.0f} at its start, {budgets['notebook_full']['load'][0]:.0f} at its end",
            f"{budgets['notebook_fast']['seconds']:.0f} s"]
    if "kernel_cpu_seconds" in budgets["notebook_full"]:   # recorded since 3ce8f31
        cpu = budgets["notebook_full"]["kernel_cpu_seconds"]
        want += [f"{cpu:,.0f} s of the kernel's CPU time", f"about {cpu / 60:.0f} minutes on an idle machine",
                 "within the 20-minute budget" if cpu < 20 * 60 else "over the 20-minute budget"]
    nb = nbformat.read(REPO / "solutions" / "hw7_verifier_rl" / "hw7_verifier_rl.ipynb", as_version=4)
    text = next(c.source for c in nb.cells if c.cell_type == "markdown" and c.source.startswith("## Budgets"))
    text = text.replace("\n", " ")
    missing = [w for w in want if w not in text]
    assert not missing, f"figures of bench/results/hw7_verifier_rl.json the budget paragraph does not quote: {missing}"
