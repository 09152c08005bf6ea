"""Shared fixtures of hw1's hidden suite.

``in_sandbox`` evaluates an expression that calls a student's stub in the student's namespace.
While a stub is tested, the grader runs the stubs it calls as the reference wherever the call's
arguments are plain data; ``train_bc`` and ``dagger`` pass networks to ``bc_loss`` and
``train_bc``, so those calls use the student's own versions. ``trusted_copy`` rebuilds a policy
from the sandbox on the grader's side, from its constructor arguments and tensors only, so
rollouts for scoring never run student code.
"""
import pytest

from rlcourse.nets import GaussianPolicy


@pytest.fixture
def in_sandbox(student):
    def call(expr: str, timeout: float | None = None, **bindings):
        """Evaluate ``expr`` in the student's namespace with ``bindings`` as local names."""
        return student.eval(expr, timeout=timeout, **bindings)

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
