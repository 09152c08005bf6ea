"""Hidden tests of hw3's Part C stubs: segment_return, preference_loss, train_reward_model."""
import numpy as np
import torch

from autograder.suite import check_tensor, stub

SR_HINT = ("Call reward_model(obs, act) and sum over the LAST axis (time): (B, L) -> (B,), "
           "(n_members, B, L) -> (n_members, B); torch only, so gradients flow.")
PL_HINT = ("-mean(mu * logsigmoid(Ra - Rb) + (1 - mu) * logsigmoid(Rb - Ra)) with torch.nn.functional.logsigmoid; "
           "return a 0-dim tensor that keeps the graph.")
TR_HINT = ("Bootstrap each member's pairs, Adam on preference_loss of segment_return under ensemble.member(k), "
           "then ensemble.normalise_ on the segments that appear in pairs.")
ENSEMBLE = "RewardEnsemble(11, 3, n_members=3, seed=seed)"
_CACHE = {}


def _segments(rng, b, length):
    return (torch.as_tensor(rng.normal(size=(b, length, 11)), dtype=torch.float32),
            torch.as_tensor(rng.uniform(-1, 1, size=(b, length, 3)), dtype=torch.float32))


@stub("segment_return", points=2, hint=SR_HINT)
def test_segment_return_ensemble(student, reference, rng):
    """An ensemble of 3 on 6 segments of 25 steps: (3, 6), summed over time"""
    obs, act = _segments(rng, 6, 25)
    got = student.segment_return(student.eval(ENSEMBLE, seed=5), obs, act)
    check_tensor(got, reference.segment_return(reference.eval(ENSEMBLE, seed=5), obs, act), rtol=1e-5, atol=1e-5)


@stub("segment_return", points=1, hint=SR_HINT)
def test_segment_return_single_member_other_lengths(student, reference, rng):
    """One member alone, one segment of 7 steps, and 4 segments of 1 step"""
    for b, length in ((1, 7), (4, 1)):
        obs, act = _segments(rng, b, length)
        expr = f"segment_return({ENSEMBLE}.member(2), obs, act)"
        check_tensor(student.eval(expr, seed=1, obs=obs, act=act), reference.eval(expr, seed=1, obs=obs, act=act),
                     rtol=1e-5, atol=1e-5, name=f"the returns of {b} segment(s) of {length} step(s)")


@stub("segment_return", points=1, hint=SR_HINT)
def test_segment_return_is_differentiable(student, rng):
    """The result keeps the autograd graph (no numpy, no detach)"""
    obs, act = _segments(rng, 3, 5)
    ok = student.eval(f"segment_return({ENSEMBLE}, obs, act).requires_grad", seed=0, obs=obs, act=act)
    assert ok is True, "the returned tensor does not require grad: compute it with torch operations only"


@stub("preference_loss", points=2, hint=PL_HINT)
def test_preference_loss_matches_reference(student, reference, rng):
    """Random returns and labels with ties"""
    ra, rb = torch.as_tensor(rng.normal(scale=3, size=40)), torch.as_tensor(rng.normal(scale=3, size=40))
    mu = torch.as_tensor(rng.choice([0.0, 0.5, 1.0], 40))
    got = student.preference_loss(ra, rb, mu)
    check_tensor(got, reference.preference_loss(ra, rb, mu), rtol=1e-6)
    assert got.dim() == 0, f"the loss should be a 0-dim tensor, got shape {tuple(got.shape)}"


@stub("preference_loss", points=1, hint=PL_HINT)
def test_preference_loss_stable(student):
    """Return differences of +-500 against the label: loss 500, not inf"""
    got = student.preference_loss(torch.tensor([500.0, 0.0]), torch.tensor([0.0, 500.0]), torch.tensor([0.0, 1.0]))
    check_tensor(got, torch.tensor(500.0), rtol=1e-6)


@stub("preference_loss", points=1, hint=PL_HINT)
def test_preference_loss_gradient(student, reference, rng):
    """Its gradient with respect to the first returns: (sigmoid(d) - mu) / B"""
    x, y, m = rng.normal(size=10), rng.normal(size=10), rng.choice([0.0, 0.5, 1.0], 10)
    expr = ("torch.autograd.grad(preference_loss((ra := torch.tensor(x, requires_grad=True)), torch.as_tensor(y), "
            "torch.as_tensor(m)), ra)[0]")
    check_tensor(student.eval(expr, x=x, y=y, m=m), reference.eval(expr, x=x, y=y, m=m), rtol=1e-6, atol=1e-9,
                 name="the gradient")


# The learner is trained and judged on segments made here, from a per-step reward the student never
# sees, with dimensions (7 and 2) that no shipped model accepts and no shipped file holds: neither
# the hw4 reward model nor the true rewards of the Hopper preference file can answer these tests.
OBS_DIM, ACT_DIM, STEPS, N_SEGMENTS, N_TEST_PAIRS = 7, 2, 12, 600, 1500


def _true_reward(obs, act):
    """The hidden per-step reward: a linear term, a bump and an action cost."""
    w = np.array([1.0, -0.6, 0.4, 0.0, 0.8, -0.3, 0.2])
    return obs @ w + 0.8 * np.tanh(2.0 * obs[..., 3]) - 0.5 * (act ** 2).sum(-1)


def _synthetic(seed=0):
    """Segments, their true returns, Bradley–Terry labelled training pairs, and held-out pairs."""
    if ("synthetic", seed) not in _CACHE:
        rng = np.random.default_rng(1000 + seed)
        obs = rng.normal(size=(N_SEGMENTS, STEPS, OBS_DIM))
        act = rng.uniform(-1, 1, size=(N_SEGMENTS, STEPS, ACT_DIM))
        returns = _true_reward(obs, act).sum(-1)
        scale = 3.0 / np.std(returns[:, None] - returns[None, :])  # labels informative, far from noiseless
        train = rng.choice(400, size=(900, 2))                    # the first 400 segments are for training
        train = train[train[:, 0] != train[:, 1]]
        p_first = 1 / (1 + np.exp(-scale * (returns[train[:, 0]] - returns[train[:, 1]])))
        mu = (rng.random(len(train)) < p_first).astype(float)
        test = 400 + rng.choice(N_SEGMENTS - 400, size=(N_TEST_PAIRS, 2))
        test = test[returns[test[:, 0]] != returns[test[:, 1]]]
        _CACHE["synthetic", seed] = (torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32),
                                     returns, train, mu, test)
    return _CACHE["synthetic", seed]


def _agreement(ensemble_handle, seed=0):
    """(share of held-out pairs the learned return orders as the true return does, learned held-out returns)."""
    obs, act, returns, _, _, test = _synthetic(seed)
    rewards = ensemble_handle.predict(obs, act)
    assert isinstance(rewards, np.ndarray) and rewards.shape[1:] == (N_SEGMENTS, STEPS), \
        f"train_reward_model must return the RewardEnsemble (predict gave {np.shape(rewards)})"
    learned = rewards.sum(-1).mean(0)
    right = np.sign(learned[test[:, 0]] - learned[test[:, 1]]) == np.sign(returns[test[:, 0]] - returns[test[:, 1]])
    return float(right.mean()), learned


def _train(ns, n_labels=800, n_members=2, seed=0, data_seed=0, n_steps=300):
    obs, act, _, train, mu, _ = _synthetic(data_seed)
    return ns.train_reward_model(obs, act, train[:n_labels], mu[:n_labels], n_members=n_members,
                                 n_steps=n_steps, seed=seed, timeout=120)


@stub("train_reward_model", points=3, hint=TR_HINT)
def test_reaches_reference_accuracy(student, reference):
    """800 labels of a hidden reward, 2 members, 300 steps: held-out pairs ordered within 0.04 of the reference"""
    if "ref_acc" not in _CACHE:
        _CACHE["ref_acc"] = _agreement(_train(reference))[0]
    acc, _ = _agreement(_train(student))
    assert acc >= _CACHE["ref_acc"] - 0.04, (f"the learned reward orders {acc:.3f} of held-out pairs as the hidden "
                                             f"reward does; the reference orders {_CACHE['ref_acc']:.3f}")


@stub("train_reward_model", points=1, hint=TR_HINT)
def test_learns_the_right_direction(student):
    """On another hidden-reward data set, the learned return correlates with the true return on held-out segments"""
    _, _, returns, _, _, _ = _synthetic(1)
    _, learned = _agreement(_train(student, n_labels=400, n_members=1, seed=1, data_seed=1), seed=1)
    r = np.corrcoef(learned[400:], returns[400:])[0, 1]
    assert r > 0.6, f"correlation with the true return is {r:.2f}: is the preferred segment's return pushed up?"


@stub("train_reward_model", points=1, hint="Call ensemble.normalise_(obs, act) on the segments used, after training.")
def test_members_normalised(student):
    """Three members, each with mean 0 and std 1 per step on the segments used"""
    obs, act, _, train, mu, _ = _synthetic(0)
    pairs = train[200:500]
    ens = student.train_reward_model(obs, act, pairs, mu[200:500], n_members=3, n_steps=50, seed=2, timeout=120)
    used = np.unique(pairs)
    rewards = ens.predict(obs[used], act[used])
    assert isinstance(rewards, np.ndarray) and rewards.shape[:2] == (3, len(used)), \
        f"expected rewards of shape (3, {len(used)}, {STEPS}) from a 3-member ensemble, got {np.shape(rewards)}"
    flat = rewards.reshape(3, -1)
    assert np.allclose(flat.mean(1), 0, atol=1e-3) and np.allclose(flat.std(1, ddof=1), 1, atol=1e-2), \
        f"per-member means {flat.mean(1).round(3)} and stds {flat.std(1).round(3)} should be 0 and 1"
