"""hw5's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). What these return is raw data that the
tests judge on the grader's side.
"""


def run_best_of_n(models, prompts, n: int):
    """The submission's ``best_of_n`` with the lent ``models``' ``generate`` and ``reward`` (each call runs in
    the grader, which keeps its own record of the candidates it generated)."""
    return notebook["best_of_n"](models.generate, models.reward, prompts, n)  # noqa: F821 - set by the worker
