"""Tests of rlcourse.ppo: running statistics, self-resetting environments, and the given PPO loop."""
import gymnasium as gym
import numpy as np
import pytest
import torch

from rlcourse.nets import GaussianPolicy
from rlcourse.ppo import Critic, PPOConfig, RunningMeanStd, make_envs, ppo

TOY_ID = "RLCourseToyLine-v0"


class ToyLine(gym.Env):
    """A 1-D walk: action moves the position, reward 1 per step, never terminates (time limit only)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = 0.0
        return np.array([self.x, 1.0], np.float32), {}

    def step(self, action):
        self.x += float(np.clip(action, -1, 1)[0])
        return np.array([self.x, 1.0], np.float32), 1.0, False, False, {}


if TOY_ID not in gym.registry:
    gym.register(TOY_ID, entry_point=ToyLine, max_episode_steps=5)


def gae(rewards, values, dones, last_value, gamma, lam):
    adv, nxt_a, nxt_v = torch.zeros_like(rewards), torch.zeros_like(last_value), last_value
    for t in reversed(range(len(rewards))):
        alive = 1 - dones[t]
        nxt_a = rewards[t] + gamma * alive * nxt_v - values[t] + gamma * lam * alive * nxt_a
        adv[t], nxt_v = nxt_a, values[t]
    return adv, adv + values


def loss_fn(new_lp, old_lp, adv, v, ret, ent, kl, clip, vf, ec, kc):
    ratio = (new_lp - old_lp).exp()
    pg = -torch.min(ratio * adv, ratio.clamp(1 - clip, 1 + clip) * adv).mean()
    loss = pg + vf * 0.5 * ((v - ret) ** 2).mean() - ec * ent.mean() + kc * kl.mean()
    return loss, {"policy_loss": pg.detach(), "kl_ref": kl.mean().detach()}


def test_running_mean_std_matches_numpy():
    rng = np.random.default_rng(0)
    chunks = [rng.normal(3.0, 2.0, size=(n, 4)) for n in (5, 17, 1, 40)]
    rms = RunningMeanStd((4,))
    for c in chunks:
        rms.update(c)
    everything = np.concatenate(chunks)
    assert np.allclose(rms.mean, everything.mean(0), atol=1e-4)
    assert np.allclose(rms.var, everything.var(0), rtol=1e-3)


def test_critic_standardises_its_inputs():
    critic = Critic(3)
    critic.obs_rms.mean, critic.obs_rms.var = np.array([10.0, -5.0, 0.0]), np.array([4.0, 1.0, 1.0])
    a = critic(torch.tensor([[10.0, -5.0, 0.0]]))
    critic.obs_rms.mean = np.zeros(3)
    b = critic(torch.zeros(1, 3))
    assert a.shape == (1,) and torch.allclose(a, b, atol=1e-5)


def test_make_envs_reset_in_the_same_step():
    envs = make_envs(2, TOY_ID)
    obs, _ = envs.reset(seed=0)
    for t in range(5):
        obs, reward, terminated, truncated, info = envs.step(np.ones((2, 1), np.float32))
    assert truncated.all() and not terminated.any()
    assert np.allclose(obs[:, 0], 0.0), "the returned observation should be the new episode's first"
    assert np.allclose(np.stack(info["final_obs"])[:, 0], 5.0), "info['final_obs'] holds the last observation"
    envs.close()


def _tiny(**kw):
    base = dict(env_id=TOY_ID, total_steps=256, n_envs=2, n_steps=32, n_epochs=2, minibatch_size=32, critic_warmup=0,
                eval_every=2)
    return PPOConfig(**{**base, **kw})


def test_ppo_calls_the_given_pieces_with_truncations_as_dones():
    seen = {}

    def spy(rewards, values, dones, last_value, gamma, lam):
        seen.setdefault("dones", dones.clone())
        seen.setdefault("rewards", rewards.clone())
        assert rewards.shape == values.shape == dones.shape == (32, 2) and last_value.shape == (2,)
        return gae(rewards, values, dones, last_value, gamma, lam)

    policy = GaussianPolicy(2, 1, hidden=(8,))
    calls = []
    trained, log = ppo(policy, policy, spy, loss_fn, _tiny(), evaluate=lambda p: calls.append(1) or {"x": 1.0},
                       verbose=False)
    done_rows = seen["dones"][:, 0].nonzero().flatten().tolist()
    assert done_rows[:3] == [4, 9, 14], "a time-limit truncation every 5 steps is a done"
    r = seen["rewards"][:, 0]
    bootstrapped = r[4] - r[3]
    assert abs(float(bootstrapped)) > 1e-6, "the truncation step's reward carries gamma * V(final obs)"
    assert len(log.iterations) == 4 and len(calls) == 1 + 2, "evaluate at the start and every eval_every iterations"
    assert {"step", "time", "policy_loss", "explained_var"} <= set(log.iterations[-1])
    assert trained is not policy


def test_ppo_leaves_the_inputs_alone_and_warmup_freezes_the_actor():
    torch.manual_seed(0)
    policy = GaussianPolicy(2, 1, hidden=(8,))
    before = [p.detach().clone() for p in policy.parameters()]
    frozen, _ = ppo(policy, policy, gae, loss_fn, _tiny(critic_warmup=100), verbose=False)
    moved, _ = ppo(policy, policy, gae, loss_fn, _tiny(), verbose=False)
    assert all(torch.equal(a, b) for a, b in zip(before, policy.parameters())), "the input policy must not change"
    assert all(torch.equal(a, b) for a, b in zip(before, frozen.parameters())), "the actor must not move in warm-up"
    assert any(not torch.equal(a, b) for a, b in zip(before, moved.parameters())), "the actor should move after warm-up"


def test_ppo_kl_penalty_keeps_the_policy_near_the_reference():
    policy = GaussianPolicy(2, 1, hidden=(8,))
    free, free_log = ppo(policy, policy, gae, loss_fn, _tiny(lr=3e-3), verbose=False)
    held, held_log = ppo(policy, policy, gae, loss_fn, _tiny(lr=3e-3, kl_coef=100.0), verbose=False)
    assert held_log.iterations[-1]["kl_ref"] < free_log.iterations[-1]["kl_ref"]


def test_config_sizes():
    cfg = PPOConfig(total_steps=10_000, n_envs=4, n_steps=512)
    assert cfg.batch_size == 2048 and cfg.n_iterations == 4
    with pytest.raises(TypeError):
        PPOConfig(unknown=1)


def test_log_series_keeps_rows_that_have_the_key_in_order():
    from rlcourse.ppo import PPOLog, TrainingLog

    rows = [{"step": 0, "return": 1.0}, {"step": 5}, {"step": 9, "return": 3.0}]
    steps, values = TrainingLog(config={}, evals=rows).series("return")
    assert steps.tolist() == [0, 9] and values.tolist() == [1.0, 3.0] and values.dtype == float
    log = PPOLog(config={}, iterations=[{"step": 2, "kl": 0.1}], evals=rows)
    assert log.series("kl", "iterations")[1].tolist() == [0.1] and log.series("return")[0].tolist() == [0, 9]
