"""Shared fixtures of hw1's hidden suite.

``trusted_copy`` rebuilds a policy from the sandbox on the grader's side: the grader's own
GaussianPolicy, of the architecture the test gave the stub (never a configuration the sandbox
reports), loaded with the tensors of the sandbox's policy, so rollouts and losses for scoring never
run student code.
"""
import pytest
import torch

from rlcourse.nets import GaussianPolicy


@pytest.fixture
def trusted_copy(student):
    def copy(handle, obs_dim: int, act_dim: int, hidden=(), **kwargs) -> GaussianPolicy:
        """The grader's GaussianPolicy(obs_dim, act_dim, hidden, **kwargs) with the weights of ``handle``."""
        with torch.random.fork_rng():
            policy = GaussianPolicy(obs_dim, act_dim, hidden=tuple(hidden), **kwargs)
        want = policy.state_dict()
        state = student.helpers.module_state(handle)
        assert isinstance(state, dict) and set(state) == set(want), (
            f"the policy should be the GaussianPolicy({obs_dim}, {act_dim}, hidden={tuple(hidden)}) it was given, "
            "trained in place (its parameters are not those of that network)")
        for key, value in want.items():
            assert type(state[key]) is torch.Tensor and state[key].shape == value.shape, \
                f"the policy's `{key}` has shape {tuple(getattr(state[key], 'shape', ()))}, expected {tuple(value.shape)}"
        policy.load_state_dict(state)
        return policy.eval()

    return copy
