"""Hidden tests of hw1's `train_bc`, run with the library's Gaussian density standing in for the notebook's `bc_loss`
(``sandbox_helpers._bc_loss_stands_in``: the reference cannot stand in for a function of a network), so only the
training loop is judged: a correct train_bc beside a wrong or missing bc_loss lost 2 or 8 of its 8 points before."""
import numpy as np
import torch

from autograder.suite import check_array, stub
from rlcourse.nets import GaussianPolicy

HINT = ("Split off round(val_fraction * N) pairs with np.random.default_rng(seed); each epoch shuffle the rest, "
        "loop over minibatches (zero_grad, bc_loss, backward, step); record the epoch's mean training loss and the "
        "held-out loss; return {'train': [...], 'val': [...]}.")


def _linear_expert(rng, n):
    W = np.array([[1.2, -0.7, 0.4], [-0.5, 0.9, 1.5]])
    b, sigma = np.array([0.3, -0.8]), np.array([0.1, 0.3])
    obs = rng.normal(size=(n, 3))
    actions = obs @ W.T + b + sigma * rng.normal(size=(n, 2))
    return W, b, sigma, obs.astype(np.float32), actions.astype(np.float32)


def _train(student, obs, actions, hidden=(), policy_seed=0, **kwargs):
    """(policy handle, history) of the student's train_bc on a freshly built, seeded policy."""
    return student.helpers.train_fresh_policy(obs, actions, hidden=tuple(hidden), policy_seed=policy_seed, **kwargs)


def _initial_policy(obs_dim, act_dim, hidden=(), policy_seed=0):
    """The grader's copy of the policy ``sandbox_helpers.make_policy`` builds before training."""
    with torch.random.fork_rng():
        torch.manual_seed(policy_seed)
        return GaussianPolicy(obs_dim, act_dim, hidden=tuple(hidden)).eval()


def _mean_nll(policy, obs, actions):
    """The Gaussian negative log-likelihood averaged over all pairs, computed on the grader's side."""
    with torch.no_grad():
        obs, actions = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(actions, dtype=torch.float32)
        z = (actions - policy(obs)) * torch.exp(-policy.log_std)
        return float((0.5 * z**2 + policy.log_std + 0.5 * np.log(2 * np.pi)).sum(-1).mean())


def _pair_nll(policy, obs, actions):
    """The Gaussian negative log-likelihood of each pair, computed on the grader's side."""
    with torch.no_grad():
        obs, actions = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(actions, dtype=torch.float32)
        z = (actions - policy(obs)) * torch.exp(-policy.log_std)
        return (0.5 * z**2 + policy.log_std + 0.5 * np.log(2 * np.pi)).sum(-1).numpy().astype(np.float64)


def _history(hist, n_epochs):
    assert isinstance(hist, dict) and {"train", "val"} <= set(hist), \
        f"train_bc should return a dict with keys 'train' and 'val', got {type(hist).__name__}"
    for key in ("train", "val"):
        assert isinstance(hist[key], list) and len(hist[key]) == n_epochs, \
            f"history['{key}'] should be a list with one entry per epoch ({n_epochs}), got {hist[key]!r:.80}"
        assert all(isinstance(v, float) for v in hist[key]), f"history['{key}'] should hold Python floats"
    return np.array(hist["train"]), np.array(hist["val"])


@stub("train_bc", points=2, hint=HINT)
def test_recovers_a_linear_gaussian_expert(student, trusted_copy, rng):
    """A linear policy trained on 3,000 pairs from a linear-Gaussian expert finds its weights, bias and noise"""
    # 20 epochs of minibatches of 256 (220 steps; 40 epochs of 128 took 940): the reference over 60 draws of these
    # inputs is within 0.046 of the weights, 0.022 of the bias and 9.5% of the noise (allowed: 0.06, 0.06, 20%), at a
    # quarter of the CPU. Fewer pairs do not fit the tolerance: 600 pairs reach 0.060 on the weights.
    W, b, sigma, obs, actions = _linear_expert(rng, 3000)
    policy, hist = _train(student, obs, actions, n_epochs=20, batch_size=256, lr=3e-2, seed=0)
    _history(hist, 20)
    learned = trusted_copy(policy, 3, 2)
    check_array(learned.mean.weight.detach().numpy().astype(float), W, atol=0.06, rtol=0, name="the learned weights")
    check_array(learned.mean.bias.detach().numpy().astype(float), b, atol=0.06, rtol=0, name="the learned bias")
    check_array(learned.log_std.exp().detach().numpy().astype(float), sigma, rtol=0.2, atol=0,
                name="the learned standard deviations")


@stub("train_bc", points=1, hint=HINT)
def test_history_has_one_finite_entry_per_epoch(student, trusted_copy, rng):
    """One training and one validation loss per epoch, finite, and falling, as the policy's loss does"""
    _, _, _, obs, actions = _linear_expert(rng, 600)
    policy, hist = _train(student, obs, actions, hidden=(8,), n_epochs=7, batch_size=50, lr=1e-2, seed=1)
    train, val = _history(hist, 7)
    assert np.isfinite(train).all() and np.isfinite(val).all(), "the losses should be finite numbers"
    assert train[-1] < train[0] and val[-1] < val[0], "both losses should fall over the epochs"
    before, after = _mean_nll(_initial_policy(3, 2, (8,)), obs, actions), _mean_nll(trusted_copy(policy, 3, 2, (8,)), obs, actions)
    assert after < before, "the policy's loss on the data did not fall: train the policy in place (the history alone is not enough)"


@stub("train_bc", points=1, hint="Draw the split and every shuffle from np.random.default_rng(seed), so a seed fixes the run.")
def test_is_reproducible_under_a_seed(student, trusted_copy, rng):
    """The same seed gives the same history and weights; another seed gives another run"""
    _, _, _, obs, actions = _linear_expert(rng, 500)
    runs = [_train(student, obs, actions, hidden=(8,), n_epochs=3, batch_size=32, lr=1e-2, seed=s) for s in (4, 4, 5)]
    (p1, h1), (p2, h2), (p3, h3) = runs
    w1, w2, w3 = (trusted_copy(p, 3, 2, (8,)).mean.weight.detach().numpy() for p in (p1, p2, p3))
    check_array(w2, w1, rtol=0, atol=0, name="the weights of the second run with the same seed")
    assert h1 == h2, "two runs with the same seed (and the same initial policy) should give identical histories"
    assert not np.array_equal(w3, w1), "a different seed gave the same weights: it should hold out (and shuffle) differently"


@stub("train_bc", points=1, hint="Convert numpy inputs of any float dtype to float32 tensors; a last minibatch may be smaller; never modify the inputs.")
def test_small_float64_data_and_inputs_untouched(student, trusted_copy, rng):
    """Ten float64 pairs with a batch size of 256 train (the one short minibatch is used) and leave the arrays unchanged"""
    obs, actions = rng.normal(size=(10, 3)), rng.normal(size=(10, 2))
    keep = obs.copy(), actions.copy()
    hist, obs_after, actions_after = student.helpers.inputs_after_training(
        obs, actions, hidden=(4,), n_epochs=2, batch_size=256, val_fraction=0.2, seed=0)
    _history(hist, 2)
    check_array(obs_after, keep[0], rtol=0, atol=0, name="the observations after training")
    check_array(actions_after, keep[1], rtol=0, atol=0, name="the actions after training")
    policy, _ = _train(student, obs, actions, hidden=(4,), n_epochs=2, batch_size=256, lr=1e-2, val_fraction=0.2, seed=0)
    before = _initial_policy(3, 2, (4,)).mean.bias.detach().numpy()
    after = trusted_copy(policy, 3, 2, (4,)).mean.bias.detach().numpy()
    assert not np.array_equal(before, after), (
        "with 8 training pairs and batch_size = 256 the policy never changed: the last (here the only) minibatch "
        "may be smaller than batch_size and must still be trained on")


@stub("train_bc", points=1, hint="history['train'][e] is the mean of the per-pair training losses over epoch e's "
                                 "minibatches: sum loss * len(batch) over the epoch, divide by the number of training pairs.")
def test_reported_training_loss_is_the_epoch_mean(student, rng):
    """With lr = 0 the policy never moves, so the reported training and held-out losses must make up the loss of all pairs"""
    for n, batch_size, fraction in ((50, 10, 0.2), (10, 256, 0.2), (2, 256, 0.5)):
        _, _, _, obs, actions = _linear_expert(rng, n)
        _, hist = _train(student, obs, actions, hidden=(8,), n_epochs=2, batch_size=batch_size, lr=0.0, seed=3,
                         val_fraction=fraction)
        train, val = _history(hist, 2)
        n_val = round(fraction * n)
        whole = _mean_nll(_initial_policy(3, 2, (8,)), obs, actions)
        implied = (n * whole - n_val * val) / (n - n_val)   # the training-pairs' mean loss the held-out loss implies
        where = f"{n} pairs, val_fraction {fraction}, batch_size {batch_size}"
        assert np.isfinite(val).all(), f"the held-out losses should be finite numbers ({where})"
        for e in range(2):
            if not np.isclose(train[e], implied[e], rtol=1e-4, atol=1e-4):
                direction = "too large" if train[e] > implied[e] else "too small"
                assert False, (f"history['train'][{e}] is {direction} ({where}, lr = 0 so the policy never changes): "
                               "it should be the mean loss per training pair over the epoch's minibatches (each batch's "
                               "mean loss weighted by its size, divided by the number of training pairs); a sum, a "
                               "total that does not start at 0, or a skipped short minibatch all break it")


@stub("train_bc", points=1, hint="With val_fraction = 0 nothing is held out: record float('nan') as the validation loss and train on everything.")
def test_no_validation_split(student, trusted_copy, rng):
    """val_fraction = 0: validation entries are NaN and training still works"""
    _, _, _, obs, actions = _linear_expert(rng, 300)
    policy, hist = _train(student, obs, actions, n_epochs=4, batch_size=64, lr=3e-2, seed=0, val_fraction=0.0)
    train, val = _history(hist, 4)
    assert np.isnan(val).all(), "with nothing held out the validation losses should be NaN"
    assert train[-1] < train[0], "the training loss should fall"
    before, after = _mean_nll(_initial_policy(3, 2), obs, actions), _mean_nll(trusted_copy(policy, 3, 2), obs, actions)
    assert after < before - 0.5, "with val_fraction = 0 the policy's loss on the data barely fell: train on every pair"


@stub("train_bc", points=1, hint="Never train on the held-out pairs: split once before the first epoch, and shuffle only the training part.")
def test_validation_pairs_are_held_out(student, trusted_copy, rng):
    """On unpredictable labels a large network memorises its training pairs and not the 20 held-out ones"""
    obs, actions = rng.normal(size=(40, 3)).astype(np.float32), rng.normal(size=(40, 2)).astype(np.float32)
    policy, hist = _train(student, obs, actions, hidden=(64, 64), n_epochs=150, batch_size=64, lr=1e-2, seed=0,
                          val_fraction=0.5)
    train, val = _history(hist, 150)
    losses = np.sort(_pair_nll(trusted_copy(policy, 3, 2, (64, 64)), obs, actions))
    fitted, unseen = losses[:20].mean(), losses[20:].mean()
    # The reference over 30 draws of these inputs: unseen - fitted >= 21.6, val[-1] within 0.1% of unseen, train[-1]
    # within 0.84 x (0.3 + 0.2 |fitted|) of fitted; not holding out: a gap of about 0.2
    assert unseen > fitted + 2.0, ("the trained policy fits all 40 pairs about equally well: the 20 held-out pairs "
                                   "were trained on (split once before the first epoch; shuffle only the training part)")
    assert np.isclose(val[-1], unseen, rtol=1e-2, atol=1e-2), \
        "history['val'][-1] is not the policy's mean loss on the pairs it never fit (the held-out pairs after the last epoch)"
    assert np.isclose(train[-1], fitted, rtol=0.3, atol=0.6), \
        "history['train'][-1] is far from the policy's mean loss on its training pairs"
