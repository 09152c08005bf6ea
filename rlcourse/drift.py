"""Hopper with pushes: the MuJoCo world in which hw1 looks for compounding error.

On the calm ``Hopper-v5`` a two-layer clone of a few expert episodes hops as well as the expert: the
expert's states form a thin tube, the clone's errors are small enough to keep it inside, and nothing
ever shows it the rest of the state space. :class:`PushedHopper` knocks the robot out of that tube.
At every step, with probability ``PUSH_RATE``, the torso's three velocities (forward, vertical and
pitch, ``qvel[:3]``) get a kick drawn from ``N(0, push**2)`` independently, in m/s and rad/s. The
pushes come from the environment's own generator, seeded by ``reset(seed=...)``, so a seeded
episode meets the same pushes whoever acts in it (the expert and every learner are evaluated on
the same pushes).

:func:`pushed_hopper` registers one gymnasium id per push size (``rlcourse/PushedHopper-p0.50-v0``
for 0.5), because :func:`rlcourse.rollouts.rollout` and hw1's ``dagger`` take an environment id.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco.hopper_v5 import HopperEnv

PUSH_RATE = 0.02
"""Probability of a push at each step: one push every 50 steps (0.4 s of simulated time) on average."""


class PushedHopper(gym.Wrapper):
    """``Hopper-v5`` whose torso is kicked now and then: see the module's docstring.

    ``n_pushes`` counts the pushes of the current episode.
    """

    def __init__(self, push: float, rate: float = PUSH_RATE, **hopper_kwargs) -> None:
        if push < 0 or not 0 <= rate <= 1:
            raise ValueError(f"need push >= 0 and 0 <= rate <= 1, got push={push}, rate={rate}")
        super().__init__(HopperEnv(**hopper_kwargs))  # registration adds the 1,000-step TimeLimit
        self.push, self.rate = float(push), float(rate)
        self.rng = np.random.default_rng()
        self.n_pushes = 0

    def reset(self, *, seed: int | None = None, options=None):
        if seed is not None:
            self.rng = np.random.default_rng([seed, 7919])  # its own stream, apart from the reset noise's
        self.n_pushes = 0
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        if self.push > 0 and self.rng.random() < self.rate:
            data = self.env.unwrapped.data
            data.qvel[:3] += self.rng.normal(0.0, self.push, size=3)
            self.n_pushes += 1
        return self.env.step(action)


def pushed_hopper(push: float) -> str:
    """The gymnasium id of Hopper with pushes of size ``push`` (registered on first use)."""
    env_id = f"rlcourse/PushedHopper-p{push:.2f}-v0"
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=PushedHopper, max_episode_steps=1000, kwargs={"push": float(push)})
    return env_id


# ---------------------------------------------------------------------------------------------------
# The protocol's pieces, shared by the notebook and bench/bench_hw1_imitation.py. They take the
# student's (or the reference's) train_bc and dagger as arguments.
# ---------------------------------------------------------------------------------------------------

def fit_clone(train_bc, obs: np.ndarray, actions: np.ndarray, seed: int, steps: int, hidden=(64, 64),
              batch_size: int = 256, lr: float = 1e-3, stats: tuple[np.ndarray, np.ndarray] | None = None):
    """A fresh :class:`~rlcourse.imitation.NormalisedPolicy` fitted by ``train_bc`` for about ``steps``
    gradient steps on ``(obs, actions)`` (standardised with ``stats`` or the data's own statistics)."""
    import torch

    from rlcourse.imitation import NormalisedPolicy

    torch.manual_seed(seed)
    mean, std = stats if stats is not None else (obs.mean(axis=0), obs.std(axis=0))
    policy = NormalisedPolicy(mean, std, actions.shape[1], hidden=hidden)
    train_bc(policy, obs, actions, n_epochs=epochs_for(steps, len(obs), batch_size), batch_size=batch_size,
             lr=lr, seed=seed)
    return policy


def epochs_for(steps: int, n_pairs: int, batch_size: int = 256, val_fraction: float = 0.1) -> int:
    """Epochs that give at least ``steps`` minibatch steps on ``n_pairs`` pairs (a tenth held out)."""
    per_epoch = max(1, int(np.ceil((n_pairs - round(val_fraction * n_pairs)) / batch_size)))
    return max(1, int(np.ceil(steps / per_epoch)))


def expert_fraction(policy, expert_return: float, env_id: str, n_episodes: int, seed: int) -> float:
    """The policy's mean return over ``n_episodes`` seeded episodes, as a fraction of ``expert_return``."""
    from rlcourse.rollouts import rollout

    return float(rollout(policy.act, env_id, n_episodes, seed).returns.mean()) / expert_return


def drift_run(train_bc, dagger, expert, env_id: str, demos, seed: int, expert_return: float, *,
              hidden=(16, 16), bc_demos=(1, 4, 12), bc_steps: int = 5000, dagger_iters: int = 8,
              dagger_episodes: int = 2, refit_steps: int = 1000, eval_episodes: int = 20, eval_seed: int = 1000,
              batch_size: int = 256, lr: float = 1e-3, keep_clone: bool = False, log=print) -> dict:
    """One training seed of hw1's drift protocol in one world (``env_id``); every fraction is of ``expert_return``.

    - behaviour cloning on the first ``k`` demonstrations for each ``k`` in ``bc_demos`` (``bc_steps``
      gradient steps each, a fresh learner of width ``hidden``, standardised with its own data);
    - DAgger from the one-demonstration clone: ``dagger_iters`` calls of ``dagger`` for one iteration
      each (beta = 0, ``dagger_episodes`` learner episodes, seeded ``10_000 + 100 * seed + i *
      dagger_episodes``), refitting the learner in place for about ``refit_steps`` gradient steps;
      the learner is evaluated after every iteration;
    - behaviour cloning on exactly as many labels as DAgger finished with: the first pairs of the
      demonstrations (whole episodes, then part of the next).

    Returns ``{"seed", "bc": [[labels, fraction], ...], "dagger": [[labels, fraction], ...]`` (the first
    DAgger point is the one-demonstration clone it starts from), ``"labels"`` (DAgger's final count),
    ``"bc_matched"``, ``"dagger_final"``}; with ``keep_clone``, also ``"matched_clone"``: that same-labels
    clone itself, for :func:`dart_run` (pop it before saving the record as JSON). ``log`` gets one line per
    finished fit.
    """
    import copy
    import time

    start = time.perf_counter()
    score = lambda policy: expert_fraction(policy, expert_return, env_id, eval_episodes, eval_seed)  # noqa: E731
    fit = lambda d_obs, d_act, stats=None: fit_clone(train_bc, d_obs, d_act, seed, bc_steps, hidden,  # noqa: E731
                                                     batch_size, lr, stats)
    out = {"seed": seed, "bc": [], "dagger": []}
    clones = {}
    for k in bc_demos:
        d = demos.first(k)
        clones[k] = fit(d.obs, d.actions)
        out["bc"].append([int(len(d.obs)), score(clones[k])])
        log(f"  seed {seed}: BC on {k} demos ({len(d.obs)} labels): {out['bc'][-1][1]:.2f} of the expert "
            f"({time.perf_counter() - start:.0f} s)")
    first = demos.first(bc_demos[0])
    learner, obs, actions = copy.deepcopy(clones[bc_demos[0]]), first.obs, first.actions
    out["dagger"].append([int(len(obs)), out["bc"][0][1]])
    for i in range(dagger_iters):
        learner, hist = dagger(env_id, expert, learner, 1, [0.0], obs, actions, episodes_per_iter=dagger_episodes,
                               seed=10_000 + 100 * seed + i * dagger_episodes,
                               n_epochs=epochs_for(refit_steps, len(obs), batch_size), batch_size=batch_size, lr=lr)
        obs, actions = hist["obs"], hist["actions"]
        out["dagger"].append([int(len(obs)), score(learner)])
        log(f"  seed {seed}: DAgger iteration {i + 1} ({len(obs)} labels): {out['dagger'][-1][1]:.2f} of the expert "
            f"({time.perf_counter() - start:.0f} s)")
    n, m = len(obs), min(len(obs), len(demos.obs))  # m < n only when too few demonstrations were recorded
    matched = fit(demos.obs[:m], demos.actions[:m])
    out.update(labels=int(n), bc_labels=int(m), bc_matched=score(matched), dagger_final=out["dagger"][-1][1])
    if keep_clone:
        out["matched_clone"] = matched
    log(f"  seed {seed}: BC on the same {m} labels: {out['bc_matched']:.2f}; DAgger {out['dagger_final']:.2f} "
        f"({time.perf_counter() - start:.0f} s)")
    return out


def summarise(runs: list[dict]) -> dict:
    """The comparison at the same labels over the seeds of one setting's :func:`drift_run` results.

    Returns ``{"labels", "bc", "dagger"}`` (per-seed lists, seeds in the order given), their means and
    standard deviations (``bc_mean``, ``bc_std``, ``dagger_mean``, ``dagger_std``), and ``target_met``:
    DAgger >= 0.9, BC <= 0.7 and a gap of the means over twice the larger spread (issue 34's bar).
    """
    bc = np.array([r["bc_matched"] for r in runs], dtype=float)
    dg = np.array([r["dagger_final"] for r in runs], dtype=float)
    spread = max(bc.std(), dg.std())
    return {"labels": [int(r["labels"]) for r in runs], "bc": bc.round(4).tolist(), "dagger": dg.round(4).tolist(),
            "bc_mean": float(bc.mean()), "bc_std": float(bc.std()), "dagger_mean": float(dg.mean()),
            "dagger_std": float(dg.std()),
            "target_met": bool(dg.mean() >= 0.9 and bc.mean() <= 0.7 and dg.mean() - bc.mean() > 2 * spread)}


def plot_drift(runs: list[dict], ax, title: str = "", dart: list[dict] | None = None) -> None:
    """Fraction of the expert against expert labels for one setting's runs: the behaviour-cloning
    curve (mean and one standard deviation over seeds), DAgger by iteration (labels averaged over
    seeds), the clone on DAgger's final number of labels and, given :func:`dart_run` results, DART there."""
    bc = np.array([[f for _, f in r["bc"]] for r in runs])
    bc_x = np.mean([[n for n, _ in r["bc"]] for r in runs], axis=0)
    dg = np.array([[f for _, f in r["dagger"]] for r in runs])
    dg_x = np.mean([[n for n, _ in r["dagger"]] for r in runs], axis=0)
    for name, x, y, color, marker in (("behaviour cloning", bc_x, bc, "tab:red", "o"),
                                      ("DAgger", dg_x, dg, "tab:blue", ".")):
        mean, std = y.mean(axis=0), y.std(axis=0)
        ax.plot(x, mean, color=color, marker=marker, label=f"{name} ({len(runs)} seeds)")
        ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.2)
    s = summarise(runs)
    ax.errorbar([np.mean(s["labels"])], [s["bc_mean"]], yerr=[s["bc_std"]], color="tab:red", marker="s",
                linestyle="none", capsize=3, label="BC on DAgger's final labels")
    if dart:
        scores = np.array([r["dart"] for r in dart])
        ax.errorbar([np.mean([r["labels"] for r in dart])], [scores.mean()], yerr=[scores.std()], color="tab:green",
                    marker="D", linestyle="none", capsize=3, label="DART on the same labels")
    ax.axhline(1.0, linestyle="--", color="grey", linewidth=1)
    ax.set_xscale("log")
    ax.set_xlabel("expert labels")
    ax.set_ylabel("return / expert's")
    ax.set_ylim(0, 1.25)
    ax.grid(alpha=0.3)
    ax.legend(frameon=False, fontsize=8)
    if title:
        ax.set_title(title)


# ---------------------------------------------------------------------------------------------------
# DART (Laskey et al., 2017): an off-policy way to put recovery states into the demonstrations. The
# expert still drives, but the action it executes carries Gaussian noise as large as the errors the
# learner will make; every state it reaches is labelled with the expert's clean action. The learner
# never acts while data are collected, as in behaviour cloning, yet its data hold the expert's
# corrections from states near the tube, as DAgger's do.
# ---------------------------------------------------------------------------------------------------

def action_error_moment(policy, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """The ``(act_dim, act_dim)`` second moment ``E[(pi(s) - a)(pi(s) - a)^T]`` of ``policy.act``'s errors on
    the pairs ``(obs, actions)``: the noise covariance DART injects, so that the expert's demonstrations
    stray from its tube as far as a learner with these errors would."""
    err = np.asarray(policy.act(obs), dtype=np.float64) - np.asarray(actions, dtype=np.float64)
    return err.T @ err / len(err)


class NoisyExpert:
    """The expert's action plus noise drawn from ``N(0, cov)``, independently per step and per environment.

    ``rng`` draws the noise, so a seeded generator gives reproducible episodes. Actions are clipped to
    ``[low, high]`` (Hopper's torques lie in [-1, 1]), as the simulator would clip them anyway.
    """

    def __init__(self, expert, cov: np.ndarray, rng: np.random.Generator, low: float = -1.0, high: float = 1.0) -> None:
        self.expert, self.cov, self.rng = expert, np.asarray(cov, dtype=np.float64), rng
        self.low, self.high = low, high

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        clean = np.asarray(self.expert.act(obs), dtype=np.float64)
        noise = self.rng.multivariate_normal(np.zeros(len(self.cov)), self.cov, size=len(clean))
        return np.clip(clean + noise, self.low, self.high)


def dart_demos(expert, env_id: str, cov: np.ndarray, n_labels: int, seed: int, batch: int = 4):
    """Exactly ``n_labels`` DART pairs: episodes of :class:`NoisyExpert` (seeded ``seed, seed + 1, ...``, in
    batches of ``batch`` run side by side) until ``n_labels`` states are visited, each state labelled
    with the expert's *clean* action; the last episode is cut where the count is reached.

    Returns a :class:`~rlcourse.imitation.Demonstrations` whose ``actions`` are the labels and whose
    ``rewards`` and ``lengths`` are those of the noisy episodes (so ``.returns`` says how well the
    expert did while disturbed; the cut episode counts its steps up to the cut).
    """
    from rlcourse.imitation import Demonstrations
    from rlcourse.rollouts import rollout

    if n_labels < 1:
        raise ValueError(f"n_labels must be at least 1, got {n_labels}")
    noisy = NoisyExpert(expert, cov, np.random.default_rng([seed, 4099]))
    parts, total, next_seed = [], 0, seed
    while total < n_labels:
        part = Demonstrations.from_episodes(rollout(noisy, env_id, batch, seed=next_seed, progress=False))
        parts.append(part)
        total += len(part.obs)
        next_seed += batch
    obs = np.concatenate([p.obs for p in parts])[:n_labels]
    rewards = np.concatenate([p.rewards for p in parts])[:n_labels]
    lengths = np.concatenate([p.lengths for p in parts])
    terminated = np.concatenate([p.terminated for p in parts])
    ends = np.cumsum(lengths)
    keep = int(np.searchsorted(ends, n_labels)) + 1           # episodes that hold the first n_labels states
    lengths, terminated = lengths[:keep].copy(), terminated[:keep].copy()
    cut = int(ends[keep - 1] - n_labels)
    lengths[-1] -= cut
    terminated[-1] &= cut == 0                                # a cut episode did not end by failure there
    labels = np.asarray(expert.act(obs), dtype=np.float32)
    return Demonstrations(obs, labels, rewards, lengths, terminated)


def dart_run(train_bc, expert, env_id: str, demos, seed: int, expert_return: float, labels: int, *,
             hidden=(16, 16), bc_steps: int = 5000, eval_episodes: int = 20, eval_seed: int = 1000,
             batch_size: int = 256, lr: float = 1e-3, clone=None, rescore_clone: bool = False, log=print,
             **_unused) -> dict:
    """One training seed of DART at ``labels`` expert labels (DAgger's final count in :func:`drift_run`).

    1. The noise: behaviour cloning on the first ``labels`` pairs of ``demos`` (exactly the clone that
       :func:`drift_run` compares with DAgger, same seed), and the second moment of its action errors on
       those pairs (:func:`action_error_moment`): the error a learner of this width makes after this many
       clean labels, measured on data the practitioner has, never on returns. Pass that clone as ``clone``
       (``drift_run(..., keep_clone=True)["matched_clone"]``) to use it rather than fit it again.
    2. ``labels`` pairs from the expert driving with that noise (:func:`dart_demos`, episodes seeded
       ``20_000 + 100 * seed``), labelled with its clean actions.
    3. A fresh learner fitted to them exactly as the clone was (``bc_steps`` steps, same seed), evaluated
       on the same ``eval_episodes`` episodes as every learner of the protocol.

    Returns ``{"seed", "labels", "noise_std"`` (square roots of the moment's diagonal), ``"noise_cov"``,
    ``"noisy_expert"`` (the disturbed expert's mean return per whole episode, as a fraction of
    ``expert_return``), ``"dart"`` (the learner's fraction), and, with ``rescore_clone``, ``"bc_matched"``
    (the clone's own fraction: :func:`drift_run`'s same-labels clone drawn again, equal to it only where
    rollouts repeat to the last digit, since Hopper's contacts amplify any difference)``}``.
    ``drift_run``'s other keyword arguments may be passed and are ignored.
    """
    import time

    start = time.perf_counter()
    score = lambda policy: expert_fraction(policy, expert_return, env_id, eval_episodes, eval_seed)  # noqa: E731
    m = min(labels, len(demos.obs))
    if clone is None:
        clone = fit_clone(train_bc, demos.obs[:m], demos.actions[:m], seed, bc_steps, hidden, batch_size, lr)
    cov = action_error_moment(clone, demos.obs[:m], demos.actions[:m])
    data = dart_demos(expert, env_id, cov, labels, seed=20_000 + 100 * seed)
    learner = fit_clone(train_bc, data.obs, data.actions, seed, bc_steps, hidden, batch_size, lr)
    returns = data.returns[:-1] if data.n_episodes > 1 else data.returns   # the last episode may be cut
    out = {"seed": seed, "labels": int(labels), "noise_std": np.sqrt(np.diag(cov)).round(4).tolist(),
           "noise_cov": cov.round(6).tolist(), "noisy_expert": float(returns.mean()) / expert_return,
           "dart": score(learner)}
    if rescore_clone:
        out["bc_matched"] = score(clone)
    log(f"  seed {seed}: DART on {labels} labels (noise sd {', '.join(f'{s:.2f}' for s in out['noise_std'])}; "
        f"the disturbed expert {out['noisy_expert']:.2f}): {out['dart']:.2f} of the expert "
        f"({time.perf_counter() - start:.0f} s)")
    return out
