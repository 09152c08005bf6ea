"""Shared fixtures of hw1's hidden suite.

``with_reference`` evaluates a call of a student's stub while the stubs it builds on are
temporarily the reference's, so one broken stub costs only its own points (``train_bc`` is
checked with the reference ``bc_loss``; ``dagger`` with the reference ``train_bc``,
``bc_loss`` and ``relabel_with_expert``). ``trusted_copy`` rebuilds a policy from the sandbox
on the grader's side, from its constructor arguments and tensors only, so rollouts for scoring
never run student code.
"""
import pytest

from autograder.samples import solution_sources
from rlcourse.nets import GaussianPolicy

ASSIGNMENT = "hw1_imitation"
# Runs inside the sandbox: exec the reference definitions into the notebook's namespace, call, restore.
RUNNER = '''
def run_with(namespace, sources, names, thunk):
    saved = {name: namespace[name] for name in names if name in namespace}
    try:
        for source in sources:
            exec(source, namespace)
        return thunk()
    finally:
        for name in names:
            namespace.pop(name, None)
        namespace.update(saved)
'''
# `mean_return` is defined by the notebook's locked setup cell, so its globals are the notebook's namespace.
CALL = "(lambda d: (exec(_RUNNER, d), d['run_with'])[1])({})(mean_return.__globals__, _SOURCES, _NAMES, lambda: {call})"


@pytest.fixture
def with_reference(student):
    sources = solution_sources(ASSIGNMENT)

    def call(names: list[str], expr: str, timeout: float | None = None, **bindings):
        """Evaluate ``expr`` in the student's namespace with the reference's ``names`` swapped in."""
        return student.eval(CALL.replace("{call}", expr), timeout=timeout, _RUNNER=RUNNER,
                            _SOURCES=[sources[n] for n in names], _NAMES=list(names), **bindings)

    return call


@pytest.fixture
def trusted_copy(student):
    def copy(handle) -> GaussianPolicy:
        """The grader's own GaussianPolicy with the same constructor arguments and weights as ``handle``."""
        config = student.eval("dict(p.config)", p=handle)
        state = student.eval("{k: v.detach().clone() for k, v in p.state_dict().items()}", p=handle)
        assert isinstance(config, dict) and isinstance(state, dict), "the policy should be a GaussianPolicy"
        policy = GaussianPolicy(**config)
        policy.load_state_dict(state)
        return policy.eval()

    return copy
