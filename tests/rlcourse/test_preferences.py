"""Tests of rlcourse.preferences: the tie model, the annotator, the shipped data, the bandit and the ensemble."""
import numpy as np
import pytest
import torch
from scipy.special import expit

from rlcourse import data
from rlcourse.preferences import (ITEMS_FILE, HOPPER_PREFS_FILE, HOPPER_PREFS_UPRIGHT_FILE, DuelingBandit,
                                  RewardEnsemble, dueling_regret,
                                  expected_bayes_accuracy, load_hopper_preferences, load_items, preference_accuracy,
                                  random_pairs, rao_kupper_probabilities, sample_labels, simulate_annotator,
                                  uniform_pairs, win_counts)


# ---------------------------------------------------------------- tie model and annotator
def test_rao_kupper_probabilities_are_a_distribution():
    d = np.linspace(-6, 6, 41)
    win, tie, loss = rao_kupper_probabilities(d, 0.4)
    assert np.allclose(win + tie + loss, 1) and (tie >= 0).all() and (tie > 0.01)[20]
    assert np.allclose(win, loss[::-1]), "swapping the items swaps win and loss"
    assert np.allclose(rao_kupper_probabilities(d, 0.0)[1], 0), "eta = 0 means no ties"
    with pytest.raises(ValueError):
        rao_kupper_probabilities(d, -0.1)


def test_half_win_label_is_nearly_unbiased_for_small_eta():
    """The module docstring's claim: E[mu] = P(win) + P(tie)/2 = sigmoid(d) + O(eta^2)."""
    d = np.linspace(-5, 5, 201)
    errors = []
    for eta in (0.1, 0.2, 0.4):
        win, tie, _ = rao_kupper_probabilities(d, eta)
        errors.append(np.abs(win + tie / 2 - expit(d)).max())
    assert errors[0] < 2e-3 and errors[-1] < 0.03
    assert errors[2] / errors[0] > 8, "the bias should grow like eta squared"


def test_sample_labels_frequencies():
    rng = np.random.default_rng(0)
    mu = sample_labels(np.full(200_000, 0.7), 0.4, rng)
    win, tie, loss = rao_kupper_probabilities(0.7, 0.4)
    assert set(np.unique(mu)) == {0.0, 0.5, 1.0} and mu.dtype == np.float32
    assert abs((mu == 1).mean() - win) < 5e-3 and abs((mu == 0.5).mean() - tie) < 5e-3


def test_annotator_flips_strict_labels_only():
    rng = np.random.default_rng(1)
    n = 100_000
    mu = simulate_annotator(np.full(n, 100.0), np.zeros(n), temperature=1.0, flip_rate=0.2, log_theta=0.3, rng=rng)
    assert abs((mu == 0).mean() - 0.2) < 5e-3 and (mu == 0.5).sum() == 0
    ties = simulate_annotator(np.zeros(n), np.zeros(n), temperature=1.0, flip_rate=0.2, log_theta=5.0, rng=rng)
    assert (ties == 0.5).mean() > 0.98, "a tie is never flipped"
    with pytest.raises(ValueError):
        simulate_annotator(np.zeros(2), np.zeros(2), temperature=1.0, flip_rate=0.5, log_theta=0.3, rng=rng)


def test_expected_bayes_accuracy_matches_simulation():
    rng = np.random.default_rng(2)
    ra, rb = rng.normal(scale=3, size=50_000), rng.normal(scale=3, size=50_000)
    mu = simulate_annotator(ra, rb, 2.0, 0.1, 0.4, rng)
    assert abs(preference_accuracy(ra, rb, mu) - expected_bayes_accuracy(ra, rb, 2.0, 0.1, 0.4)) < 6e-3


def test_preference_accuracy_conventions():
    assert preference_accuracy([2, 0, 5], [1, 1, 5], [1.0, 1.0, 0.5]) == 0.5, "ties are left out"
    assert preference_accuracy([1.0], [1.0], [0.0]) == 0.5, "a predicted tie is half right"
    with pytest.raises(ValueError):
        preference_accuracy([1.0], [0.0], [0.5])


def test_random_pairs_and_win_counts():
    rng = np.random.default_rng(3)
    pairs = random_pairs(np.array([3, 5, 9]), 1000, rng)
    assert pairs.shape == (1000, 2) and (pairs[:, 0] != pairs[:, 1]).all() and set(np.unique(pairs)) == {3, 5, 9}
    wins, games = win_counts(4, np.array([0, 0, 1]), np.array([1, 1, 2]), np.array([1.0, 0.5, 0.0]))
    assert np.allclose(wins + wins.T, games) and games[0, 1] == 2 and wins[0, 1] == 1.5 and wins[2, 1] == 1.0


# ---------------------------------------------------------------- dueling bandits
def test_dueling_bandit_frequencies_and_count():
    P = np.array([[0.5, 0.8], [0.2, 0.5]])
    env = DuelingBandit(P, seed=0)
    wins = np.mean([env.duel(0, 1) for _ in range(20_000)])
    assert abs(wins - 0.8) < 0.01 and env.n_duels == 20_000 and env.n_arms == 2
    with pytest.raises(ValueError):
        DuelingBandit(np.array([[0.5, 0.8], [0.8, 0.5]]))


def test_dueling_regret():
    P = np.array([[0.5, 0.6, 0.9], [0.4, 0.5, 0.7], [0.1, 0.3, 0.5]])
    regret = dueling_regret(P, np.array([[0, 0], [1, 2], [0, 2]]), winner=0)
    assert np.allclose(regret, [0.0, (0.6 + 0.9 - 1) / 2, (0.5 + 0.9 - 1) / 2])
    with pytest.raises(ValueError):
        dueling_regret(P, np.array([[0, 1]]), winner=3)
    # it takes the winner on trust: regret against another arm is not refused (refusing would reveal the winner)
    assert dueling_regret(P, np.array([[1, 1]]), winner=2)[0] < 0
    pairs = uniform_pairs(DuelingBandit(P, 0), 500, np.random.default_rng(0))
    assert pairs.shape == (500, 2) and (pairs[:, 0] != pairs[:, 1]).all()


# ---------------------------------------------------------------- reward ensemble
def test_ensemble_seeded_and_leaves_global_rng_alone():
    torch.manual_seed(123)
    expected = torch.rand(1)
    torch.manual_seed(123)
    a, b = RewardEnsemble(11, 3, 2, seed=7), RewardEnsemble(11, 3, 2, seed=7)
    assert torch.rand(1).item() == expected.item(), "building an ensemble must not consume the global generator"
    x, u = torch.randn(4, 11), torch.randn(4, 3)
    assert torch.equal(a(x, u), b(x, u)) and not torch.equal(a(x, u), RewardEnsemble(11, 3, 2, seed=8)(x, u))


def test_ensemble_shapes_members_and_normalisation():
    ens = RewardEnsemble(11, 3, n_members=3, seed=0)
    obs, act = np.random.default_rng(0).normal(size=(2, 50, 25, 11)), np.zeros((50, 25, 3))
    obs = obs[0]
    ens.set_input_scaling(obs, act)
    ens.normalise_(obs, act)
    r = ens(obs, act)
    assert r.shape == (3, 50, 25)
    flat = r.detach().reshape(3, -1)
    assert torch.allclose(flat.mean(1), torch.zeros(3), atol=1e-4) and torch.allclose(flat.std(1), torch.ones(3), atol=1e-4)
    assert torch.allclose(ens.member(1)(obs, act), r[1]), "member(k) is row k of the ensemble's output"
    own = {id(p) for p in ens.members[1].parameters()}
    assert {id(p) for p in ens.member(1).parameters()} == own, "member(k) exposes only its own weights"
    assert np.allclose(ens.predict(obs, act), r.detach().numpy())


# ---------------------------------------------------------------- shipped data
def test_items_data():
    d = load_items()
    assert d["utilities"].shape == (d["n_items"],) and abs(d["utilities"].mean()) < 1e-12
    assert d["i"].shape == d["j"].shape == d["mu"].shape and (d["i"] != d["j"]).all()
    assert set(np.unique(d["mu"])) == {0.0, 0.5, 1.0}
    info = data.info(ITEMS_FILE)["info"]
    assert info["n_comparisons"] == len(d["mu"]) and "Rao-Kupper" in info["tie_model"]


def test_hopper_preferences_data():
    p = load_hopper_preferences()
    info = p.info
    n, length = p.obs.shape[:2]
    assert length == info["segment_length"] and p.act.shape == (n, length, 3) and p.rewards.shape == (n, length)
    assert len(p.train_mu) == info["n_train_pairs"] and len(p.test_mu) == info["n_test_pairs"]
    assert len(p.train_mu) + len(p.test_mu) >= 5000
    assert not p.test_segment[p.train_pairs].any() and p.test_segment[p.test_pairs].all(), "the split leaks"
    assert set(np.unique(np.concatenate([p.train_mu, p.test_mu]))) <= {0.0, 0.5, 1.0}
    ret = p.returns
    assert np.isclose(preference_accuracy(ret[p.test_pairs[:, 0]], ret[p.test_pairs[:, 1]], p.test_mu),
                      info["bayes_ceiling_test"], atol=1e-4), "the MANIFEST's Bayes ceiling is out of date"
    assert 0.6 < info["bayes_ceiling_test"] < 1.0 and len(p.source_names) == p.source.max() + 1
    assert p.rollout_obs.shape[:2] == p.rollout_rewards.shape and (p.rollout_length > 0).all()
    assert data.verify(HOPPER_PREFS_FILE).stat().st_size < 10e6
    # falls: absorbing steps pay nothing and carry no action; every pair split has pairs with a fall
    assert p.terminated.dtype == bool and p.terminated.sum() == info["n_fall_segments"] > 0
    assert (p.length[~p.terminated] == length).all() and (p.length[p.terminated] < length).all()
    assert (p.rewards[p.absorbing] == 0).all() and (p.act[p.absorbing] == 0).all()
    assert np.isclose(p.terminated[p.train_pairs].any(1).mean(), info["fall_pair_fraction_train"], atol=1e-4)
    assert 0.1 < info["fall_pair_fraction_test"] < 0.5
    upright = load_hopper_preferences(HOPPER_PREFS_UPRIGHT_FILE)
    assert not upright.terminated.any() and not upright.absorbing.any()
    n_old = len(upright.obs)
    assert np.array_equal(p.train_pairs[: len(upright.train_pairs)], upright.train_pairs), "the upright pairs are kept"
    assert np.array_equal(p.rewards[:n_old], upright.rewards) and not p.terminated[:n_old].any()


def test_hopper_annotate_reproduces_annotator_statistics():
    p = load_hopper_preferences()
    mu = p.annotate(p.train_pairs, np.random.default_rng(0))
    ret = p.returns
    agree = preference_accuracy(ret[p.train_pairs[:, 0]], ret[p.train_pairs[:, 1]], mu)
    assert abs(agree - p.info["label_agreement_with_true_return"]) < 0.03


def test_render_segment_shapes():
    from rlcourse.video import egl_available

    if not egl_available():
        pytest.skip("no EGL for headless MuJoCo rendering")
    from rlcourse.preferences import render_segment

    frames = render_segment(load_hopper_preferences().obs[0][:3], size=48)
    assert frames.shape == (3, 48, 48, 3) and frames.dtype == np.uint8 and frames.std() > 0
