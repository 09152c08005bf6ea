"""The given loops of hw5 and hw6 (rlcourse.lm_training), run with the reference solutions of the stubs they take.

Each loop is checked for what its docstring promises: that it calls the function it is given (a loss that
carries no gradient leaves the model unchanged), that it learns with the reference (the reward it optimises
rises, the loss falls), and what it logs. The models are tiny transformers over the review language, so
every test runs in seconds.
"""
from __future__ import annotations

import contextlib
import io
import math

import nbformat
import numpy as np
import pytest
import torch

from conftest import REPO
from rlcourse import group_rl as G
from rlcourse import group_training as GT
from rlcourse import lm_training as L
from rlcourse import reviews as R
from rlcourse.lm import LMConfig, TinyLM, completion_mask

P = 5  # prompt length, as in the preference file


def reference(assignment: str) -> dict:
    """The stub cells of ``solutions/<assignment>`` (the reference solutions), executed after the imports."""
    nb = nbformat.read(REPO / "solutions" / assignment / f"{assignment}.ipynb", as_version=4)
    ns: dict = {"__name__": "__reference__"}
    exec("import numpy as np\nimport torch\nimport torch.nn.functional as F\n", ns)
    for cell in nb.cells:
        if cell.cell_type == "code" and cell.metadata.get("nbgrader", {}).get("solution"):
            with contextlib.redirect_stdout(io.StringIO()):
                exec(compile(cell.source, cell.metadata["nbgrader"]["grade_id"], "exec"), ns)
    return ns


@pytest.fixture(scope="module")
def hw5() -> dict:
    return reference("hw5_lm_alignment")


@pytest.fixture(scope="module")
def hw6() -> dict:
    return reference("hw6_group_rl")


def tiny_lm(seed: int = 0) -> TinyLM:
    torch.set_num_threads(1)
    torch.manual_seed(seed)
    return TinyLM(LMConfig(vocab_size=len(R.VOCAB), context=R.MAX_LEN, n_layer=1, n_head=2, d_model=16)).eval()


def prompts(n: int, seed: int = 0) -> torch.Tensor:
    """``n`` prompts of ``P`` tokens from the grammar (``<bos>`` and four words)."""
    corpus, _ = R.sample_corpus(n, seed=seed)
    return torch.as_tensor(corpus[:, :P])


def low_ids(tokens: torch.Tensor) -> torch.Tensor:
    """A reward a tiny model can learn in a few steps: the fraction of completion tokens with an id below 60."""
    mask = completion_mask(tokens, P)
    return ((tokens < 60).float() * mask).sum(1) / mask.sum(1).clamp(min=1.0)


def unchanged(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters()))


def seq_log_prob_sums(hw5: dict):
    return lambda model, x, p: hw5["sequence_log_prob"](model(x), x, completion_mask(x, p))


def test_gae_is_the_backward_recursion_inside_the_mask():
    rng = np.random.default_rng(0)
    rewards, values = (torch.as_tensor(rng.normal(size=(3, 7)), dtype=torch.float32) for _ in range(2))
    mask = torch.tensor([[0, 0, 1, 1, 1, 0, 0], [0, 1, 1, 1, 1, 1, 1], [0, 0, 0, 1, 0, 0, 0]], dtype=torch.float32)
    got = L.gae(rewards, values, mask, lam=0.9)
    for b in range(3):
        idx = np.flatnonzero(mask[b].numpy())
        adv, want = 0.0, np.zeros(7)
        for k, t in reversed(list(enumerate(idx))):
            v_next = float(values[b, idx[k + 1]]) if k + 1 < len(idx) else 0.0
            adv = float(rewards[b, t]) + v_next - float(values[b, t]) + 0.9 * adv
            want[t] = adv
        assert np.allclose(got[b].numpy(), want, atol=1e-5), (b, got[b], want)


def test_evaluate_gives_zero_kl_against_itself_and_the_gold_reward_of_its_samples(hw5):
    model, x = tiny_lm(), prompts(6)
    e = L.evaluate(model, model, low_ids, x, seed=3, log_prob_sums=seq_log_prob_sums(hw5))
    assert e["kl"] == 0.0 and e["kl_se"] == 0.0
    assert math.isclose(e["gold"], float(L.gold_fn(e["tokens"]).mean()), rel_tol=1e-6)
    assert math.isclose(e["proxy"], float(low_ids(e["tokens"]).mean()), rel_tol=1e-6)
    other = L.evaluate(tiny_lm(1), model, low_ids, x, seed=3, log_prob_sums=seq_log_prob_sums(hw5))
    assert other["kl_se"] > 0 and torch.equal(other["tokens"][:, :P], x)
    g = L.evaluate(tiny_lm(1), model, low_ids, x, seed=3, log_prob_sums=G.completion_log_prob_sums)
    assert math.isclose(g["kl"], other["kl"], rel_tol=1e-5, abs_tol=1e-6), "hw5's and hw6's log-probabilities agree"


def test_train_reward_model_fits_pairs_with_the_given_loss_and_standardises(hw5):
    sft = tiny_lm()
    x = torch.as_tensor(R.sample_corpus(96, seed=1)[0])
    gold = L.gold_fn(x)
    order = gold[:48] > gold[48:]
    chosen = torch.where(order[:, None], x[:48], x[48:])
    rejected = torch.where(order[:, None], x[48:], x[:48])
    rm = L.fit_reward_model(sft, chosen, rejected, hw5["reward_model_loss"], steps=60, seed=0, batch=16, lr=3e-3)
    with torch.no_grad():
        s = (torch.cat([rm.score(chosen), rm.score(rejected)]) - rm.shift) / rm.scale
    assert abs(float(s.mean())) < 1e-4 and abs(float(s.std()) - 1) < 1e-4
    assert float((s[:48] > s[48:]).float().mean()) > 0.8, "the fitted model should rank its training pairs"
    zero = L.fit_reward_model(sft, chosen, rejected, lambda c, r: 0.0 * (c - r).sum(), steps=5, seed=0, batch=16)
    head = float(zero.head.weight.detach().abs().sum() + zero.head.bias.detach().abs().sum())
    assert head == 0.0, "the loop must use the given loss (the zero-initialised head had no gradient to follow)"


def test_ppo_train_raises_the_reward_with_the_reference_stubs_and_logs_per_iteration(hw5):
    sft, x = tiny_lm(), prompts(32)
    stubs = (hw5["token_log_probs"], hw5["kl_penalised_rewards"], hw5["ppo_token_loss"])
    policy, log = L.ppo_train(sft, low_ids, x, *stubs, beta=0.0, iters=12, batch=32, seed=0, lr=3e-3)
    assert set(log) == {"reward", "gold", "kl", "clipfrac"} and all(len(v) == 12 for v in log.values())
    assert log["kl"][0] == 0.0, "the first batch is sampled from the SFT model itself"
    assert log["reward"][-3:].mean() > log["reward"][:3].mean() + 0.05, log["reward"]
    assert not policy.training and not unchanged(policy, sft)
    frozen, _ = L.ppo_train(sft, low_ids, x, stubs[0], stubs[1], lambda *a: 0.0 * a[0].sum(), beta=0.0, iters=2,
                            batch=8, seed=0)
    assert unchanged(frozen, sft), "the loop must step on the given ppo_token_loss"


def test_dpo_train_starts_at_log_2_and_learns_its_pairs(hw5):
    sft = tiny_lm()
    x = torch.as_tensor(R.sample_corpus(64, seed=2)[0])
    chosen, rejected = x[:32], x[32:]
    policy, log = L.dpo_train(sft, chosen, rejected, P, hw5["sequence_log_prob"], hw5["dpo_loss"], beta=0.5, steps=30,
                              seed=0, batch=16, lr=3e-3)
    assert math.isclose(log["loss"][0], math.log(2), rel_tol=1e-5), "at pi = pi_ref the DPO loss is log 2"
    assert log["loss"][-5:].mean() < log["loss"][0] - 0.1 and log["accuracy"][-5:].mean() > 0.8
    frozen, _ = L.dpo_train(sft, chosen, rejected, P, hw5["sequence_log_prob"], lambda *a: 0.0 * a[0].sum(), beta=0.5,
                            steps=2, seed=0, batch=8)
    assert unchanged(frozen, sft), "the loop must step on the given dpo_loss"


@pytest.mark.parametrize("variant", ["GRPO", "Dr. GRPO", "RLOO"])
def test_critic_free_train_raises_the_reward_with_each_variant(hw6, variant):
    sft, x = tiny_lm(), prompts(16)
    advantage_fn, length_norm = {"GRPO": (hw6["group_advantages"], True), "RLOO": (hw6["rloo_advantages"], True),
                                 "Dr. GRPO": (lambda r: hw6["group_advantages"](r, scale=False), False)}[variant]
    lr = 3e-3 if variant == "GRPO" else 3e-2   # Dr. GRPO and RLOO do not divide by the groups' small spread
    policy, log = GT.critic_free_train(sft, low_ids, x, advantage_fn, hw6["grpo_token_loss"], iters=12, n_prompts=4,
                                      group=8, seed=0, length_norm=length_norm, lr=lr, proxy_fn=L.gold_fn)
    assert set(log) == {"reward", "gold", "proxy", "kl", "equal_groups", "seconds"}
    assert np.allclose(log["proxy"], log["gold"]) and log["kl"][0] == 0.0
    assert log["reward"][-3:].mean() > log["reward"][:3].mean() + 0.05, log["reward"]
    _, plain = GT.critic_free_train(sft, low_ids, x, advantage_fn, hw6["grpo_token_loss"], iters=1, n_prompts=2,
                                   group=4, seed=0)
    assert np.isnan(plain["proxy"]).all(), "without a proxy_fn the proxy column is NaN"


def test_critic_free_train_steps_on_the_given_loss_only(hw6):
    sft = tiny_lm()
    frozen, _ = GT.critic_free_train(sft, low_ids, prompts(4), hw6["group_advantages"], lambda *a: 0.0 * a[0].sum(),
                                    iters=2, n_prompts=2, group=4, seed=0)
    assert unchanged(frozen, sft)


def test_pairwise_and_kto_train_learn_with_the_reference_losses(hw6):
    sft = tiny_lm()
    x = torch.as_tensor(R.sample_corpus(64, seed=3)[0])
    chosen, rejected = x[:32], x[32:]
    margin = lambda m: (G.completion_log_prob_sums(m, chosen, P) - G.completion_log_prob_sums(m, rejected, P))  # noqa: E731
    ipo = GT.pairwise_train(sft, chosen, rejected, P, lambda pc, pr, rc, rr: hw6["ipo_loss"](pc, pr, rc, rr, 0.5),
                           steps=40, seed=0, batch=16, lr=3e-3)
    with torch.no_grad():
        h = margin(ipo) - margin(sft)
    assert float(h.mean()) > 0.3, "IPO's margin should move towards its target 1 / (2 beta) = 1"
    desirable = torch.arange(64) < 32
    kto = GT.kto_train(sft, x, desirable, P, hw6["kto_loss"], beta=0.5, steps=40, seed=0, batch=16, lr=3e-3)
    with torch.no_grad():
        r = G.completion_log_prob_sums(kto, x, P) - G.completion_log_prob_sums(sft, x, P)
    assert float(r[desirable].mean()) > float(r[~desirable].mean()) + 0.3
    zero = lambda *a: 0.0 * a[0].sum()  # noqa: E731
    assert unchanged(GT.pairwise_train(sft, chosen, rejected, P, zero, steps=2, seed=0, batch=8), sft)
    assert unchanged(GT.kto_train(sft, x, desirable, P, zero, beta=0.5, steps=2, seed=0, batch=8), sft)
