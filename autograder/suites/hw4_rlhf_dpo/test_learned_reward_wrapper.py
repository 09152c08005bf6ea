"""Hidden tests of hw4's `LearnedRewardWrapper`: learned reward on the pre-step observations, true reward kept."""
import numpy as np

from autograder.suite import check_array, stub
from rlcourse.ppo import make_envs

HINT = ("Remember the observations from reset() and from every step(); reward = (reward_fn(obs before the step, "
        "actions) - mean) / std + offset; info['true_reward'] = the env's reward; keep the other info keys.")
N_ENVS, SEED = 3, 11


def _expected(acts, mean, std, offset):
    envs = make_envs(N_ENVS)
    obs, _ = envs.reset(seed=SEED)
    out = []
    for a in acts:
        learned = ((obs[:, 1] - 2.0 * a[:, 2]).astype(np.float32) - mean) / std + offset
        obs, reward, term, trunc, info = envs.step(a)
        out.append((obs, learned, reward, term | trunc))
    envs.close()
    return out


def _run(student, acts, mean, std, offset):
    w = student.helpers.reward_wrapper(N_ENVS, mean, std, offset)   # reward_fn: sandbox_helpers.hand_reward
    first = w.reset(seed=SEED)
    assert isinstance(first, (tuple, list)) and len(first) == 2, "reset() should return (obs, info) like the env it wraps"
    got = student.helpers.wrapper_steps(w, acts)
    w.close()
    return first[0], got


def _actions(rng, n):
    return [rng.uniform(-1, 1, size=(N_ENVS, 3)).astype(np.float32) for _ in range(n)]


@stub("LearnedRewardWrapper", points=2, hint=HINT)
def test_rewards_over_episode_ends(student, rng):
    """80 random steps of 3 Hopper envs (episodes end and reset): learned reward, true reward and observations"""
    acts = _actions(rng, 80)
    want = _expected(acts, 0.3, 2.5, 1.0)
    obs0, got = _run(student, acts, 0.3, 2.5, 1.0)
    assert any(w[3].any() for w in want), "test set-up: some episode should end within 80 random steps"
    for t, ((g_obs, g_rew, g_true, g_done, _), (w_obs, w_rew, w_true, w_done)) in enumerate(zip(got, want)):
        check_array(g_obs, w_obs, rtol=1e-5, atol=1e-6, name=f"the observations returned at step {t}")
        check_array(g_true, w_true.astype(float), rtol=1e-6, atol=1e-8, name=f"info['true_reward'] at step {t}")
        check_array(g_rew, w_rew.astype(float), rtol=1e-5, atol=1e-5,
                    name=f"the learned reward at step {t}" + (" (right after an episode ended: use the new episode's "
                                                              "first observation)" if t and want[t - 1][3].any() else ""))


@stub("LearnedRewardWrapper", points=1, hint="Evaluate reward_fn on the observations *before* the step (s_t, a_t), "
      "not on the observations the step returns.")
def test_first_step_uses_reset_observation(student, rng):
    """The first reward uses the observations returned by reset()"""
    acts = _actions(rng, 1)
    want = _expected(acts, 0.0, 1.0, 0.0)
    _, got = _run(student, acts, 0.0, 1.0, 0.0)
    check_array(got[0][1], want[0][1].astype(float), rtol=1e-5, atol=1e-5, name="the first learned reward")


@stub("LearnedRewardWrapper", points=1, hint="Normalise as (r - mean) / std, then add offset (in that order).")
def test_normalisation_and_offset(student, rng):
    """mean, std and offset each enter as documented"""
    acts = _actions(rng, 3)
    for mean, std, offset in ((1.0, 1.0, 0.0), (0.0, 4.0, 0.0), (0.0, 1.0, -2.0), (-0.5, 0.25, 3.0)):
        want = _expected(acts, mean, std, offset)
        _, got = _run(student, acts, mean, std, offset)
        for t in range(3):
            check_array(got[t][1], want[t][1].astype(float), rtol=1e-5, atol=1e-5,
                        name=f"the learned reward with mean {mean}, std {std}, offset {offset}")


@stub("LearnedRewardWrapper", points=1, hint="Add 'true_reward' to the env's info dict; keep the keys already there "
      "(the PPO loop needs info['final_obs'] at episode ends).")
def test_info_keeps_env_keys(student, rng):
    """On a step where an episode ends, info still holds the env's own 'final_obs' beside 'true_reward', and the reward there is the learned one"""
    acts = _actions(rng, 80)
    want = _expected(acts, 0.5, 2.0, 0.0)
    _, got = _run(student, acts, 0.5, 2.0, 0.0)
    ends = [t for t, w in enumerate(want) if w[3].any()]
    assert ends, "test set-up: some episode should end within 80 random steps"
    assert all("final_obs" in got[t][4] for t in ends), "info lost the env's 'final_obs' key on a step where an episode ended"
    for t in ends:
        check_array(got[t][1], want[t][1].astype(float), rtol=1e-5, atol=1e-5,
                    name="the reward on a step where an episode ended (the learned reward, not the env's)")
