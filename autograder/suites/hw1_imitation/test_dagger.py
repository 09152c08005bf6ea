"""Hidden tests of hw1's `dagger`, on the race track, checked against rollouts computed on the grader's side.

In the learning test the student's `dagger` runs beside its own `train_bc` (a network cannot cross to the
reference's); elsewhere a lent stand-in that trains nothing replaces it. The library's density stands in for the
notebook's `bc_loss` (``sandbox_helpers._bc_loss_stands_in``) and the grader's labels, lent, for its
`relabel_with_expert`, so a mistake in those stubs costs them alone. Most checks judge what training does not change
(the untrained learner's rollouts, the expert's at beta = 1, the labels). Every rollout that a check relies on is
recomputed here, with the trusted environment, the trusted expert and a trusted copy of the learner's weights.
"""
import numpy as np
import torch

from autograder.suite import check_array, check_scalar, lend, stub
from rlcourse import racetrack
from rlcourse.imitation import Demonstrations
from rlcourse.nets import GaussianPolicy
from rlcourse.rollouts import rollout

HINT = ("Per iteration i: MixturePolicy(expert.act, policy.act, beta_schedule[i], rng) with one rng = "
        "np.random.default_rng(seed); rollout(mixture, env_id, episodes_per_iter, seed=seed + i * episodes_per_iter); "
        "add the real steps (episodes.obs[episodes.mask]) with the EXPERT's labels; retrain with train_bc(..., seed=seed + i).")
EXPERT = racetrack.Expert()
_CACHE = {}


def _demo():
    if "demo" not in _CACHE:
        _CACHE["demo"] = Demonstrations.from_episodes(rollout(EXPERT.act, racetrack.ENV_ID, 1, seed=100))
    return _CACHE["demo"]


def _initial_learner(policy_seed):
    """The grader's copy of the learner ``sandbox_helpers.run_dagger`` starts from."""
    with torch.random.fork_rng():
        torch.manual_seed(policy_seed)
        return GaussianPolicy(4, 1, hidden=(16,)).eval()


def _run(student, betas, episodes=2, seed=0, policy_seed=0, hidden=(16,), state=None, timeout=None, trainer=None,
         **train):
    """The student's (policy, history) for a DAgger run on the race track, from a GaussianPolicy(4, 1, hidden)
    seeded ``policy_seed`` (or with the weights ``state``); with ``trainer`` (a ``_Trainer``), its train_bc replaced
    by the stand-in that trains nothing and loads the weights the trainer plants."""
    demo = _demo()
    train = {"n_epochs": 3, "batch_size": 64, "lr": 3e-3, **train}
    labeller = lend(_Labeller(), methods=["labels"])
    if trainer is None:
        result = student.helpers.run_dagger(list(betas), demo.obs, demo.actions, episodes, seed, policy_seed=policy_seed,
                                            hidden=tuple(hidden), state=state, labeller=labeller, timeout=timeout, **train)
    else:
        assert state is None, "suite error: the stand-in run starts from a seeded learner"
        result = student.helpers.run_dagger_with_stand_in(lend(trainer, methods=["train"]), list(betas), demo.obs,
                                                          demo.actions, episodes, seed, policy_seed=policy_seed,
                                                          hidden=tuple(hidden), labeller=labeller, timeout=timeout,
                                                          **train)
    assert isinstance(result, tuple) and len(result) == 2, "dagger should return (policy, history)"
    policy, hist = result
    assert isinstance(hist, dict) and {"returns", "dataset_sizes", "obs", "actions"} <= set(hist), \
        "history should be a dict with 'returns', 'dataset_sizes', 'obs' and 'actions'"
    for key, kind in (("returns", "f"), ("dataset_sizes", "iu"), ("obs", "f"), ("actions", "f")):
        value = hist[key]
        assert isinstance(value, np.ndarray) and value.dtype.kind in kind, \
            f"history['{key}'] should be a numpy array of {'integers' if kind == 'iu' else 'floats'}, got {type(value).__name__}"
    assert hist["returns"].shape == hist["dataset_sizes"].shape == (len(betas),), \
        f"one return and one data-set size per iteration ({len(betas)}), got shapes {hist['returns'].shape}, {hist['dataset_sizes'].shape}"
    return policy, hist


class _Labeller:
    """The race-track expert's labels, lent to the sandbox to stand in for the notebook's relabel_with_expert while
    dagger is tested (the grader's reference cannot take an expert object, so the student's own would run)."""

    def labels(self, obs):
        obs = np.asarray(obs, dtype=np.float32)
        return EXPERT.act(obs.reshape(-1, obs.shape[-1])).reshape(obs.shape[:-1] + (1,)).astype(np.float32)


def _rows(a):
    """Rows of a 2-d array in a canonical order (so an equally valid order of visited states compares equal)."""
    a = np.asarray(a, dtype=np.float64)
    return a[np.lexsort(a.T[::-1])]


@stub("dagger", points=2, hint=HINT)
def test_beta_zero_rolls_out_the_learner_and_adds_its_real_steps(student):
    """beta = 0: the rollouts are the initial learner's, and exactly its real steps are added, with expert labels"""
    demo, seed = _demo(), 5
    # train_bc replaced by the stand-in: only what is rolled out before training is judged (the student's own
    # train_bc, missing or wrong, cost this test before)
    _, hist = _run(student, [0.0], episodes=3, seed=seed, policy_seed=1, trainer=_Trainer([_planted(71)[0]]))
    own = rollout(_initial_learner(1).act, racetrack.ENV_ID, 3, seed=seed)
    check_scalar(hist["returns"][0], float(own.returns.mean()), rtol=1e-4,
                 name="the first iteration's mean return (the untrained learner's own episodes)")
    n_new = int(own.lengths.sum())
    got_size = int(hist["dataset_sizes"][0])
    assert got_size == len(demo.obs) + n_new, (
        f"after one iteration the data set should hold the {len(demo.obs)} demonstration pairs plus the real steps of "
        f"the rollouts; it holds {'more' if got_size > len(demo.obs) + n_new else 'fewer'} pairs than that "
        "(padding after an episode ends is not a step; every real step counts once)")
    check_array(_rows(hist["obs"][len(demo.obs):]), _rows(own.obs[own.mask]), rtol=1e-5, atol=1e-6,
                name="the states added in the first iteration (the learner's visited states)")


@stub("dagger", points=2, hint="Label the visited states with the expert's actions (relabel_with_expert), never with the actions that were taken.")
def test_every_label_is_the_experts_action(student):
    """With a mixture and an untrained learner, every label in the data set is the expert's action at its state"""
    demo = _demo()
    # train_bc replaced by the stand-in (the labels do not depend on what the learner becomes)
    _, hist = _run(student, [0.5, 0.0, 0.0], episodes=2, seed=1, policy_seed=2,
                   trainer=_Trainer([_planted(72 + k)[0] for k in range(3)]))
    assert hist["obs"].ndim == 2 and hist["obs"].shape[1] == 4 and hist["actions"].shape == (len(hist["obs"]), 1), \
        f"the data set should be (N, 4) states and (N, 1) labels, got {hist['obs'].shape} and {hist['actions'].shape}"
    check_array(hist["obs"][:len(demo.obs)], demo.obs, rtol=0, atol=0, name="the first rows of the data set (the demonstrations)")
    assert len(hist["obs"]) > len(demo.obs), "the data set holds only the demonstrations: add the states each iteration visits"
    check_array(hist["actions"], EXPERT.act(hist["obs"]), rtol=1e-5, atol=1e-6, name="the labels of the aggregated data set")


@stub("dagger", points=2, hint=HINT)
def test_follows_the_beta_schedule(student):
    """Schedule [0, 1, 1]: iteration 0 drives the learner, iterations 1 and 2 are exactly the expert's seeded episodes"""
    # train_bc replaced by the stand-in (what is rolled out does not depend on what training does with the data)
    seed, episodes = 2, 2
    _, hist = _run(student, [0.0, 1.0, 1.0], episodes=episodes, seed=seed, policy_seed=3,
                   trainer=_Trainer([_planted(70)[0]]))
    learner = rollout(_initial_learner(3).act, racetrack.ENV_ID, episodes, seed=seed)
    check_scalar(hist["returns"][0], float(learner.returns.mean()), rtol=1e-4,
                 name="iteration 0's mean return (beta = beta_schedule[0] = 0: the learner drives)")
    sizes = [len(_demo().obs) + int(learner.lengths.sum())]
    for i in (1, 2):
        expert = rollout(EXPERT.act, racetrack.ENV_ID, episodes, seed=seed + i * episodes)
        check_scalar(hist["returns"][i], float(expert.returns.mean()), rtol=1e-4,
                     name=f"iteration {i}'s mean return (beta = 1: the expert's episodes seeded {seed + i * episodes}, ...)")
        sizes.append(sizes[-1] + int(expert.lengths.sum()))
    check_array(hist["dataset_sizes"], np.array(sizes), rtol=0, atol=0,
                name="the data-set sizes after each iteration (only real steps count: padding after an episode ends is not a step)")
    assert len(hist["obs"]) == sizes[-1], "history['obs'] should be the whole aggregated data set"


class _Trainer:
    """A stand-in for train_bc, lent to the sandbox: it trains nothing, keeps the grader's own record of the data
    set each call was given, and answers with the weights the learner is to have next (planted by the test)."""

    def __init__(self, plan) -> None:
        self.plan, self.calls = plan, []

    def train(self, obs, actions, kwargs):
        self.calls.append((np.array(obs, dtype=np.float64), np.array(actions, dtype=np.float64), dict(kwargs)))
        return self.plan[min(len(self.calls), len(self.plan)) - 1]


def _planted(seed):
    """A learner's weights the grader chooses (as numpy arrays), and the grader's policy with them."""
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        policy = GaussianPolicy(4, 1, hidden=(16,)).eval()
    return {k: v.detach().numpy().copy() for k, v in policy.state_dict().items()}, policy


@stub("dagger", points=2, hint="Every iteration: roll out the CURRENT learner (mixed with the expert), add the visited "
                               "states with the expert's labels to the data set (demonstrations first, nothing dropped), "
                               "then call train_bc(policy, dataset.obs, dataset.actions, seed=seed + i, **train_kwargs).")
def test_retrains_on_the_aggregate_and_rolls_out_the_retrained_learner(student, trusted_copy):
    """With train_bc replaced by a stand-in: each iteration trains once on everything aggregated so far, and the
    next rolls out the learner it left"""
    demo, seed, episodes = _demo(), 3, 2
    plan = [_planted(60 + i) for i in range(3)]
    trainer = _Trainer([state for state, _ in plan])
    result = student.helpers.run_dagger_with_stand_in(lend(trainer, methods=["train"]), [0.0, 0.0, 0.0], demo.obs,
                                                      demo.actions, episodes, seed, policy_seed=5, hidden=(16,),
                                                      labeller=lend(_Labeller(), methods=["labels"]), n_epochs=3,
                                                      batch_size=64, lr=3e-3)
    calls = trainer.calls
    assert len(calls) == 3, f"dagger should call train_bc once per iteration (3), it called it {len(calls)} times"
    drivers = [_initial_learner(5)] + [policy for _, policy in plan[:2]]
    data_obs, returns = demo.obs.astype(np.float64), []
    for i, ((obs, actions, kwargs), driver) in enumerate(zip(calls, drivers)):
        episodes_i = rollout(driver.act, racetrack.ENV_ID, episodes, seed=seed + i * episodes)
        returns.append(float(episodes_i.returns.mean()))
        visited = episodes_i.obs[episodes_i.mask]
        who = "the initial learner" if i == 0 else f"the learner as train_bc left it after iteration {i - 1}"
        assert obs.ndim == 2 and obs.shape[1] == 4 and actions.shape == (len(obs), 1), \
            f"train_bc's call {i} got states of shape {obs.shape} and labels of shape {actions.shape}: expected (N, 4), (N, 1)"
        assert len(obs) == len(data_obs) + len(visited), (
            f"train_bc's call {i} got {len(obs)} pairs; it should get the whole aggregated data set: the "
            f"{len(data_obs)} pairs before iteration {i} plus the real steps of {who}'s {episodes} episodes")
        check_array(obs[:len(data_obs)], data_obs, rtol=0, atol=0,
                    name=f"the first rows of train_bc's call {i} (everything aggregated before iteration {i}, in order)")
        check_array(_rows(obs[len(data_obs):]), _rows(visited), rtol=1e-5, atol=1e-6,
                    name=f"the states added in iteration {i} (those {who} visited)")
        check_array(actions, EXPERT.act(obs), rtol=1e-5, atol=1e-6, name=f"the labels of train_bc's call {i}")
        assert kwargs.get("seed") == seed + i, f"train_bc's call {i} should get seed = seed + i = {seed + i}"
        for key, value in (("n_epochs", 3), ("batch_size", 64), ("lr", 3e-3)):
            assert kwargs.get(key) == value, f"train_bc's call {i} should get {key}={value} (dagger's own **train_kwargs)"
        data_obs = obs
    assert isinstance(result, tuple) and len(result) == 2, "dagger should return (policy, history)"
    policy, hist = result
    check_array(np.asarray(hist["returns"], dtype=np.float64), np.array(returns), rtol=1e-4, atol=1e-6,
                name="history['returns'] (the mean return of each iteration's own episodes)")
    got = trusted_copy(policy, 4, 1, (16,)).state_dict()
    want = plan[-1][0]
    assert all(np.array_equal(got[k].numpy(), want[k]) for k in want), \
        "the returned policy should be the learner train_bc trained in place in the last iteration"


@stub("dagger", points=1, hint="Create one np.random.default_rng(seed) for the mixture and seed rollouts and training from `seed`.")
def test_reproducible_under_a_seed(student):
    """Two runs with the same seed and initial learner give the same returns and data set; another seed another run"""
    # train_bc replaced by the stand-in, which plants the same learner for the second iteration in every run: what is
    # judged is dagger's own randomness (the mixture's generator and the rollouts' seeds); that train_bc gets
    # seed + i is test_retrains_on_the_aggregate_and_rolls_out_the_retrained_learner's.
    def run(seed):
        return _run(student, [0.5, 0.5], episodes=2, seed=seed, policy_seed=4, trainer=_Trainer([_planted(80)[0]]))[1]

    first, second = run(7), run(7)
    check_array(second["returns"], first["returns"], rtol=0, atol=0, name="the returns of the second run")
    check_array(second["obs"], first["obs"], rtol=0, atol=0, name="the data set of the second run")
    other = run(8)
    assert other["obs"].shape != first["obs"].shape or not np.array_equal(other["obs"], first["obs"]), \
        "a different seed gave the same data set: seed the rollouts and the mixture from `seed`"


@stub("dagger", points=2, hint=HINT + " This test trains with your own train_bc.")
def test_learns_to_drive(student, reference, trusted_copy):
    """Six iterations from a clone of one demonstration: the learner then stays on the track like the expert"""
    # The suite's one learning test of dagger, on the smallest instance that still separates (two episodes an
    # iteration; four cost twice the time; fewer iterations, fewer epochs, a larger batch or learning rate, or one
    # episode an iteration each left the reference short of the expert on one seed in five): the reference reaches 99
    # to 100% of the expert from dagger seeds 0 to 7 (five episodes scored), the clone alone 8%. The clone: 30 epochs
    # at lr 1e-2 (a third of the 100 at 3e-3 it had, for the same DAgger result).
    demo = _demo()   # the clone is trained on the grader's side, by the reference train_bc, and handed over as weights
    clone, _ = reference.helpers.train_fresh_policy(demo.obs, demo.actions, hidden=(64, 64), policy_seed=0, n_epochs=30,
                                                    batch_size=64, lr=1e-2, seed=0)
    policy, hist = _run(student, [0.0] * 6, episodes=2, seed=0, hidden=(64, 64),
                        state=reference.helpers.module_state(clone), n_epochs=50, timeout=120)
    expert = rollout(EXPERT.act, racetrack.ENV_ID, 5, seed=1000).returns.mean()
    got = rollout(trusted_copy(policy, 4, 1, (64, 64)).act, racetrack.ENV_ID, 5, seed=1000).returns.mean()
    assert got >= 0.8 * expert, (f"after six iterations the learner earns about {round(100 * got / expert, -1):.0f}% of the "
                                 "expert's return on the grader's episodes; the reference reaches the expert's level "
                                 "(at least 80% is needed)")
