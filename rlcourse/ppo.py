"""Proximal Policy Optimisation, fine-tuning a pretrained Gaussian policy, in one readable loop.

The loop (:func:`ppo`) follows the shape of CleanRL's single-file PPO (Huang et al., 2022): collect
``n_steps`` steps from ``n_envs`` environments into pre-allocated ``(n_steps, n_envs, ...)`` tensors,
compute advantages with GAE, then run ``n_epochs`` of minibatch updates on the clipped objective and
log every term. Two pieces are *not* here but passed in, because hw4 asks students to write them:

* ``compute_gae(rewards, values, dones, last_value, gamma, lam) -> (advantages, returns)`` and
* ``ppo_loss(new_log_prob, old_log_prob, advantages, new_values, returns, entropy, kl_to_ref,
  clip_coef, vf_coef, ent_coef, kl_coef) -> (loss, terms)``.

Conventions the two pieces rely on:

* ``dones[t, i]`` is 1 when the transition at step ``t`` of environment ``i`` ended its episode,
  by termination (the hopper fell) **or** by truncation (the time limit). After a truncation the
  episode did not really end, so the loop adds the discounted value of the final observation to that
  step's reward, ``r_t += gamma * V(s_final)``, before calling ``compute_gae``; GAE can then stop at
  every ``done`` alike.
* Advantages are normalised per minibatch by the loop before ``ppo_loss`` sees them.
* ``kl_to_ref`` is the exact KL divergence ``KL(pi_theta(.|s) || pi_ref(.|s))`` between the two
  diagonal Gaussians at each minibatch state, with gradient with respect to the policy.

What the loop adds for fine-tuning a pretrained actor: a fresh critic with its own observation
normaliser, ``critic_warmup`` iterations in which only the critic learns (a random critic would
otherwise push the good actor around with noise), and reward scaling by a running estimate of the
discounted return's standard deviation (the rewards PPO sees; the logged returns are unscaled).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Callable, Optional

import numpy as np
import torch
from torch import nn
from torch.distributions import kl_divergence

from rlcourse.envs import HOPPER as ENV_ID
from rlcourse.envs import make_envs  # noqa: F401  (hw4 and its suite import make_envs from here)
from rlcourse.nets import GaussianPolicy, mlp
from rlcourse.training import EvaluationHook, TrainingLog, due, fine_tuning_copies


@dataclass
class PPOConfig:
    """Every knob of :func:`ppo`, with the defaults used in hw4."""

    total_steps: int = 100_000
    """environment steps to collect (summed over the parallel environments)"""
    n_envs: int = 4
    """parallel environments in one ``SyncVectorEnv``"""
    n_steps: int = 512
    """steps per environment per rollout; a rollout is ``n_envs * n_steps`` transitions"""
    gamma: float = 0.99
    """discount factor"""
    gae_lambda: float = 0.95
    """GAE's lambda: 0 is the one-step TD error, 1 the Monte-Carlo return minus the value"""
    n_epochs: int = 10
    """passes over each rollout"""
    minibatch_size: int = 256
    """transitions per gradient step"""
    lr: float = 3e-4
    """Adam learning rate of the actor"""
    critic_lr: float = 1e-3
    """Adam learning rate of the critic"""
    clip_coef: float = 0.2
    """probability-ratio clipping range epsilon"""
    vf_coef: float = 0.5
    """weight of the value loss"""
    ent_coef: float = 0.0
    """weight of the entropy bonus"""
    kl_coef: float = 0.0
    """weight of the KL penalty to the reference policy"""
    max_grad_norm: float = 0.5
    """gradient clipping"""
    critic_warmup: int = 3
    """initial iterations in which only the critic is trained"""
    eval_every: int = 5
    """iterations between calls of ``evaluate`` (and once at the start and at the end)"""
    seed: int = 0
    """seeds the environments, torch and the minibatch order"""
    env_id: str = ENV_ID
    """the gymnasium environment"""

    @property
    def batch_size(self) -> int:
        return self.n_envs * self.n_steps

    @property
    def n_iterations(self) -> int:
        return max(1, self.total_steps // self.batch_size)


class RunningMeanStd:
    """Running mean and variance of a stream of arrays (the parallel-update formula of Chan et al.)."""

    def __init__(self, shape: tuple[int, ...] = ()) -> None:
        self.mean, self.var, self.count = np.zeros(shape), np.ones(shape), 1e-4

    def update(self, x: np.ndarray) -> None:
        batch_mean, batch_var, n = x.mean(0), x.var(0), x.shape[0]
        delta, total = batch_mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + batch_var * n + delta**2 * self.count * n / total) / total
        self.count = total


class Critic(nn.Module):
    """V(s): an MLP on observations standardised by running statistics (updated by the loop)."""

    def __init__(self, obs_dim: int, hidden: tuple[int, ...] = (64, 64)) -> None:
        super().__init__()
        self.net = mlp([obs_dim, *hidden, 1], "tanh")
        self.obs_rms = RunningMeanStd((obs_dim,))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        mean = torch.as_tensor(self.obs_rms.mean, dtype=torch.float32)
        std = torch.as_tensor(np.sqrt(self.obs_rms.var + 1e-8), dtype=torch.float32)
        return self.net(((obs - mean) / std).clamp(-10, 10)).squeeze(-1)


@dataclass
class PPOLog(TrainingLog):
    """What :func:`ppo` records: besides ``evals``, ``iterations`` holds one dict per update (``step``,
    ``time``, the loss terms, ``approx_kl``, ``clip_frac``, ``explained_var``, the mean training-episode
    returns)."""

    iterations: list[dict] = field(default_factory=list)


def ppo(policy: GaussianPolicy, reference: GaussianPolicy, compute_gae: Callable, ppo_loss: Callable,
        config: PPOConfig, wrap: Optional[Callable] = None,
        evaluate: Optional[Callable[[GaussianPolicy], dict]] = None, verbose: bool = True,
        ) -> tuple[GaussianPolicy, PPOLog]:
    """Fine-tune a copy of ``policy`` with PPO; ``reference`` is the frozen KL anchor.

    ``wrap(envs)`` may replace the environments' reward (hw4's ``LearnedRewardWrapper``); when the
    wrapped env reports ``info["true_reward"]`` the loop logs true returns beside the training ones.
    ``evaluate(policy) -> dict`` (for instance deterministic returns and the KL to the reference) is
    called every ``config.eval_every`` iterations. Returns the trained copy and the log.
    """
    cfg = config
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    actor, reference = fine_tuning_copies(policy, reference)
    envs = make_envs(cfg.n_envs, cfg.env_id, wrap=wrap)
    critic = Critic(envs.single_observation_space.shape[0])
    actor_opt = torch.optim.Adam(actor.parameters(), lr=cfg.lr, eps=1e-5)
    critic_opt = torch.optim.Adam(critic.parameters(), lr=cfg.critic_lr, eps=1e-5)
    log = PPOLog(config=asdict(cfg))
    run_evaluation = EvaluationHook(log, evaluate, verbose)

    # Storage: (n_steps, n_envs, ...), filled in place every rollout.
    T, N = cfg.n_steps, cfg.n_envs
    obs_buf = torch.zeros((T, N) + envs.single_observation_space.shape)
    act_buf = torch.zeros((T, N) + envs.single_action_space.shape)
    logp_buf, rew_buf, done_buf, val_buf = (torch.zeros((T, N)) for _ in range(4))

    reward_rms, disc_return = RunningMeanStd(), np.zeros(N)
    ep_true, ep_train = np.zeros(N), np.zeros(N)
    obs, _ = envs.reset(seed=cfg.seed)
    critic.obs_rms.update(obs)
    step = 0

    run_evaluation(actor, step)
    for iteration in range(cfg.n_iterations):
        finished_true, finished_train = [], []
        # ---- rollout ------------------------------------------------------------------
        for t in range(T):
            obs_t = torch.as_tensor(obs, dtype=torch.float32)
            with torch.no_grad():
                dist = actor.distribution(obs_t)
                action = dist.sample()
                logp_buf[t], val_buf[t] = dist.log_prob(action), critic(obs_t)
            obs_buf[t], act_buf[t] = obs_t, action
            obs, reward, terminated, truncated, info = envs.step(action.numpy())
            true_reward = np.asarray(info.get("true_reward", reward), dtype=float)
            ep_true += true_reward
            ep_train += reward
            done = terminated | truncated
            # reward scaling by the running std of the discounted return
            disc_return = disc_return * cfg.gamma + reward
            reward_rms.update(disc_return)
            scaled = reward / np.sqrt(reward_rms.var + 1e-8)
            if truncated.any():  # bootstrap the time-limit cut from the final observation's value
                final = np.stack([info["final_obs"][i] for i in np.flatnonzero(truncated)])
                with torch.no_grad():
                    scaled[truncated] += cfg.gamma * critic(torch.as_tensor(final, dtype=torch.float32)).numpy()
            rew_buf[t] = torch.as_tensor(scaled, dtype=torch.float32)
            done_buf[t] = torch.as_tensor(done, dtype=torch.float32)
            for i in np.flatnonzero(done):
                finished_true.append(ep_true[i])
                finished_train.append(ep_train[i])
            ep_true[done], ep_train[done], disc_return[done] = 0.0, 0.0, 0.0
            critic.obs_rms.update(obs)
        step += T * N
        with torch.no_grad():
            last_value = critic(torch.as_tensor(obs, dtype=torch.float32))
        advantages, returns = compute_gae(rew_buf, val_buf, done_buf, last_value, cfg.gamma, cfg.gae_lambda)

        # ---- update -------------------------------------------------------------------
        b_obs, b_act = obs_buf.reshape(T * N, -1), act_buf.reshape(T * N, -1)
        b_logp, b_adv, b_ret = logp_buf.reshape(-1), advantages.reshape(-1), returns.reshape(-1)
        train_actor = iteration >= cfg.critic_warmup
        terms_sum: dict[str, float] = {}
        n_updates = 0
        for _ in range(cfg.n_epochs):
            for mb in np.array_split(rng.permutation(T * N), max(1, T * N // cfg.minibatch_size)):
                dist = actor.distribution(b_obs[mb])
                new_logp, entropy = dist.log_prob(b_act[mb]), dist.entropy()
                kl_ref = kl_divergence(dist, reference.distribution(b_obs[mb]))
                adv = (b_adv[mb] - b_adv[mb].mean()) / (b_adv[mb].std() + 1e-8)
                loss, terms = ppo_loss(new_logp, b_logp[mb], adv, critic(b_obs[mb]), b_ret[mb], entropy, kl_ref,
                                       cfg.clip_coef, cfg.vf_coef, cfg.ent_coef, cfg.kl_coef)
                actor_opt.zero_grad()
                critic_opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(critic.parameters(), cfg.max_grad_norm)
                critic_opt.step()
                if train_actor:
                    nn.utils.clip_grad_norm_(actor.parameters(), cfg.max_grad_norm)
                    actor_opt.step()
                for k, v in terms.items():
                    terms_sum[k] = terms_sum.get(k, 0.0) + float(v)
                n_updates += 1
        explained = 1 - float((b_ret - val_buf.reshape(-1)).var() / (b_ret.var() + 1e-8))
        row = {"step": step, "time": run_evaluation.elapsed(), "explained_var": explained,
               **{k: v / n_updates for k, v in terms_sum.items()}}
        if finished_true:
            row["train_true_return"] = float(np.mean(finished_true))
            row["train_return"] = float(np.mean(finished_train))
        log.iterations.append(row)
        if due(iteration + 1, cfg.eval_every, cfg.n_iterations):
            run_evaluation(actor, step)
    envs.close()
    return actor.eval(), log
