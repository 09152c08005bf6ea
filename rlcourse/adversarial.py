"""Adversarial imitation (GAIL, AIRL) on walled gridworlds with known dynamics, and the transfer test (hw2b).

The worlds are hw2's terrain grids (:func:`rlcourse.gridworld.terrain_grid`: one-hot terrain and a goal
indicator as features, the same hidden linear reward, Boltzmann-rational experts) with a wall across the
middle that has a two-cell gap. :func:`transfer_worlds` returns the training world and three changed
worlds with the *same* states, features and true reward but other dynamics or starts: the gap moved,
the ground three times as slippery (the slip probability raised from 0.1 to 0.4), and a new start region
beyond the wall.

Given to the student: the worlds, the sampler, the behaviour-cloning and MaxEnt baselines, the two
discriminators, the training loop and the transfer experiment. Planning and evaluation go through two
functions the student writes in hw2b, passed in as arguments: ``plan(P, reward, T)``, the soft-optimal
policy of a ``(T, S, A)`` reward (hw2's backward pass, generalised to rewards of state and action), and
``visits(P, policy, p0)``, the per-step state distributions ``(T, S)`` (hw2's forward pass, kept per step).
Nothing here plans or computes visitation itself, so this module answers none of hw2's stubs; the loop
also takes the student's discriminator loss, AIRL logits and policy reward.

Conventions follow :mod:`rlcourse.gridworld`: a trajectory visits ``s_0 .. s_{T-1}``, takes an action at
each, and here also records where each action led, ``s_{t+1}`` (for ``t = T - 1`` a last draw from the
dynamics), so that transitions ``(s_t, a_t, s_{t+1})`` are ``(N, T)`` arrays ``states, actions,
next_states``; ``done`` marks the last one. Policies are time-dependent, ``(T, S, A)``; the policy step
of the adversarial learners is exact planning on the current reward through the known dynamics.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import torch
from scipy.sparse import csr_array

from rlcourse.gridworld import MOVES, GridMDP, _sample_rows, terrain_grid

WORLD_NAMES = ("original", "wall moved", "slippery", "new start")


class Transitions(NamedTuple):
    """A batch of trajectories as transitions: three ``(N, T)`` integer arrays."""

    states: np.ndarray
    actions: np.ndarray
    next_states: np.ndarray


def walled_transitions(size: int, slip: float, blocked: np.ndarray) -> np.ndarray:
    """``P[s, a, s']`` of a ``size x size`` grid whose ``blocked`` cells (a boolean ``(S,)`` mask) cannot be
    entered: the intended move with probability ``1 - slip``, otherwise a uniformly random action; a move
    off the grid or into a blocked cell stays put."""
    n_states = size * size
    rows, cols = np.divmod(np.arange(n_states), size)
    target_r = np.clip(rows[:, None] + MOVES[None, :, 0], 0, size - 1)
    target_c = np.clip(cols[:, None] + MOVES[None, :, 1], 0, size - 1)
    next_state = target_r * size + target_c                         # (S, A)
    next_state = np.where(blocked[next_state], np.arange(n_states)[:, None], next_state)
    move = np.zeros((n_states, MOVES.shape[0], n_states))
    move[np.arange(n_states)[:, None], np.arange(MOVES.shape[0])[None, :], next_state] = 1.0
    return (1.0 - slip) * move + slip * move.mean(axis=1, keepdims=True)


def transfer_worlds(size: int = 10, horizon: int = 25, seed: int = 0, beta: float = 2.0) -> dict[str, GridMDP]:
    """The training world and three changed worlds (fixed before any learner was run).

    All four share the terrain, the features, the goal and the true reward of ``terrain_grid(size,
    horizon, seed=seed)``; a wall fills column ``size // 2`` except a gap of two rows.

    - ``"original"``: the gap in rows 1-2, slip 0.1, starts in the three left columns;
    - ``"wall moved"``: the gap in rows ``size - 3 .. size - 2`` instead;
    - ``"slippery"``: slip 0.4 instead of 0.1;
    - ``"new start"``: starts in the top three rows right of the wall instead (cells no expert
      trajectory starts from).
    """
    base = terrain_grid(size=size, horizon=horizon, slip=0.1, seed=seed, beta=beta)
    wall_col = size // 2

    def wall(gap_rows) -> np.ndarray:
        blocked = np.zeros((size, size), dtype=bool)
        blocked[:, wall_col] = True
        blocked[list(gap_rows), wall_col] = False
        return blocked.ravel()

    def starts(region: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        p0 = region.ravel() & ~blocked
        return p0 / p0.sum()

    left = np.zeros((size, size), dtype=bool)
    left[:, :3] = True
    beyond = np.zeros((size, size), dtype=bool)
    beyond[:3, wall_col + 1:] = True
    top_gap, bottom_gap = wall((1, 2)), wall((size - 3, size - 2))
    settings = {"original": (top_gap, 0.1, left), "wall moved": (bottom_gap, 0.1, left),
                "slippery": (top_gap, 0.4, left), "new start": (top_gap, 0.1, beyond)}
    worlds = {}
    for name, (blocked, slip, region) in settings.items():
        worlds[name] = GridMDP(size=size, P=walled_transitions(size, slip, blocked), features=base.features,
                               feature_names=base.feature_names, p0=starts(region, blocked), horizon=horizon,
                               true_reward=base.true_reward, true_weights=base.true_weights, beta=beta)
    return worlds


def blocked_cells(mdp: GridMDP) -> np.ndarray:
    """Boolean ``(S,)``: the cells no action can enter (every move into them stays put)."""
    n_states = mdp.n_states
    inflow = mdp.P.sum(axis=(0, 1)) - mdp.P[np.arange(n_states), :, np.arange(n_states)].sum(axis=1)
    return inflow < 1e-12


def sample_transitions(P: np.ndarray, policy: np.ndarray, p0: np.ndarray, n: int,
                       rng: np.random.Generator) -> Transitions:
    """``n`` trajectories of ``T = policy.shape[0]`` steps from a ``(T, S, A)`` policy, as transitions."""
    horizon = policy.shape[0]
    states = np.empty((n, horizon), dtype=np.int64)
    actions = np.empty_like(states)
    next_states = np.empty_like(states)
    s = _sample_rows(np.broadcast_to(p0, (n, p0.shape[0])), rng)
    for t in range(horizon):
        a = _sample_rows(policy[t, s], rng)
        s_next = _sample_rows(P[s, a], rng)
        states[:, t], actions[:, t], next_states[:, t] = s, a, s_next
        s = s_next
    return Transitions(states, actions, next_states)


def _flat(P: np.ndarray) -> csr_array:
    return csr_array(np.asarray(P, dtype=float).reshape(-1, P.shape[-1]))


def as_time_table(reward: np.ndarray, horizon: int, n_states: int, n_actions: int) -> np.ndarray:
    """A reward of shape ``(S,)``, ``(S, A)`` or ``(T, S, A)`` as a ``(T, S, A)`` array."""
    reward = np.asarray(reward, dtype=float)
    if reward.ndim == 1:
        reward = reward[:, None]
    return np.broadcast_to(reward, (horizon, n_states, n_actions)).copy()


def true_return(mdp: GridMDP, policy: np.ndarray, visits: Callable) -> float:
    """Exact expected true return ``sum_t E[r(s_t)]`` of a ``(T, S, A)`` policy in ``mdp``, from
    ``visits(P, policy, p0)``, the per-step state distributions ``(T, S)`` (the student's forward pass)."""
    return float((np.asarray(visits(mdp.P, policy, mdp.p0)) @ mdp.true_reward).sum())


def normalised_return(mdp: GridMDP, policy: np.ndarray, visits: Callable) -> float:
    """``(J(pi) - J(uniform)) / (J(expert) - J(uniform))`` in ``mdp``: 1 is the expert planned in that
    world (Boltzmann-rational in its optimal Q-values, as the demonstrators), 0 the uniformly random policy."""
    uniform = np.full((mdp.horizon, mdp.n_states, mdp.n_actions), 1.0 / mdp.n_actions)
    j_uniform = true_return(mdp, uniform, visits)
    return (true_return(mdp, policy, visits) - j_uniform) / (true_return(mdp, mdp.expert_policy(), visits) - j_uniform)


def behaviour_cloning(demos: Transitions, n_states: int, n_actions: int, horizon: int,
                      prior: float = 0.1) -> np.ndarray:
    """Tabular BC: ``pi(a | s)`` proportional to the expert's count of ``(s, a)`` plus ``prior``, the same at
    every step (uniform in states the expert never visited); shape ``(T, S, A)``."""
    counts = np.full((n_states, n_actions), prior)
    np.add.at(counts, (demos.states.ravel(), demos.actions.ravel()), 1.0)
    return np.broadcast_to(counts / counts.sum(axis=1, keepdims=True), (horizon, n_states, n_actions)).copy()


def fit_maxent_weights(mdp: GridMDP, demos: Transitions, plan: Callable, visits: Callable, n_iters: int = 300,
                       lr: float = 0.05) -> np.ndarray:
    """Linear MaxEnt IRL weights ``w`` (``r(s) = phi(s) . w``) by Adam on the causal log-likelihood, whose
    gradient is the expert's feature counts minus those of ``plan``'s soft-optimal policy (hw2); from
    ``w = 0``, ``n_iters`` steps of size ``lr``."""
    phi = np.asarray(mdp.features, dtype=float)
    shape = (mdp.horizon, mdp.n_states, mdp.n_actions)
    mu_expert = phi[demos.states].sum(axis=1).mean(axis=0)
    w = torch.zeros(phi.shape[1], dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([w], lr=lr)
    for _ in range(n_iters):
        policy = plan(mdp.P, as_time_table(phi @ w.detach().numpy(), *shape), mdp.horizon)
        mu_model = phi.T @ np.asarray(visits(mdp.P, policy, mdp.p0)).sum(axis=0)
        opt.zero_grad()
        w.grad = torch.as_tensor(mu_model - mu_expert)      # minus the log-likelihood's gradient
        opt.step()
    return w.detach().numpy().copy()


class GailDiscriminator(torch.nn.Module):
    """GAIL's discriminator logit ``l(s, a) = phi(s) . W[:, a] + b[a]`` (``D = sigmoid(l)``, the probability
    that ``(s, a)`` is the expert's): linear in the state features, one weight vector per action."""

    def __init__(self, features: np.ndarray, n_actions: int):
        super().__init__()
        self.register_buffer("phi", torch.as_tensor(np.asarray(features), dtype=torch.float64))
        self.W = torch.nn.Parameter(torch.zeros(self.phi.shape[1], n_actions, dtype=torch.float64))
        self.b = torch.nn.Parameter(torch.zeros(n_actions, dtype=torch.float64))

    def table(self) -> torch.Tensor:
        """Logits of every state and action, ``(S, A)``."""
        return self.phi @ self.W + self.b

    def forward(self, states, actions) -> torch.Tensor:
        return self.table()[torch.as_tensor(states), torch.as_tensor(actions)]


class AirlDiscriminator(torch.nn.Module):
    """AIRL's reward and shaping terms: ``g(s) = phi(s) . w`` (state-only, linear in the features, the
    reward meant to transfer) and a free potential ``h(s)``, one number per state."""

    def __init__(self, features: np.ndarray):
        super().__init__()
        self.register_buffer("phi", torch.as_tensor(np.asarray(features), dtype=torch.float64))
        self.w = torch.nn.Parameter(torch.zeros(self.phi.shape[1], dtype=torch.float64))
        self.h = torch.nn.Parameter(torch.zeros(self.phi.shape[0], dtype=torch.float64))

    def g(self) -> torch.Tensor:
        """``g(s)`` for every state, ``(S,)``."""
        return self.phi @ self.w


def airl_expected_logits(disc: AirlDiscriminator, P: np.ndarray, log_pi: np.ndarray, gamma: float,
                         airl_logits: Callable) -> torch.Tensor:
    """AIRL's logits averaged over the next state, ``(T, S, A)``, from the student's ``airl_logits``:
    ``f`` is linear in ``h(s')``, so passing ``sum_s' P[s, a, s'] h(s')`` gives ``E_s'[f] - log pi``;
    ``done`` is 1 at ``t = T - 1`` only."""
    horizon = log_pi.shape[0]
    n_states, n_actions = P.shape[:2]
    h = disc.h
    h_next = (torch.as_tensor(_flat(P).toarray()) @ h).reshape(n_states, n_actions)
    done = torch.zeros(horizon, 1, 1, dtype=torch.float64)
    done[-1] = 1.0
    return airl_logits(disc.g()[None, :, None], h[None, :, None], h_next[None], torch.as_tensor(log_pi), gamma, done)


def train_adversarial(mdp: GridMDP, demos: Transitions, kind: str, discriminator_loss: Callable,
                      policy_reward: Callable, airl_logits: Callable | None, plan: Callable, visits: Callable,
                      n_iters: int = 150, n_policy: int = 200, disc_steps: int = 5, lr: float = 0.05,
                      policy_step: float = 0.5, gamma: float = 0.9, seed: int = 0) -> dict:
    """GAIL (``kind="gail"``) or AIRL (``kind="airl"``) on a world with known dynamics.

    Each iteration: sample ``n_policy`` trajectories of the current policy; take ``disc_steps`` Adam steps
    (``lr``) on ``discriminator_loss(expert_logits, policy_logits)``; then the policy step, through
    ``plan(P, reward, T)``, the soft-optimal policy of a ``(T, S, A)`` reward (the student's backward pass):

    - GAIL: the reward ``r_k(s, a) = policy_reward(l(s, a), "gail")`` of this round is added, times
      ``policy_step``, to a running sum, and the policy is ``plan`` of the sum (follow the regularised leader:
      the policy answers every discriminator so far, not only the last);
    - AIRL: the reward ``policy_reward(l, "airl") = f - log pi`` already holds the entropy term that ``plan``
      adds itself, so ``plan`` gets ``f`` (expected over ``s'``), the reward plus ``log pi``.

    Returns the discriminator, the final policy, GAIL's summed reward (``"reward_sum"``) and a history
    (``loss``, ``expert_accuracy``, ``policy_accuracy`` of the discriminator, ``score``: the normalised true
    return in ``mdp``, one entry per iteration).
    """
    if kind not in ("gail", "airl"):
        raise ValueError(f"kind must be 'gail' or 'airl', got {kind!r}")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    horizon, n_states, n_actions = mdp.horizon, mdp.n_states, mdp.n_actions
    disc = GailDiscriminator(mdp.features, n_actions) if kind == "gail" else AirlDiscriminator(mdp.features)
    opt = torch.optim.Adam(disc.parameters(), lr=lr)
    policy = np.full((horizon, n_states, n_actions), 1.0 / n_actions)
    reward_sum = np.zeros_like(policy)
    time_index = np.broadcast_to(np.arange(horizon), demos.states.shape)
    history = {"loss": [], "expert_accuracy": [], "policy_accuracy": [], "score": []}

    def logits_of(batch: Transitions, times: np.ndarray, log_pi: np.ndarray) -> torch.Tensor:
        s, a, s2 = (torch.as_tensor(x) for x in batch)
        if kind == "gail":
            return disc(s, a)
        done = torch.as_tensor((times == horizon - 1).astype(float))
        return airl_logits(disc.g()[s], disc.h[s], disc.h[s2], torch.as_tensor(log_pi[times, batch.states,
                                                                                    batch.actions]), gamma, done)

    for _ in range(n_iters):
        rollouts = sample_transitions(mdp.P, policy, mdp.p0, n_policy, rng)
        times_p = np.broadcast_to(np.arange(horizon), rollouts.states.shape)
        log_pi = np.log(np.maximum(policy, 1e-300))
        for _ in range(disc_steps):
            expert_logits = logits_of(demos, time_index, log_pi)
            policy_logits = logits_of(rollouts, times_p, log_pi)
            loss = discriminator_loss(expert_logits.reshape(-1), policy_logits.reshape(-1))
            opt.zero_grad()
            loss.backward()
            opt.step()
        history["loss"].append(float(loss.detach()))
        history["expert_accuracy"].append(float((expert_logits > 0).double().mean()))
        history["policy_accuracy"].append(float((policy_logits < 0).double().mean()))
        with torch.no_grad():
            if kind == "gail":
                reward_sum = reward_sum + policy_step * policy_reward(disc.table(), "gail").numpy()[None]
                policy = plan(mdp.P, reward_sum, horizon)
            else:
                logits = airl_expected_logits(disc, mdp.P, log_pi, gamma, airl_logits)
                policy = plan(mdp.P, policy_reward(logits, "airl").numpy() + log_pi, horizon)
        policy = np.asarray(policy)
        history["score"].append(normalised_return(mdp, policy, visits))
    return {"discriminator": disc, "policy": policy, "reward_sum": reward_sum, "kind": kind, "gamma": gamma,
            "scale": policy_step * n_iters, "history": {k: np.array(v) for k, v in history.items()}}


def transfer_rewards(result: dict, policy_reward: Callable, airl_logits: Callable | None, world: GridMDP) -> dict:
    """The rewards a trained learner hands to a new world, each ``(T, S, A)``. GAIL: its final
    discriminator's ``r(s, a)``, scaled by ``policy_step * n_iters`` (as if every round had said the same;
    unscaled it is too flat to plan on), and the running sum its own policy was planned on. AIRL: ``g(s)``
    alone, and its whole ``f = g + gamma h(s') - h(s)`` averaged over the *new* world's next states."""
    disc, horizon = result["discriminator"], world.horizon
    shape = (horizon, world.n_states, world.n_actions)
    with torch.no_grad():
        if result["kind"] == "gail":
            final = policy_reward(disc.table(), "gail").numpy()
            return {"GAIL r(s, a)": as_time_table(result["scale"] * final, *shape),
                    "GAIL sum of r": result["reward_sum"].copy()}
        f = airl_expected_logits(disc, world.P, np.zeros(shape), result["gamma"], airl_logits).numpy()
        return {"AIRL g(s)": as_time_table(disc.g().numpy(), *shape), "AIRL f(s, a, s')": f}


LEARNERS = ("BC policy", "MaxEnt r(s)", "GAIL policy", "GAIL r(s, a)", "GAIL sum of r", "AIRL policy", "AIRL g(s)",
            "AIRL f(s, a, s')")


def transfer_experiment(worlds: dict[str, GridMDP], seed: int, n_demos: int, discriminator_loss: Callable,
                        policy_reward: Callable, airl_logits: Callable, plan: Callable, visits: Callable,
                        n_iters: int = 150, airl_gamma: float = 0.9) -> dict:
    """One seed of the transfer test: ``n_demos`` expert demonstrations in ``worlds["original"]`` (drawn with
    ``seed``), BC, MaxEnt IRL, GAIL and AIRL fitted on them, then in every world the normalised true return
    (:func:`normalised_return`) of each learner's policy carried over unchanged (``"... policy"``) and of
    ``plan``'s policy trained from scratch in that world on each recovered reward.
    Returns ``{"scores": {learner: {world: score}}, "gail": ..., "airl": ..., "maxent_weights": ..., "demos": ...}``."""
    train = worlds["original"]
    shape = (train.horizon, train.n_states, train.n_actions)
    demos = sample_transitions(train.P, train.expert_policy(), train.p0, n_demos, np.random.default_rng(seed))
    bc = behaviour_cloning(demos, *shape[1:], train.horizon)
    w = fit_maxent_weights(train, demos, plan, visits)
    gail = train_adversarial(train, demos, "gail", discriminator_loss, policy_reward, None, plan, visits,
                             n_iters=n_iters, seed=seed)
    airl = train_adversarial(train, demos, "airl", discriminator_loss, policy_reward, airl_logits, plan, visits,
                             n_iters=n_iters, gamma=airl_gamma, seed=seed)
    scores = {name: {} for name in LEARNERS}
    for world_name, world in worlds.items():
        rewards = {"MaxEnt r(s)": as_time_table(train.features @ w, *shape)}
        rewards.update(transfer_rewards(gail, policy_reward, None, world))
        rewards.update(transfer_rewards(airl, policy_reward, airl_logits, world))
        policies = {"BC policy": bc, "GAIL policy": gail["policy"], "AIRL policy": airl["policy"]}
        policies.update({k: np.asarray(plan(world.P, r, world.horizon)) for k, r in rewards.items()})
        for name in LEARNERS:
            scores[name][world_name] = normalised_return(world, policies[name], visits)
    return {"scores": scores, "gail": gail, "airl": airl, "maxent_weights": w, "demos": demos}
