"""hw3's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). What these return is raw data that the
tests judge on the grader's side.
"""
import numpy as np


def run_rucb(env, horizon: int, seed: int, alpha: float = 0.51):
    """The submission's ``rucb`` on ``env`` (a lent environment) with ``np.random.default_rng(seed)``."""
    return notebook["rucb"](env, horizon, alpha, np.random.default_rng(seed))  # noqa: F821 - set by the worker
