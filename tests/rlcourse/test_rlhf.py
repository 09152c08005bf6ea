"""Tests of rlcourse.rlhf (the reference policy, the shipped reward model, pairs, KL, evaluation and the DPO
loop) and of the instructor script that fits the reward model."""
import copy
import importlib.util

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse.nets import GaussianPolicy
from rlcourse.preferences import RewardEnsemble, load_hopper_preferences, preference_accuracy
from rlcourse.rlhf import (evaluate_policy, load_reference, load_reward_model, mean_kl, oriented_pairs,
                           reward_function, save_reward_model, train_dpo)
from conftest import REPO


def _reward_model_script():
    path = REPO / "datasets" / "scripts" / "make_hw4_reward_model.py"
    spec = importlib.util.spec_from_file_location("make_hw4_reward_model", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_reference_policy_is_verified_and_mid_skill():
    ref = load_reference()
    assert isinstance(ref, GaussianPolicy) and not any(p.requires_grad for p in ref.parameters())
    assert 500 < ref.metadata["return_mean"] < 1500 and ref.metadata["eval_episodes"] == 20


def _synthetic_segments(rng, n=300, length=5):
    obs = rng.normal(size=(n, length, 11)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(n, length, 3)).astype(np.float32)
    returns = (obs[..., 0] + act[..., 1]).sum(1)
    return obs, act, returns


def test_reward_model_script_fit_learns_and_normalises():
    rng = np.random.default_rng(0)
    obs, act, returns = _synthetic_segments(rng)
    pairs = rng.integers(0, 200, size=(1500, 2))
    mu = (returns[pairs[:, 0]] > returns[pairs[:, 1]]).astype(np.float32)
    mu[::50] = 0.5
    ens = _reward_model_script().fit(obs, act, pairs, mu, n_members=2, hidden=[64, 64], n_steps=300, batch_size=64,
                                     lr=1e-3, weight_decay=1e-4, seed=0)
    r = reward_function(ens)
    per_step = r(obs.reshape(-1, 11), act.reshape(-1, 3))
    assert per_step.shape == (obs.shape[0] * obs.shape[1],) and per_step.dtype == np.float32
    seg = per_step.reshape(obs.shape[:2]).sum(1)
    test = rng.integers(200, 300, size=(500, 2))
    test_mu = (returns[test[:, 0]] > returns[test[:, 1]]).astype(np.float32)
    assert preference_accuracy(seg[test[:, 0]], seg[test[:, 1]], test_mu) > 0.9
    members = ens.predict(obs[np.unique(pairs)], act[np.unique(pairs)]).reshape(2, -1)
    assert np.allclose(members.mean(1), 0.0, atol=1e-4) and np.allclose(members.std(1), 1.0, atol=1e-2)


def test_segment_bt_loss_is_log2_at_equal_rewards_and_follows_the_label():
    bt = _reward_model_script().segment_bt_loss
    member = lambda obs, act: obs[..., 0]
    a, b = torch.zeros(4, 3, 11), torch.zeros(4, 3, 11)
    b[..., 0] = 1.0  # R_b - R_a = 3 per pair
    u = torch.zeros(4, 3, 3)
    assert torch.isclose(bt(member, a, u, a, u, torch.full((4,), 0.7)), torch.tensor(np.log(2), dtype=torch.float32))
    assert torch.isclose(bt(member, a, u, b, u, torch.zeros(4)), F.softplus(torch.tensor(-3.0)))
    assert torch.isclose(bt(member, a, u, b, u, torch.full((4,), 0.5)),
                         0.5 * (F.softplus(torch.tensor(3.0)) + F.softplus(torch.tensor(-3.0))))


def test_shipped_reward_model_is_verified_and_near_the_annotator():
    model = load_reward_model()
    meta = model.metadata
    assert isinstance(model, RewardEnsemble) and not any(p.requires_grad for p in model.parameters())
    prefs = load_hopper_preferences()
    seg = model.predict(prefs.obs, prefs.act, prefs.absorbing).mean(0)
    i, j = prefs.test_pairs.T
    accuracy = preference_accuracy(seg.sum(1)[i], seg.sum(1)[j], prefs.test_mu)
    assert abs(accuracy - meta["test_accuracy"]) < 1e-3 and accuracy > meta["bayes_ceiling_test"] - 0.03
    real = seg[~prefs.absorbing]
    assert abs(real.mean() - meta["step_mean"]) < 1e-3 and abs(real.std() - meta["step_std"]) < 1e-3
    # the absorbing state: its learned reward, and the offset that makes it pay 0 after normalisation
    absorbing = float(model.absorbing_value().mean())
    assert np.isclose(absorbing, meta["absorbing_reward"], atol=1e-5) and np.allclose(seg[prefs.absorbing], absorbing)
    assert np.isclose((absorbing - meta["step_mean"]) / meta["step_std"] + meta["data_offset"], 0.0, atol=1e-6)
    assert meta["data_offset"] > 0, "a fall should cost more than an average upright step"


def test_upright_reward_model_is_kept_for_the_first_table():
    model = load_reward_model("hw4/reward_model_upright.pt")
    assert not model.has_absorbing and model.metadata["data"] == "hopper_prefs/hopper_prefs.npz"


def test_reward_model_script_fits_the_absorbing_constant():
    """Synthetic segments whose true per-step reward is obs[0] + 1 while upright and 0 after a fall. With pairs
    that contain falls, the fitted model pays an upright step with obs[0] = 0 one unit of obs[0] more than the
    absorbing state: (intercept - absorbing) / slope of its per-step reward is near 1, the true survival bonus."""
    rng = np.random.default_rng(1)
    n, L = 400, 10
    obs, act = rng.normal(size=(n, L, 11)).astype(np.float32), rng.normal(size=(n, L, 3)).astype(np.float32)
    length = np.where(rng.random(n) < 0.4, rng.integers(1, L, size=n), L)
    absorbing = np.arange(L) >= length[:, None]
    step = np.where(absorbing, 0.0, obs[..., 0] + 1.0)
    returns = step.sum(1)
    pairs = rng.integers(0, n, size=(4000, 2))
    mu = (rng.random(4000) < 1 / (1 + np.exp(-(returns[pairs[:, 0]] - returns[pairs[:, 1]])))).astype(np.float32)
    ens = _reward_model_script().fit(obs, act, pairs, mu, n_members=2, hidden=[32], n_steps=1500, batch_size=128,
                                     lr=3e-3, weight_decay=0.0, seed=0, absorbing=absorbing)
    per_step = ens.predict(obs, act)[:, ~absorbing]  # (2, real steps), normalised
    for k, absorbing_value in enumerate(ens.absorbing_value()):
        slope, intercept = np.polyfit(obs[..., 0][~absorbing], per_step[k], 1)
        assert abs((intercept - absorbing_value) / slope - 1.0) < 0.15, (k, intercept, absorbing_value, slope)


def test_choices_from_preference_data_follow_the_stated_rules():
    from rlcourse.rlhf import choose_beta, choose_kl_coef

    checks = {0.01: {"learned_return": 900.0, "disagreement": 0.5}, 0.03: {"learned_return": 700.0, "disagreement": 0.2},
              0.1: {"learned_return": 400.0, "disagreement": 0.1}}
    assert choose_kl_coef(checks, 0.3) == 0.03  # the best covered policy, not the best learned return overall
    assert choose_kl_coef(checks, 1.0) == 0.01
    assert choose_kl_coef(checks, 0.05) == 0.1  # none covered: the largest coefficient
    assert choose_beta({0.03: 0.80, 0.1: 0.83, 0.3: 0.828, 1.0: 0.79}) == 0.3  # within 0.005 of the best: the largest
    assert choose_beta({0.03: 0.80, 0.1: 0.83, 0.3: 0.82}) == 0.1


def test_choose_kl_coef_can_pick_no_penalty_and_can_reject_it():
    from rlcourse.rlhf import choose_kl_coef

    checks = {0.0: {"learned_return": 3000.0, "disagreement": 0.36}, 0.01: {"learned_return": 2900.0, "disagreement": 0.30}}
    assert choose_kl_coef(checks, 0.42) == 0.0  # covered: no penalty is a candidate like any other
    assert choose_kl_coef(checks, 0.33) == 0.01  # not covered: the rule rejects it


def test_bootstrap_ratio_brackets_the_ratio_and_widens_with_spread():
    from rlcourse.rlhf import bootstrap_ratio

    lo, hi = bootstrap_ratio([3000.0] * 5, [3000.0] * 5)
    assert lo == hi == 1.0  # no spread: the interval is the point
    steady = bootstrap_ratio([3100.0, 3200.0, 3300.0], [3200.0, 3250.0, 3150.0])
    failed = bootstrap_ratio([3100.0, 3200.0, 3300.0], [3200.0, 3250.0, 1600.0])
    ratio = np.mean([3100.0, 3200.0, 3300.0]) / np.mean([3200.0, 3250.0, 1600.0])
    assert failed[0] < ratio < failed[1] and steady[0] < 1.0 < steady[1]
    assert failed[1] - failed[0] > 5 * (steady[1] - steady[0])  # one failed seed of the denominator: far wider
    assert failed[1] <= 3300.0 / 1600.0  # no resample goes past the extremes
    assert bootstrap_ratio([1.0, 2.0, 4.0], [2.0, 3.0], seed=1) == bootstrap_ratio([1.0, 2.0, 4.0], [2.0, 3.0], seed=1)


def test_reward_model_save_and_load_round_trip(tmp_path, monkeypatch):
    import rlcourse.rlhf as rlhf

    ens = RewardEnsemble(11, 3, n_members=2, hidden=(16,), seed=3)
    x, u = torch.randn(7, 11), torch.randn(7, 3)
    ens.set_input_scaling(x, u)
    ens.normalise_(x, u)
    save_reward_model(ens, tmp_path / "rm.pt", note="test")
    monkeypatch.setattr(rlhf._data, "verify", lambda name: tmp_path / name)
    back = load_reward_model("rm.pt")
    assert back.hidden == [16] and back.metadata == {"note": "test"} and torch.equal(back(x, u), ens(x, u))


def test_oriented_pairs_drop_ties_and_put_the_winner_first():
    obs = np.arange(4, dtype=np.float32)[:, None, None] * np.ones((4, 2, 11), np.float32)
    act = np.zeros((4, 2, 3), np.float32)
    pairs = np.array([[0, 1], [2, 3], [1, 2]])
    sp = oriented_pairs(obs, act, pairs, np.array([1.0, 0.0, 0.5]))
    assert len(sp) == 2
    assert sp.chosen_obs[:, 0, 0].tolist() == [0.0, 3.0] and sp.rejected_obs[:, 0, 0].tolist() == [1.0, 2.0]
    (co, ca), (ro, ra) = sp.batch([1])
    assert co.shape == (1, 2, 11) and ra.shape == (1, 2, 3)


def test_mean_kl_closed_form():
    pol = GaussianPolicy(11, 3, hidden=(8,), log_std_init=np.log(0.5))
    ref = copy.deepcopy(pol)
    obs = np.random.default_rng(0).normal(size=(20, 11))
    assert abs(mean_kl(pol, ref, obs)) < 1e-7
    with torch.no_grad():
        pol.mean.bias.add_(torch.tensor([0.1, -0.2, 0.0]))
    assert np.isclose(mean_kl(pol, ref, obs), (0.01 + 0.04) / (2 * 0.25), rtol=1e-5)


def test_evaluate_policy_reports_return_kl_and_learned_return():
    ref = load_reference()
    out = evaluate_policy(ref, ref, reward_fn=lambda o, a: np.ones(len(o), np.float32), n_episodes=2, max_steps=30)
    assert set(out) == {"return", "return_std", "length", "kl", "learned_return"}
    assert out["kl"] == 0.0 and np.isclose(out["learned_return"], out["length"])


def _dpo(policy, reference, chosen, rejected, beta):
    lp = lambda p, seg: p.log_prob(*seg).sum(-1)
    with torch.no_grad():
        rc, rr = lp(reference, chosen), lp(reference, rejected)
    m = beta * ((lp(policy, chosen) - rc) - (lp(policy, rejected) - rr))
    return -F.logsigmoid(m).mean(), {"margin": m.mean().detach(), "accuracy": (m > 0).float().mean()}


def test_train_dpo_learns_the_preferences_and_keeps_the_reference():
    rng = np.random.default_rng(1)
    n, length = 400, 4
    obs = rng.normal(size=(2 * n, length, 11)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(2 * n, length, 3)).astype(np.float32)
    good = act[..., 0].sum(1)  # the annotator likes a large first action
    pairs = np.stack([np.arange(n), np.arange(n, 2 * n)], 1)
    mu = (good[:n] > good[n:]).astype(np.float32)
    train, val = oriented_pairs(obs, act, pairs[:300], mu[:300]), oriented_pairs(obs, act, pairs[300:], mu[300:])
    ref = GaussianPolicy(11, 3, hidden=(16,)).requires_grad_(False)
    before = [p.clone() for p in ref.parameters()]
    evals = []
    pol, log = train_dpo(ref, ref, _dpo, train, beta=0.5, n_steps=200, lr=3e-3, val=val, eval_every=100,
                         evaluate=lambda p: evals.append(1) or {"bias0": float(p.mean.bias[0].detach())}, log_every=50,
                         verbose=False)
    assert log.steps[0]["step"] == 50 and log.steps[-1]["val_accuracy"] > 0.8
    assert len(log.evals) == 3 and log.evals[-1]["bias0"] > log.evals[0]["bias0"]
    assert all(torch.equal(a, b) for a, b in zip(before, ref.parameters()))
