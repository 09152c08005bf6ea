"""The feedback spectrum measured: a simulated panel of annotators who rate, compare or rank the
same Hopper segments for the same total effort, and linear reward models fitted from each answer type.

**One perception, three answers.** When annotator ``k`` looks at segment ``i`` at second ``t`` of
their session, they perceive ``v = R_i / T + g`` with ``R_i`` the true return, ``T`` the temperature
(return units per logit; 2.0 as hw3's shipped annotator) and ``g`` fresh standard Gumbel noise,
centred. What they report depends on what they are asked:

* a **rating** on the 1–10 scale: ``y = clip(round(c + a_k * kappa * (v - m) + b_k + delta_k(t)), 1, 10)``
  with the scale's centre ``c = 5.5``, ``kappa`` rating points per logit (the pool's middle 99 %
  spans the scale), ``m`` the pool's mean of ``R / T``, a personal scale ``a_k = exp(N(0, scale_sd^2))``,
  a personal offset ``b_k ~ N(0, offset_sd^2)`` and a **drift** ``delta_k``, a Gaussian random walk
  in rating points whose standard deviation after 600 s of labelling is ``drift``;
* a **comparison** of two segments seen side by side at the same moment: the larger ``v`` wins,
  and a difference smaller than ``tie_margin`` (logits) is a tie. Offset, scale and drift are the
  same for both clips, so they cancel (lecture 4, eq. ``eq-within-cancel``);
* a **ranking** of ``k`` segments seen together, best first, by ``v``: with Gumbel noise this is
  exactly a Plackett–Luce draw with utilities ``R / T``.

The per-view noise is the same in all three, so the differences between them come only from what a
rating adds (offsets, scales, drift, rounding and clipping) and from what each answer costs.

**Effort.** Labels are bought with seconds (:data:`SECONDS_PER_LABEL`): a comparison costs 4 s,
from Christiano et al. (2017), whose Hopper backflip took about 900 comparisons of 1–2 s clips in
under an hour of human time (at most 4 s each). The 3 s for a rating of one clip and the 8 s for a
ranking of four are *assumptions* of this course (one clip watched instead of two; four clips
instead of two), not measured figures. Annotators take turns, so each works ``budget / n_annotators``
seconds.

**Reward models.** Every model is linear in :func:`segment_features` (sums over a segment's real
steps of the observation, the squared action and a constant), so it is fitted in milliseconds and
the section stays cheap: regression on the ratings (pooled, or with one offset per annotator),
Bradley–Terry on comparisons (the half-win convention of hw3), Plackett–Luce on rankings. Each is
scored as hw3 scores its reward ensembles: held-out accuracy on the shipped test labels, divided by
the Bayes ceiling.

The conversion of ratings into within-annotator comparisons is hw3's stub ``ratings_to_comparisons``;
no function here computes it (:func:`run_budget` takes it as an argument).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_expit

from rlcourse.preferences import HopperPreferences, preference_accuracy

SECONDS_PER_LABEL = {"rating": 3.0, "comparison": 4.0, "ranking": 8.0}
"""seconds an annotator spends per answer: comparison from Christiano et al. (2017); the others assumed"""
RANK_K = 4
"""segments per ranking query"""
DRIFT_SECONDS = 600.0
"""``drift`` is the standard deviation (rating points) of the offset's random walk after this many seconds"""
RATING_CENTRE, RATING_MIN, RATING_MAX = 5.5, 1, 10
EULER_GAMMA = 0.5772156649015329
METHODS = ("ratings: regression", "ratings: per-annotator offsets", "ratings: within-annotator comparisons",
           "comparisons", f"rankings of {RANK_K}")
"""the five reward models, in the order the tables list them"""


# --------------------------------------------------------------------------- features
def segment_features(prefs: HopperPreferences) -> np.ndarray:
    """``(N, 15)`` per-segment features: sums over the real (not absorbing) steps of the 11 observation
    entries, the 3 squared actions and a constant 1, each column standardised over all segments.
    A linear reward of these is a linear per-step reward summed over the segment."""
    real = ~prefs.absorbing                                                   # (N, L)
    per_step = np.concatenate([prefs.obs, prefs.act ** 2, np.ones(prefs.obs.shape[:2] + (1,), np.float32)], -1)
    f = (per_step * real[..., None]).sum(1).astype(float)
    return (f - f.mean(0)) / (f.std(0) + 1e-12)


# --------------------------------------------------------------------------- the panel
@dataclass(frozen=True)
class Panel:
    """Who labels: ``n_annotators`` taking turns, with rating offsets ``N(0, offset_sd^2)`` (points),
    log-scales ``N(0, scale_sd^2)`` and a drift (points of standard deviation after ``DRIFT_SECONDS``)."""

    n_annotators: int = 1
    offset_sd: float = 0.0
    scale_sd: float = 0.0
    drift: float = 0.0
    temperature: float = 2.0
    tie_margin: float = 0.4


def _perceive(returns: np.ndarray, idx: np.ndarray, temperature: float, rng: np.random.Generator) -> np.ndarray:
    """``R[idx] / T`` plus centred standard Gumbel noise, one fresh draw per view; ``idx``'s shape."""
    return returns[idx] / temperature + rng.gumbel(size=np.shape(idx)) - EULER_GAMMA


def _turns(n_labels: int, panel: Panel, seconds: float, rng: np.random.Generator):
    """Who answers label ``m`` (round robin), and their offset ``b_k + delta_k(t)`` and scale at that moment."""
    who = np.arange(n_labels) % panel.n_annotators
    offset = rng.normal(0.0, panel.offset_sd, panel.n_annotators)
    scale = np.exp(rng.normal(0.0, panel.scale_sd, panel.n_annotators))
    step_sd = panel.drift * np.sqrt(seconds / DRIFT_SECONDS)                  # random-walk step per label
    walk = np.zeros(n_labels)
    for k in range(panel.n_annotators):
        mine = who == k
        walk[mine] = np.cumsum(rng.normal(0.0, step_sd, mine.sum()))
    return who, offset[who] + walk, scale[who]


def rating_spread(returns: np.ndarray, temperature: float) -> tuple[float, float]:
    """``(m, kappa)``: the pool's mean of ``R / T`` and the rating points per logit that map the pool's
    0.5 and 99.5 percentiles onto the ends of the 1–10 scale."""
    v = np.asarray(returns, dtype=float) / temperature
    lo, hi = np.percentile(v, [0.5, 99.5])
    return float(v.mean()), float((RATING_MAX - RATING_MIN) / (hi - lo))


def simulate_ratings(returns: np.ndarray, segments: np.ndarray, panel: Panel, rng: np.random.Generator,
                     spread: tuple[float, float]) -> dict[str, np.ndarray]:
    """Ratings of ``segments`` (in session order): ``segment``, ``annotator``, ``rating`` (ints 1..10)."""
    segments = np.asarray(segments)
    who, offset, scale = _turns(len(segments), panel, SECONDS_PER_LABEL["rating"], rng)
    m, kappa = spread
    latent = RATING_CENTRE + scale * kappa * (_perceive(returns, segments, panel.temperature, rng) - m) + offset
    rating = np.clip(np.round(latent), RATING_MIN, RATING_MAX).astype(np.int64)
    return {"segment": segments, "annotator": who, "rating": rating}


def simulate_comparisons(returns: np.ndarray, pairs: np.ndarray, panel: Panel,
                         rng: np.random.Generator) -> np.ndarray:
    """Labels ``mu`` (1: first better, 0.5: tie, 0: second) for ``pairs`` ``(n, 2)`` seen side by side.
    Offsets, scales and drift are shared by the two clips of a pair, so they do not enter."""
    v = _perceive(returns, np.asarray(pairs), panel.temperature, rng)
    d = v[:, 0] - v[:, 1]
    return np.where(np.abs(d) < panel.tie_margin, 0.5, (d > 0).astype(float))


def simulate_rankings(returns: np.ndarray, groups: np.ndarray, panel: Panel, rng: np.random.Generator) -> np.ndarray:
    """For ``groups`` ``(n, k)`` of segments, ``(n, k)`` positions into each row, best first."""
    v = _perceive(returns, np.asarray(groups), panel.temperature, rng)
    return np.argsort(-v, axis=1, kind="stable")


# --------------------------------------------------------------------------- reward models (linear)
def fit_regression(X: np.ndarray, y: np.ndarray, groups: np.ndarray | None = None, ridge: float = 1e-3) -> np.ndarray:
    """Least squares ``y ~ X w + intercept`` (one intercept per group when ``groups`` is given); returns ``w``."""
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    g = np.zeros(len(y), dtype=np.int64) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
    D = np.concatenate([X, np.eye(g.max() + 1)[g]], 1)
    reg = np.r_[np.full(X.shape[1], ridge), np.zeros(g.max() + 1)] * len(y)
    coef = np.linalg.solve(D.T @ D + np.diag(reg), D.T @ y)
    return coef[:X.shape[1]]


def fit_bradley_terry_linear(X: np.ndarray, pairs: np.ndarray, mu: np.ndarray, l2: float = 1e-3) -> np.ndarray:
    """``w`` minimising the mean half-win Bradley–Terry cross-entropy of ``(X[a] - X[b]) w`` plus ``l2 |w|^2``."""
    X, pairs, mu = np.asarray(X, dtype=float), np.asarray(pairs), np.asarray(mu, dtype=float)
    if len(mu) == 0:
        return np.zeros(X.shape[1])
    Z = X[pairs[:, 0]] - X[pairs[:, 1]]

    def f(w):
        d = Z @ w
        loss = -np.mean(mu * log_expit(d) + (1 - mu) * log_expit(-d)) + l2 * w @ w
        grad = Z.T @ (np.exp(log_expit(d)) - mu) / len(mu) + 2 * l2 * w
        return loss, grad
    return minimize(f, np.zeros(X.shape[1]), jac=True, method="BFGS", options={"gtol": 1e-6}).x


def fit_plackett_luce_linear(X: np.ndarray, groups: np.ndarray, order: np.ndarray, l2: float = 1e-3) -> np.ndarray:
    """``w`` minimising the mean Plackett–Luce negative log-likelihood of ``order`` (positions into each
    row of ``groups``, best first) under scores ``X w``, plus ``l2 |w|^2``."""
    X = np.asarray(X, dtype=float)
    F = X[np.take_along_axis(np.asarray(groups), np.asarray(order), 1)]       # (n, k, d), best first

    def f(w):
        s = F @ w                                                              # (n, k)
        lse = np.logaddexp.accumulate(s[:, ::-1], axis=1)[:, ::-1]             # log sum over the rest
        loss = np.mean((lse - s).sum(1)) + l2 * w @ w
        # d lse_j / d s_l = softmax over l >= j; gradient of sum_j (lse_j - s_j)
        p = np.exp(s[:, None, :] - lse[:, :, None]) * np.triu(np.ones((s.shape[1],) * 2))[None]
        ds = p.sum(1) - 1.0                                                    # (n, k)
        return loss, np.einsum("nk,nkd->d", ds, F) / len(s) + 2 * l2 * w
    return minimize(f, np.zeros(X.shape[1]), jac=True, method="BFGS", options={"gtol": 1e-6}).x


def accuracy_to_ceiling(scores: np.ndarray, prefs: HopperPreferences) -> float:
    """hw3's measure: held-out accuracy of ``scores`` on the shipped test labels over the Bayes ceiling."""
    acc = preference_accuracy(scores[prefs.test_pairs[:, 0]], scores[prefs.test_pairs[:, 1]], prefs.test_mu)
    return acc / prefs.info["bayes_ceiling_test"]


# --------------------------------------------------------------------------- the experiment
def labels_for_budget(seconds: float) -> dict[str, int]:
    """How many answers of each type ``seconds`` of annotator time buy."""
    return {kind: int(seconds // cost) for kind, cost in SECONDS_PER_LABEL.items()}


def run_budget(prefs: HopperPreferences, features: np.ndarray, panel: Panel, seconds: float, seed: int,
               to_comparisons: Callable, window: int = 5) -> dict[str, float]:
    """Accuracy over the ceiling of the five reward models (:data:`METHODS`) from ``seconds`` of annotation.

    Segments are drawn uniformly from the training segments (those not held out), afresh per answer
    type; every draw of ``seed`` is independent of the others. ``to_comparisons(annotator, segment,
    rating, window)`` converts ratings to within-annotator comparisons: hw3's stub of that name, which
    this module does not define (the notebook passes the student's function, the bench its own copy).
    """
    returns = prefs.returns
    pool = np.flatnonzero(~prefs.test_segment)
    n = labels_for_budget(seconds)
    rng = np.random.default_rng([seed, int(seconds)])
    spread = rating_spread(returns[pool], panel.temperature)
    out = {}

    rated = simulate_ratings(returns, rng.choice(pool, n["rating"]), panel, rng, spread)
    out[METHODS[0]] = fit_regression(features[rated["segment"]], rated["rating"])
    out[METHODS[1]] = fit_regression(features[rated["segment"]], rated["rating"], groups=rated["annotator"])
    pairs, mu = to_comparisons(rated["annotator"], rated["segment"], rated["rating"], window)
    out[METHODS[2]] = fit_bradley_terry_linear(features, np.asarray(pairs), np.asarray(mu))

    compared = np.stack([rng.choice(pool, n["comparison"]), rng.choice(pool, n["comparison"])], 1)
    compared = compared[compared[:, 0] != compared[:, 1]]
    out[METHODS[3]] = fit_bradley_terry_linear(features, compared, simulate_comparisons(returns, compared, panel, rng))

    groups = np.stack([rng.choice(pool, RANK_K, replace=False) for _ in range(n["ranking"])]) if n["ranking"] \
        else np.zeros((0, RANK_K), np.int64)
    out[METHODS[4]] = (fit_plackett_luce_linear(features, groups, simulate_rankings(returns, groups, panel, rng))
                       if len(groups) else np.zeros(features.shape[1]))
    return {k: accuracy_to_ceiling(features @ w, prefs) for k, w in out.items()}


def run_grid(prefs: HopperPreferences, features: np.ndarray, panels: dict[str, Panel], budgets: Sequence[float],
             seeds: Sequence[int], **kwargs) -> dict[str, dict[str, np.ndarray]]:
    """``{panel name: {method: (n_seeds, n_budgets) accuracy over the ceiling}}``."""
    out = {}
    for name, panel in panels.items():
        table = {m: np.zeros((len(seeds), len(budgets))) for m in METHODS}
        for s, seed in enumerate(seeds):
            for b, seconds in enumerate(budgets):
                for m, value in run_budget(prefs, features, panel, seconds, seed, **kwargs).items():
                    table[m][s, b] = value
        out[name] = table
    return out


def retest_correlation(first: np.ndarray, second: np.ndarray) -> float:
    """Pearson correlation of two ratings of the same clips (nan when either is constant)."""
    first, second = np.asarray(first, dtype=float), np.asarray(second, dtype=float)
    if len(first) < 2 or first.std() == 0 or second.std() == 0:
        return float("nan")
    return float(np.corrcoef(first, second)[0, 1])


def rating_comparison_agreement(pairs: np.ndarray, mu: np.ndarray, clip_index: np.ndarray,
                                ratings: np.ndarray) -> float:
    """Of the strict comparisons ``(pairs, mu)``, the fraction whose winner the ratings also rate higher
    (equal ratings count one half). ``clip_index`` maps a segment to its position in ``ratings``."""
    pairs, mu = np.asarray(pairs), np.asarray(mu, dtype=float)
    strict = mu != 0.5
    if not strict.any():
        return float("nan")
    lookup = {int(s): i for i, s in enumerate(clip_index)}
    ra = np.array([ratings[lookup[int(s)]] for s in pairs[strict, 0]], dtype=float)
    rb = np.array([ratings[lookup[int(s)]] for s in pairs[strict, 1]], dtype=float)
    sign = np.sign(ra - rb) * np.where(mu[strict] == 1.0, 1.0, -1.0)
    return float(np.mean(np.where(sign == 0, 0.5, sign > 0)))
