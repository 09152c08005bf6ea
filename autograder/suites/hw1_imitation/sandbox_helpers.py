"""hw1's suite helpers: run in the sandbox, beside the submission, after all its cells.

Trusted code the tests call as ``student.helpers.<name>(...)`` (and ``reference.helpers``): it
builds objects that cannot cross the channel, in ordinary Python instead of expressions in
strings. Student code can read this module, so it holds nothing a student may not see, and can
patch what it runs on, so what it returns is raw data the tests judge on the grader's side.
``notebook`` is the submission's namespace (set by the worker); the helpers common to every suite
(``autograder/suites/sandbox_common.py``) run before this file, in the same module.
"""
from contextlib import contextmanager

import numpy as np
import torch

from rlcourse import data, racetrack
from rlcourse.nets import GaussianPolicy


def _library_bc_loss(policy, obs, actions):
    """bc_loss by the library's own density, as the public check states it: the grader's reference cannot stand in
    for a function of a network (it cannot cross), so this one does, while train_bc and dagger are tested."""
    return -policy.log_prob(obs, actions).mean()


@contextmanager
def _bc_loss_stands_in():
    """The notebook's ``bc_loss`` replaced by :func:`_library_bc_loss` for the duration (put back afterwards): a
    mistake in bc_loss costs bc_loss alone, not the train_bc and dagger that call it."""
    with standing_in(bc_loss=_library_bc_loss):  # noqa: F821 - sandbox_common's, same module
        yield


@contextmanager
def _relabel_stands_in(labeller):
    """The notebook's ``relabel_with_expert`` replaced, for the duration, by ``labeller.labels`` (an object the
    grader lends: the race-track expert's actions, computed in the grader), then put back. The grader's reference
    cannot stand in for a function of an expert object (it cannot cross), so without this a correct dagger beside a
    missing relabel_with_expert scored 0/11. Nothing here computes a label: asked to label with anything but the race
    expert dagger was given (the learner, say), it calls the notebook's own relabel_with_expert, as before."""
    own = notebook.get("relabel_with_expert")  # noqa: F821 - set by the worker; the notebook's, before the swap

    def relabel_with_expert(expert, obs):
        if isinstance(expert, racetrack.Expert):
            return np.asarray(labeller.labels(np.asarray(obs, dtype=np.float32)), dtype=np.float32)
        if own is None:
            raise NameError("name 'relabel_with_expert' is not defined")
        return own(expert, obs)

    with standing_in(relabel_with_expert=relabel_with_expert):  # noqa: F821 - sandbox_common's, same module
        yield


def make_policy(obs_dim: int, act_dim: int, hidden: tuple[int, ...] = (), seed: int = 0, state=None,
                **kwargs) -> GaussianPolicy:
    """A freshly initialised GaussianPolicy, its weights drawn under ``seed`` (or loaded from ``state``)."""
    torch.manual_seed(seed)
    policy = GaussianPolicy(obs_dim, act_dim, hidden=tuple(hidden), **kwargs)
    if state is not None:
        policy.load_state_dict(state)
    return policy


def train_fresh_policy(obs, actions, hidden: tuple[int, ...] = (), policy_seed: int = 0, **train_kwargs):
    """(policy, history) of the submission's ``train_bc`` on a fresh seeded policy."""
    policy = make_policy(obs.shape[1], actions.shape[1], hidden, policy_seed)
    with _bc_loss_stands_in():
        return policy, notebook["train_bc"](policy, obs, actions, **train_kwargs)  # noqa: F821 - set by the worker


def inputs_after_training(obs, actions, hidden: tuple[int, ...] = (), policy_seed: int = 0, **train_kwargs):
    """(history, obs, actions) after the submission's ``train_bc``: the arrays as it left them."""
    _, history = train_fresh_policy(obs, actions, hidden, policy_seed, **train_kwargs)
    return history, obs, actions


class FormulaOnlyPolicy(GaussianPolicy):
    """A GaussianPolicy without its own log-density: the notebook asks ``bc_loss`` to write the formula from
    ``policy(obs)`` and ``policy.log_std``, and ``-policy.log_prob(obs, actions).mean()`` would be the whole stub."""

    def distribution(self, obs):
        raise RuntimeError("bc_loss should compute the Gaussian negative log-likelihood itself, from policy(obs) "
                           "and policy.log_std, not with policy.log_prob or policy.distribution")

    def log_prob(self, obs, actions):
        return self.distribution(obs)


def bc_policy(seed: int, obs_dim: int, act_dim: int, log_std, hidden: tuple[int, ...] = (16, 16),
              bias_shift=None) -> GaussianPolicy:
    """A seeded policy for bc_loss's tests, with the given log_std (and ``bias_shift`` added to the mean's
    bias), whose log_prob and distribution raise."""
    torch.manual_seed(seed)
    policy = FormulaOnlyPolicy(obs_dim, act_dim, hidden=tuple(hidden))
    with torch.no_grad():
        policy.log_std.copy_(torch.as_tensor(log_std, dtype=torch.float32))
        if bias_shift is not None:
            policy.mean.bias.add_(torch.as_tensor(bias_shift, dtype=torch.float32))
    return policy


def expert(name: str):
    """A released expert: ``"hopper"`` (Hopper-v5's, from the data folder) or ``"race"`` (the race track's)."""
    if name == "hopper":
        return data.load_policy("experts/Hopper-v5/expert.pt")
    if name == "race":
        return racetrack.Expert()
    raise ValueError(f"no expert {name!r}")


def run_dagger(betas, obs, actions, episodes: int, seed: int, policy_seed: int = 0, hidden=(16,), state=None,
               labeller=None, **train_kwargs):
    """The submission's ``dagger`` on the race track with its expert, from a learner GaussianPolicy(4, 1, hidden)
    seeded ``policy_seed`` (or loaded from ``state``): its (policy, history). With ``labeller`` (lent by the grader),
    the grader's labels stand in for the notebook's relabel_with_expert."""
    learner = make_policy(racetrack.OBS_DIM, 1, tuple(hidden), policy_seed, state=state)
    with _bc_loss_stands_in():
        if labeller is None:
            return notebook["dagger"](racetrack.ENV_ID, racetrack.Expert(), learner, len(betas),  # noqa: F821
                                      list(betas), obs, actions, episodes_per_iter=episodes, seed=seed, **train_kwargs)
        with _relabel_stands_in(labeller):
            return notebook["dagger"](racetrack.ENV_ID, racetrack.Expert(), learner, len(betas),  # noqa: F821
                                      list(betas), obs, actions, episodes_per_iter=episodes, seed=seed, **train_kwargs)


def run_dagger_with_stand_in(trainer, betas, obs, actions, episodes: int, seed: int, policy_seed: int = 0,
                             hidden=(16,), labeller=None, **train_kwargs):
    """``run_dagger`` with the notebook's ``train_bc`` replaced, for this call, by a stand-in that trains nothing:
    it hands the data set it is given to ``trainer`` (an object lent by the grader, which keeps its own record of
    every call) and loads into the learner the weights the grader answers with. The notebook's ``train_bc`` is put
    back afterwards."""
    def stand_in(policy, obs, actions, **kwargs):
        plain = {k: v for k, v in kwargs.items() if isinstance(v, (bool, int, float, str))}
        state = trainer.train(np.asarray(obs, dtype=np.float64), np.asarray(actions, dtype=np.float64), plain)
        with torch.no_grad():
            for name, value in policy.state_dict().items():
                value.copy_(torch.as_tensor(state[name], dtype=value.dtype))
        n = int(kwargs.get("n_epochs", 20))
        return {"train": [0.0] * n, "val": [float("nan")] * n}

    saved = notebook["train_bc"]  # noqa: F821 - set by the worker
    notebook["train_bc"] = stand_in  # noqa: F821
    try:
        return run_dagger(betas, obs, actions, episodes, seed, policy_seed=policy_seed, hidden=hidden, labeller=labeller,
                          **train_kwargs)
    finally:
        notebook["train_bc"] = saved  # noqa: F821
