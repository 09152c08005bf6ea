"""hw3's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). What these return is raw data that the
tests judge on the grader's side.
"""
from contextlib import contextmanager

import numpy as np


@contextmanager
def _part_c_stand_ins():
    """The notebook's ``segment_return`` and ``preference_loss`` replaced, for the duration, by the docstrings' own
    one-liners (the sum over the last axis; torch's binary cross-entropy with logits), then put back.

    While train_reward_model and select_queries are tested, the grader's reference stands in for the stubs they call
    only on plain data, and these are called with networks and tensors that need gradients, so the student's own
    versions ran: a correct train_reward_model beside a missing preference_loss scored 0, a correct select_queries
    beside a missing segment_return 0/4. Both are made here, per call, so no test of those two stubs can reach them.
    """
    import torch

    def segment_return(reward_model, obs, act):
        return reward_model(obs, act).sum(dim=-1)

    def preference_loss(returns_a, returns_b, mu):
        d = returns_a - returns_b
        return torch.nn.functional.binary_cross_entropy_with_logits(d, torch.as_tensor(mu, dtype=d.dtype).expand_as(d))

    with standing_in(segment_return=segment_return, preference_loss=preference_loss):  # noqa: F821 - sandbox_common's
        yield


def run_train_reward_model(*args, **kwargs):
    """The submission's ``train_reward_model``, with the stand-ins of :func:`_part_c_stand_ins` for the stubs it calls."""
    with _part_c_stand_ins():
        return notebook["train_reward_model"](*args, **kwargs)  # noqa: F821


def run_select_queries(*args, **kwargs):
    """The submission's ``select_queries``, with the stand-ins of :func:`_part_c_stand_ins` for the stubs it calls."""
    with _part_c_stand_ins():
        return notebook["select_queries"](*args, **kwargs)  # noqa: F821


def run_rucb(env, horizon: int, seed: int, alpha: float = 0.51):
    """The submission's ``rucb`` on ``env`` (a lent environment) with ``np.random.default_rng(seed)``."""
    return notebook["rucb"](env, horizon, alpha, np.random.default_rng(seed))  # noqa: F821 - set by the worker
