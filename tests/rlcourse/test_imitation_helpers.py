"""rlcourse.imitation: demonstrations, the expert/learner mixture, the aggregated data set, the normalised policy."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from rlcourse import data
from rlcourse.imitation import AggregatedDataset, Demonstrations, MixturePolicy, NormalisedPolicy
from rlcourse.nets import GaussianPolicy
from rlcourse.rollouts import rollout


class Constant:
    """A policy that answers a constant action and counts the states it was asked about."""

    def __init__(self, value: float) -> None:
        self.value, self.asked = value, 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.asked += len(obs)
        return np.full((len(obs), 2), self.value, dtype=np.float32)


@pytest.mark.parametrize("beta", [0.0, 1.0])
def test_mixture_extremes_ask_only_one_policy(beta):
    expert, learner = Constant(1.0), Constant(-1.0)
    mix = MixturePolicy(expert, learner, beta, np.random.default_rng(0))
    actions = mix(np.zeros((50, 3)))
    assert np.all(actions == (1.0 if beta else -1.0))
    assert (expert.asked, learner.asked) == ((50, 0) if beta else (0, 50))
    assert mix.n_expert_steps == expert.asked and mix.n_steps == 50


def test_mixture_chooses_per_state_with_probability_beta_and_is_seeded():
    expert, learner = Constant(1.0), Constant(-1.0)
    mix = MixturePolicy(expert, learner, 0.3, np.random.default_rng(1))
    actions = np.concatenate([mix(np.zeros((100, 3))) for _ in range(50)])
    chose_expert = actions[:, 0] == 1.0
    assert np.all(actions[:, 1] == actions[:, 0]), "a state gets one policy's whole action"
    assert abs(chose_expert.mean() - 0.3) < 0.03 and mix.n_expert_steps == chose_expert.sum()
    again = MixturePolicy(Constant(1.0), Constant(-1.0), 0.3, np.random.default_rng(1))
    assert np.array_equal(np.concatenate([again(np.zeros((100, 3))) for _ in range(50)]), actions)
    with pytest.raises(ValueError):
        MixturePolicy(expert, learner, 1.5, np.random.default_rng(0))


def test_aggregated_dataset_appends_copies_in_order():
    obs, act = np.ones((3, 4)), np.zeros((3, 2))
    dataset = AggregatedDataset(obs, act)
    obs[:] = 7.0  # the data set keeps its own copy
    dataset.add(np.full((2, 4), 2.0), np.full((2, 2), 5.0))
    assert len(dataset) == 5 and dataset.obs.dtype == np.float32
    assert np.all(dataset.obs[:3] == 1.0) and np.all(dataset.obs[3:] == 2.0) and np.all(dataset.actions[3:] == 5.0)
    with pytest.raises(ValueError):
        dataset.add(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError):
        dataset.add(np.zeros((2, 4)), np.zeros((3, 2)))


def test_demonstrations_flatten_episodes_and_take_the_first_ones():
    episodes = rollout(lambda o: np.zeros((len(o), 3), dtype=np.float32), "Hopper-v5", 3, seed=0)
    demos = Demonstrations.from_episodes(episodes)
    assert len(demos.obs) == episodes.lengths.sum() == demos.lengths.sum()
    assert np.allclose(demos.returns, episodes.returns, rtol=1e-5)
    two = demos.first(2)
    assert two.n_episodes == 2 and len(two.obs) == episodes.lengths[:2].sum()
    assert np.array_equal(two.obs[episodes.lengths[0]], episodes.obs[1, 0])
    with pytest.raises(ValueError):
        demos.first(4)


def test_shipped_hopper_demonstrations_load_and_match_their_manifest_entry():
    demos = Demonstrations.load("demos/Hopper-v5.npz")
    entry = data.info("demos/Hopper-v5.npz")
    assert demos.n_episodes == entry["info"]["episodes"] and len(demos.obs) == demos.lengths.sum() == entry["info"]["steps"]
    assert demos.obs.shape[1] == 11 and demos.actions.shape[1] == 3
    assert abs(demos.returns.mean() - entry["info"]["return_mean"]) < 1.0


def test_normalised_policy_standardises_its_input():
    rng = np.random.default_rng(0)
    obs = rng.normal(loc=5.0, scale=[1.0, 10.0, 0.1], size=(200, 3)).astype(np.float32)
    torch.manual_seed(0)
    policy = NormalisedPolicy.for_data(obs, 2, hidden=(8,))
    torch.manual_seed(0)
    plain = GaussianPolicy(3, 2, hidden=(8,))
    x = torch.as_tensor(obs[:5])
    standardised = (x - torch.as_tensor(obs.mean(0))) / torch.as_tensor(obs.std(0))
    assert torch.allclose(policy(x), plain(standardised), atol=1e-5)
    assert len(list(policy.parameters())) == len(list(plain.parameters())), "the statistics are not trained"
    assert {"obs_mean", "obs_std"} <= set(policy.state_dict())
    assert policy.act(obs[:4]).shape == (4, 2)
