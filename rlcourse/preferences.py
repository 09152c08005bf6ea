"""Preference data: the tie model, a simulated annotator, the shipped data sets, a dueling-bandit
environment and the reward-ensemble container used by ``hw3_preferences`` and ``hw4_rlhf_dpo``.

**The tie model (Rao and Kupper, 1967).** With a utility (or scaled return) difference
``d = u_i - u_j`` and a tie parameter ``theta >= 1`` (``eta = log theta``)::

    P(i beats j) = sigmoid(d - eta)
    P(j beats i) = sigmoid(-d - eta)
    P(tie)       = 1 - P(i beats j) - P(j beats i)

which is Bradley–Terry with a dead zone of half-width ``eta`` on the logistic scale (with
``eta = 0`` there are no ties). A comparison is recorded as a label ``mu`` in ``{1, 0.5, 0}``:
1 when the first item wins, 0 when the second wins, 0.5 for a tie. Models in the course are
fitted by the Bradley–Terry cross-entropy with ``mu`` as a soft target, so a tie counts as half
a win for each side (the "half-win" convention). For small ``eta`` the expected label
``P(win) + P(tie) / 2`` equals ``sigmoid(d)`` up to a term of order ``eta**2``, which is why
this fit recovers the utilities of Rao–Kupper data almost without bias.

**The simulated annotator** compares two segments by their true returns ``R_a, R_b``:
``d = (R_a - R_b) / temperature`` goes through the tie model above, then each strict label
(not a tie) is flipped with probability ``flip_rate`` (annotator error). The Bayes-optimal
prediction is therefore "the segment with the higher true return", and its accuracy on strict
labels is the ceiling that no reward model beats in expectation.

No function here solves an assignment's stub: these are the environment and the data the
stubs are run against.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import numpy as np
import torch
from scipy.special import expit
from torch import nn

from rlcourse import data as _data
from rlcourse.nets import mlp

ITEMS_FILE = "items/comparisons.npz"
ITEMS_UTILITIES_FILE = "items/true_utilities.npz"
HOPPER_PREFS_UPRIGHT_FILE = "hopper_prefs/hopper_prefs.npz"
"""the first Hopper set: every segment shows a robot still upright (kept: earlier results were measured on it)"""
HOPPER_PREFS_FILE = "hopper_prefs/hopper_prefs_falls.npz"
"""the course's Hopper set: the upright set plus segments that end in a fall and pairs that contain them"""


# --------------------------------------------------------------------------- tie model and annotator
def rao_kupper_probabilities(diff: np.ndarray, log_theta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(P(first wins), P(tie), P(second wins))`` for differences ``diff`` (any shape), each of ``diff``'s shape."""
    if log_theta < 0:
        raise ValueError(f"log_theta must be >= 0 (theta >= 1), got {log_theta}")
    diff = np.asarray(diff, dtype=float)
    win, loss = expit(diff - log_theta), expit(-diff - log_theta)
    return win, 1.0 - win - loss, loss


def sample_labels(diff: np.ndarray, log_theta: float, rng: np.random.Generator) -> np.ndarray:
    """Labels in ``{1, 0.5, 0}`` drawn from the Rao–Kupper model at differences ``diff``; same shape, float32."""
    win, tie, _ = rao_kupper_probabilities(diff, log_theta)
    u = rng.random(np.shape(win))
    return np.where(u < win, 1.0, np.where(u < win + tie, 0.5, 0.0)).astype(np.float32)


def simulate_annotator(returns_a: np.ndarray, returns_b: np.ndarray, temperature: float, flip_rate: float,
                       log_theta: float, rng: np.random.Generator) -> np.ndarray:
    """Labels ``mu`` (1: ``a`` preferred, 0.5: tie, 0: ``b`` preferred) from a noisy annotator.

    ``d = (returns_a - returns_b) / temperature`` goes through the Rao–Kupper tie model, then each
    strict label is flipped with probability ``flip_rate``. Shapes: ``(n,)`` in, ``(n,)`` float32 out.
    """
    if temperature <= 0 or not 0 <= flip_rate < 0.5:
        raise ValueError(f"need temperature > 0 and 0 <= flip_rate < 0.5, got {temperature}, {flip_rate}")
    diff = (np.asarray(returns_a, dtype=float) - np.asarray(returns_b, dtype=float)) / temperature
    mu = sample_labels(diff, log_theta, rng)
    flip = (rng.random(mu.shape) < flip_rate) & (mu != 0.5)
    return np.where(flip, 1.0 - mu, mu).astype(np.float32)


def expected_bayes_accuracy(returns_a: np.ndarray, returns_b: np.ndarray, temperature: float, flip_rate: float,
                            log_theta: float) -> float:
    """Expected accuracy, on strict labels, of predicting the higher true return (the annotator's own model).

    Each pair counts in proportion to its chance of getting a strict label.
    """
    diff = np.abs(np.asarray(returns_a, dtype=float) - np.asarray(returns_b, dtype=float)) / temperature
    right, _, wrong = rao_kupper_probabilities(diff, log_theta)
    correct = (1 - flip_rate) * right + flip_rate * wrong
    return float(correct.sum() / (right + wrong).sum())


def preference_accuracy(score_a: np.ndarray, score_b: np.ndarray, mu: np.ndarray) -> float:
    """Fraction of strict labels (``mu`` 0 or 1) whose winner has the higher score; ties are left out.

    A predicted tie (equal scores) counts as half right.
    """
    score_a, score_b, mu = (np.asarray(x, dtype=float) for x in (score_a, score_b, mu))
    strict = mu != 0.5
    if not strict.any():
        raise ValueError("no strict labels to score")
    sign = np.sign(score_a - score_b)[strict]
    target = np.where(mu[strict] == 1.0, 1.0, -1.0)
    return float(np.mean(np.where(sign == 0, 0.5, sign == target)))


def random_pairs(candidates: np.ndarray, n_pairs: int, rng: np.random.Generator) -> np.ndarray:
    """``(n_pairs, 2)`` int64 pairs of distinct elements of ``candidates`` drawn uniformly (with repetition)."""
    candidates = np.asarray(candidates)
    first = rng.integers(len(candidates), size=n_pairs)
    second = (first + rng.integers(1, len(candidates), size=n_pairs)) % len(candidates)
    return np.stack([candidates[first], candidates[second]], axis=1).astype(np.int64)


def win_counts(n_items: int, i: np.ndarray, j: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Empirical ``(wins, games)``, both ``(n_items, n_items)``: ``wins[a, b]`` sums ``a``'s labels against ``b``
    (a tie adds 0.5 to each side) and ``games[a, b]`` counts their comparisons (symmetric)."""
    i, j, mu = np.asarray(i), np.asarray(j), np.asarray(mu, dtype=float)
    wins = np.zeros((n_items, n_items))
    np.add.at(wins, (i, j), mu)
    np.add.at(wins, (j, i), 1.0 - mu)
    games = np.zeros((n_items, n_items))
    np.add.at(games, (i, j), 1.0)
    return wins, games + games.T


# --------------------------------------------------------------------------- shipped data
def load_items() -> dict[str, Any]:
    """The item comparisons: ``i``, ``j`` (``(M,)`` int64), ``mu`` (``(M,)`` float32), ``n_items``,
    the hidden ``utilities`` (``(n_items,)``, mean zero) and the MANIFEST ``info`` (tie model, seed)."""
    comps = _data.load_npz(ITEMS_FILE)
    truth = _data.load_npz(ITEMS_UTILITIES_FILE)
    return {"i": comps["i"].astype(np.int64), "j": comps["j"].astype(np.int64), "mu": comps["mu"],
            "n_items": int(truth["utilities"].shape[0]), "utilities": truth["utilities"],
            "info": _data.info(ITEMS_FILE)["info"]}


@dataclass
class HopperPreferences:
    """The Hopper segment pool and its labelled pairs.

    Shapes (``N`` segments of ``L`` steps): ``obs`` ``(N, L, 11)`` float32 (stored as float16),
    ``act`` ``(N, L, 3)`` float32, ``rewards`` ``(N, L)`` float32 true rewards, ``returns`` ``(N,)``,
    ``source`` ``(N,)`` index into ``source_names`` (the policy that produced the segment),
    ``test_segment`` ``(N,)`` bool (segments of held-out episodes); ``train_pairs`` ``(M, 2)`` and
    ``test_pairs`` ``(M_test, 2)`` index segments, ``train_mu`` and ``test_mu`` are their labels.
    ``terminated`` ``(N,)`` bool marks segments that contain a fall: their first ``length`` steps are
    real and the rest are the absorbing state after the fall (reward 0, action 0, the last real
    observation repeated as a placeholder); ``absorbing`` is that ``(N, L)`` mask.
    """

    obs: np.ndarray
    act: np.ndarray
    rewards: np.ndarray
    source: np.ndarray
    test_segment: np.ndarray
    train_pairs: np.ndarray
    train_mu: np.ndarray
    test_pairs: np.ndarray
    test_mu: np.ndarray
    rollout_obs: np.ndarray
    rollout_act: np.ndarray
    rollout_rewards: np.ndarray
    rollout_length: np.ndarray
    source_names: list[str]
    info: dict[str, Any] = field(default_factory=dict)
    terminated: Optional[np.ndarray] = None
    length: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        n, seg_len = self.obs.shape[:2]
        if self.terminated is None:  # the upright set: no falls
            self.terminated = np.zeros(n, dtype=bool)
        if self.length is None:
            self.length = np.full(n, seg_len, dtype=np.int64)

    @property
    def absorbing(self) -> np.ndarray:
        """``(N, L)`` bool: True on the steps after a segment's fall (the absorbing state)."""
        return np.arange(self.obs.shape[1]) >= self.length[:, None]

    @property
    def returns(self) -> np.ndarray:
        """True return of each segment, ``(N,)`` float64."""
        return self.rewards.astype(float).sum(axis=1)

    def annotate(self, pairs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Fresh labels for ``pairs`` ``(n, 2)`` from the same simulated annotator that labelled the data."""
        r = self.returns
        return simulate_annotator(r[pairs[:, 0]], r[pairs[:, 1]], self.info["temperature"],
                                  self.info["flip_rate"], self.info["log_theta"], rng)


def load_hopper_preferences(name: str = HOPPER_PREFS_FILE) -> HopperPreferences:
    """A shipped Hopper preference data set (by default the one with falls), verified against the MANIFEST."""
    d = _data.load_npz(name)
    falls = {"terminated": d["terminated"], "length": d["length"].astype(np.int64)} if "terminated" in d else {}
    return HopperPreferences(
        obs=d["obs"].astype(np.float32), act=d["act"].astype(np.float32), rewards=d["rewards"].astype(np.float32),
        source=d["source"], test_segment=d["test_segment"], train_pairs=d["train_pairs"].astype(np.int64),
        train_mu=d["train_mu"], test_pairs=d["test_pairs"].astype(np.int64), test_mu=d["test_mu"],
        rollout_obs=d["rollout_obs"].astype(np.float32), rollout_act=d["rollout_act"].astype(np.float32),
        rollout_rewards=d["rollout_rewards"].astype(np.float32), rollout_length=d["rollout_length"].astype(np.int64),
        source_names=[str(s) for s in d["source_names"]], info=_data.info(name)["info"], **falls)


# --------------------------------------------------------------------------- dueling bandits
class DuelingBandit:
    """A K-armed dueling bandit: ``duel(i, j)`` returns 1.0 when arm ``i`` wins, else 0.0.

    ``P[i, j]`` is the probability that ``i`` beats ``j`` (``P + P.T = 1``, diagonal 1/2).
    Duels are drawn from the environment's own seeded generator; ``n_duels`` counts them. An
    algorithm learns about ``P`` only through ``duel`` (the matrix is kept private).
    """

    def __init__(self, P: np.ndarray, seed: int = 0) -> None:
        P = np.asarray(P, dtype=float)
        if P.ndim != 2 or P.shape[0] != P.shape[1]:
            raise ValueError(f"P must be a square matrix, got shape {P.shape}")
        if not np.allclose(P + P.T, 1.0):
            raise ValueError("P must satisfy P[i, j] + P[j, i] = 1 (with 1/2 on the diagonal)")
        self._P, self.n_arms, self.n_duels = P, P.shape[0], 0
        self._rng = np.random.default_rng(seed)

    def duel(self, i: int, j: int) -> float:
        """One noisy comparison: 1.0 when arm ``i`` beats arm ``j`` (probability ``P[i, j]``), else 0.0."""
        self.n_duels += 1
        return float(self._rng.random() < self._P[int(i), int(j)])


def dueling_regret(P: np.ndarray, pairs: np.ndarray, winner: int) -> np.ndarray:
    """Per-step regret ``(P[c, a] + P[c, b] - 1) / 2`` of each duel ``(a, b)`` in ``pairs`` ``(T, 2)``,
    against the Condorcet winner ``c = winner`` (Zoghi et al. 2014), which the caller names.

    It is not found here, nor checked: a function that found it would answer hw3's ``condorcet_winner``.
    """
    P, pairs = np.asarray(P, dtype=float), np.asarray(pairs)
    if not 0 <= int(winner) < P.shape[0]:
        raise ValueError(f"winner {winner} is not an arm of this {P.shape[0]}-armed bandit")
    return (P[winner, pairs[:, 0]] + P[winner, pairs[:, 1]] - 1.0) / 2.0


def uniform_pairs(env: DuelingBandit, horizon: int, rng: np.random.Generator) -> np.ndarray:
    """The baseline: duel a uniformly random pair of distinct arms at every step; ``(horizon, 2)`` int64."""
    pairs = random_pairs(np.arange(env.n_arms), horizon, rng)
    for a, b in pairs:
        env.duel(a, b)
    return pairs


# --------------------------------------------------------------------------- reward ensembles
class _Member(nn.Module):
    """One member of a :class:`RewardEnsemble`, seen alone: ``(obs, act) -> (...)`` reward per step."""

    def __init__(self, ensemble: "RewardEnsemble", k: int) -> None:
        super().__init__()
        self.net = ensemble.members[k]
        self._ensemble, self.k = [ensemble], k  # a list hides the parent from nn.Module's registry

    def forward(self, obs: torch.Tensor, act: torch.Tensor, absorbing: Optional[torch.Tensor] = None) -> torch.Tensor:
        ens = self._ensemble[0]
        raw = self.net(ens.scale_inputs(obs, act)).squeeze(-1)
        if absorbing is not None:
            raw = torch.where(torch.as_tensor(absorbing, dtype=torch.bool), ens.absorbing_reward[self.k], raw)
        return (raw - ens.out_mean[self.k]) / ens.out_std[self.k]


class RewardEnsemble(nn.Module):
    """``n_members`` small MLPs, each mapping one step's ``(obs, act)`` to a scalar reward.

    With ``absorbing=True`` each member also holds one learned number, ``absorbing_reward[k]`` (a
    parameter, in the member's raw output units): the reward of the absorbing state after a fall.
    Passing an ``absorbing`` mask (the shape of the steps) to ``forward``, ``member(k)`` or
    ``predict`` puts that number on the masked steps instead of the network's output, so segments
    that end in a fall are scored as the data describes them, and comparisons against them identify
    the per-step constant that equal-length upright segments cannot.

    Calling the ensemble on ``obs`` ``(..., obs_dim)`` and ``act`` ``(..., act_dim)`` (tensors or
    arrays) gives ``(n_members, ...)`` per-step rewards. Inputs are standardised with statistics
    set by :meth:`set_input_scaling`; each member's output is shifted and scaled by
    :meth:`normalise_` so that it has mean 0 and standard deviation 1 on the data given (before
    that call the output is the raw network output). ``member(k)`` is member ``k`` alone,
    ``(obs, act) -> (...)``, whose ``parameters()`` are that member's weights.
    Initialisation is seeded by ``seed`` and leaves the global torch generator untouched.
    """

    def __init__(self, obs_dim: int, act_dim: int, n_members: int = 3, hidden: Sequence[int] = (64, 64),
                 seed: int = 0, absorbing: bool = False) -> None:
        super().__init__()
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            self.members = nn.ModuleList(mlp([obs_dim + act_dim, *hidden, 1], "relu") for _ in range(n_members))
        self.obs_dim, self.act_dim, self.n_members, self.hidden = obs_dim, act_dim, n_members, list(hidden)
        self.register_buffer("in_mean", torch.zeros(obs_dim + act_dim))
        self.register_buffer("in_std", torch.ones(obs_dim + act_dim))
        self.register_buffer("out_mean", torch.zeros(n_members))
        self.register_buffer("out_std", torch.ones(n_members))
        self.has_absorbing = absorbing
        if absorbing:
            self.absorbing_reward = nn.Parameter(torch.zeros(n_members))

    def scale_inputs(self, obs, act) -> torch.Tensor:
        x = torch.cat([torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)], -1)
        return (x - self.in_mean) / self.in_std

    @torch.no_grad()
    def set_input_scaling(self, obs, act) -> None:
        """Standardise inputs with the mean and standard deviation of the given steps (any leading shape)."""
        x = torch.cat([torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)], -1)
        x = x.reshape(-1, x.shape[-1])
        self.in_mean.copy_(x.mean(0))
        self.in_std.copy_(x.std(0).clamp_min(1e-6))

    def member(self, k: int) -> nn.Module:
        return _Member(self, k)

    def forward(self, obs, act, absorbing=None) -> torch.Tensor:
        x = self.scale_inputs(obs, act)
        raw = torch.stack([net(x).squeeze(-1) for net in self.members])  # (n_members, ...)
        shape = (-1,) + (1,) * (raw.dim() - 1)
        if absorbing is not None:
            if not self.has_absorbing:
                raise ValueError("this ensemble has no absorbing-state reward (made with absorbing=False)")
            raw = torch.where(torch.as_tensor(absorbing, dtype=torch.bool), self.absorbing_reward.view(shape), raw)
        return (raw - self.out_mean.view(shape)) / self.out_std.view(shape)

    @torch.no_grad()
    def absorbing_value(self) -> np.ndarray:
        """Each member's normalised reward of the absorbing state, ``(n_members,)``: what ``forward`` puts on
        masked steps."""
        if not self.has_absorbing:
            raise ValueError("this ensemble has no absorbing-state reward (made with absorbing=False)")
        return ((self.absorbing_reward - self.out_mean) / self.out_std).numpy()

    @torch.no_grad()
    def normalise_(self, obs, act) -> "RewardEnsemble":
        """Set each member's output offset and scale so its rewards on the given steps have mean 0, std 1."""
        self.out_mean.zero_()
        self.out_std.fill_(1.0)
        raw = self(obs, act).reshape(self.n_members, -1)
        self.out_mean.copy_(raw.mean(1))
        self.out_std.copy_(raw.std(1).clamp_min(1e-6))
        return self

    @torch.no_grad()
    def predict(self, obs, act, absorbing=None) -> np.ndarray:
        """Per-step rewards as a numpy array ``(n_members, ...)`` (no gradient); ``absorbing`` as in ``forward``."""
        return self(obs, act, absorbing).numpy()


# --------------------------------------------------------------------------- rendering
def render_segment(obs: np.ndarray, size: int = 160, env_id: str = "Hopper-v5") -> np.ndarray:
    """Frames ``(L, size, size, 3)`` uint8 that show a segment from its observations alone.

    A Hopper observation is the joint configuration without the horizontal position (``qpos[1:]``)
    followed by the velocities, and the horizontal position does not change the picture but for
    the camera; it is integrated from the forward velocity. Each frame sets the simulator's state
    and renders it; no physics is stepped.
    """
    import gymnasium as gym

    env = gym.make(env_id, render_mode="rgb_array", width=size, height=size)
    env.reset(seed=0)
    sim = env.unwrapped
    nq = sim.model.nq
    obs = np.asarray(obs, dtype=float)
    x = np.concatenate([[0.0], np.cumsum(obs[:-1, nq - 1] * sim.dt)])  # qvel[0] sits right after qpos[1:]
    frames = []
    for t in range(len(obs)):
        sim.set_state(np.concatenate([[x[t]], obs[t, : nq - 1]]), obs[t, nq - 1:])
        frames.append(env.render())
    env.close()
    return np.stack(frames)
