"""Formulas from the lecture notes (`lectures/`), written as the lectures state them.

Each function cites the equation label (e.g. `[eq-bt]`) it implements, so that
`tests/test_lecture_identities.py` can compare the formula with an independent
computation (enumeration, a generic optimiser, Monte Carlo, finite
differences).  Shapes are given in the docstrings; arrays are numpy.

Conventions (see `lectures/notation.md`):
  * dynamics ``P[s, a, s'] = P(s' | s, a)``, start distribution ``p0[s]``;
  * features ``f[s, a, k]``, so that ``F(tau) = sum_t gamma^t f(s_t, a_t)``;
  * time-dependent policies ``pi[t, s, a]``, stationary ones ``pi[s, a]``;
  * time runs ``t = 0, ..., T-1``.
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit, log_expit, logsumexp

# --------------------------------------------------------------------------
# Chapter 2: occupancy measures
# --------------------------------------------------------------------------


def state_marginals(P: np.ndarray, p0: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """State marginals ``d[t, s] = Pr(s_t = s)`` under a time-dependent policy.

    Recursion [eq-marginal-recursion]: ``d_0 = p0`` and
    ``d_{t+1}(s') = sum_{s,a} d_t(s) pi_t(a|s) P(s'|s,a)``.

    Args:
        P: dynamics, shape (S, A, S).
        p0: start distribution, shape (S,).
        pi: policy, shape (T, S, A).

    Returns:
        d: shape (T, S).
    """
    horizon = pi.shape[0]
    d = np.zeros((horizon, p0.shape[0]))
    d[0] = p0
    for t in range(horizon - 1):
        d[t + 1] = np.einsum("s,sa,sax->x", d[t], pi[t], P)
    return d


def occupancy_finite(
    P: np.ndarray, p0: np.ndarray, pi: np.ndarray, gamma: float = 1.0
) -> np.ndarray:
    """Finite-horizon discounted state-action occupancy [eq-occ-finite].

    ``rho(s, a) = sum_{t=0}^{T-1} gamma^t d_t(s) pi_t(a|s)``.

    Returns:
        rho: shape (S, A).
    """
    d = state_marginals(P, p0, pi)
    discounts = gamma ** np.arange(pi.shape[0])
    return np.einsum("t,ts,tsa->sa", discounts, d, pi)


def occupancy_discounted(
    P: np.ndarray, p0: np.ndarray, pi: np.ndarray, gamma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Infinite-horizon discounted occupancy from the flow constraints.

    Solves ``rho(s) = p0(s) + gamma sum_{s',a'} P(s|s',a') rho(s',a')`` with
    ``rho(s,a) = pi(a|s) rho(s)`` ([eq-flow-state], [eq-flow-sa]), i.e.
    ``(I - gamma P_pi^T) rho = p0``.

    Args:
        pi: stationary policy, shape (S, A).

    Returns:
        (rho_s, rho_sa) with shapes (S,) and (S, A).
    """
    P_pi = np.einsum("sa,sax->sx", pi, P)
    n_states = p0.shape[0]
    rho_s = np.linalg.solve(np.eye(n_states) - gamma * P_pi.T, p0)
    return rho_s, rho_s[:, None] * pi


def occupancy_weighted_features(rho_sa: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Right-hand side of the occupancy identity [eq-occupancy-identity]."""
    return np.einsum("sa,sak->k", rho_sa, f)


def policy_from_occupancy(rho_sa: np.ndarray) -> np.ndarray:
    """``pi(a|s) = rho(s,a) / sum_a' rho(s,a')`` (uniform where rho(s) = 0)."""
    rho_s = rho_sa.sum(axis=1, keepdims=True)
    uniform = np.full_like(rho_sa, 1.0 / rho_sa.shape[1])
    return np.where(rho_s > 0, rho_sa / np.where(rho_s > 0, rho_s, 1.0), uniform)


# --------------------------------------------------------------------------
# Chapter 3: maximum-entropy distributions and MaxEnt IRL
# --------------------------------------------------------------------------


def exponential_family(F: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Max-ent solution [eq-maxent-solution]: ``p(tau) = exp(w.F(tau)) / Z(w)``.

    Args:
        F: trajectory features, shape (n_outcomes, d).
        w: weights (one Lagrange multiplier per feature), shape (d,).
    """
    logits = F @ w
    return np.exp(logits - logsumexp(logits))


def maxent_dual(w: np.ndarray, F: np.ndarray, mu_hat: np.ndarray) -> float:
    """Dual function [eq-maxent-dual]: ``g(w) = log Z(w) - w . mu_hat``."""
    return float(logsumexp(F @ w) - w @ mu_hat)


def maxent_dual_grad(w: np.ndarray, F: np.ndarray, mu_hat: np.ndarray) -> np.ndarray:
    """Gradient of the dual: model minus target feature expectation."""
    return exponential_family(F, w) @ F - mu_hat


def soft_value_iteration(
    P: np.ndarray, r: np.ndarray, horizon: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Finite-horizon soft value iteration [eq-soft-q]--[eq-soft-policy].

    ``V_T = 0``; ``Q_t(s,a) = r_t(s,a) + sum_s' P(s'|s,a) V_{t+1}(s')``;
    ``V_t(s) = logsumexp_a Q_t(s,a)``; ``pi_t(a|s) = exp(Q_t(s,a) - V_t(s))``.

    Args:
        P: dynamics, shape (S, A, S).
        r: reward, shape (S, A) (the same at every step) or (T, S, A).
        horizon: T.

    Returns:
        Q with shape (T, S, A), V with shape (T + 1, S), pi with shape (T, S, A).
    """
    r_t = np.broadcast_to(r, (horizon,) + P.shape[:2])
    n_states, n_actions = P.shape[:2]
    Q = np.zeros((horizon, n_states, n_actions))
    V = np.zeros((horizon + 1, n_states))
    for t in reversed(range(horizon)):
        Q[t] = r_t[t] + P @ V[t + 1]
        V[t] = logsumexp(Q[t], axis=1)
    pi = np.exp(Q - V[:-1, :, None])
    return Q, V, pi


def maxent_irl_gradient(
    P: np.ndarray,
    p0: np.ndarray,
    f: np.ndarray,
    w: np.ndarray,
    horizon: int,
    mu_hat: np.ndarray,
) -> np.ndarray:
    """Likelihood gradient [eq-irl-gradient]: ``mu_hat - sum_{s,a} rho_w(s,a) f(s,a)``.

    Both terms are per-trajectory feature sums over ``t = 0..T-1``, undiscounted:
    ``mu_hat`` is the average over demonstrations, ``rho_w`` comes from the
    soft backward pass followed by the forward pass.
    """
    _, _, pi = soft_value_iteration(P, f @ w, horizon)
    rho = occupancy_finite(P, p0, pi)
    return mu_hat - occupancy_weighted_features(rho, f)


def causal_dual_objective(
    P: np.ndarray,
    p0: np.ndarray,
    f: np.ndarray,
    w: np.ndarray,
    horizon: int,
    mu_hat: np.ndarray,
) -> float:
    """Maximum-causal-entropy objective [eq-mce-objective]: ``w.mu_hat - E_{p0} V_0``."""
    _, V, _ = soft_value_iteration(P, f @ w, horizon)
    return float(w @ mu_hat - p0 @ V[0])


# --------------------------------------------------------------------------
# Chapter 5: Bradley-Terry, Plackett-Luce, MM
# --------------------------------------------------------------------------


def bradley_terry_prob(u_i: np.ndarray, u_j: np.ndarray) -> np.ndarray:
    """[eq-bt]: ``Pr(i > j) = sigma(u_i - u_j)``."""
    return expit(u_i - u_j)


def bt_log_likelihood(u: np.ndarray, winners: np.ndarray, losers: np.ndarray) -> float:
    """[eq-bt-loglik] for hard labels: ``sum_n log sigma(u_{w_n} - u_{l_n})``."""
    return float(np.sum(log_expit(u[winners] - u[losers])))


def bt_gradient(u: np.ndarray, winners: np.ndarray, losers: np.ndarray) -> np.ndarray:
    """[eq-bt-grad]: observed wins minus expected wins, per item."""
    miss = 1.0 - expit(u[winners] - u[losers])  # Pr(the observed winner loses)
    grad = np.zeros_like(u)
    np.add.at(grad, winners, miss)
    np.add.at(grad, losers, -miss)
    return grad


def plackett_luce_prob(u: np.ndarray, ranking: np.ndarray) -> float:
    """[eq-plackett-luce]: product of softmax choices among the remaining items."""
    scores = u[ranking]
    tail_lse = np.array([logsumexp(scores[k:]) for k in range(len(scores))])
    return float(np.exp(np.sum(scores - tail_lse)))


def mm_update(gamma: np.ndarray, wins: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """One MM step [eq-mm-update] (Hunter 2004), renormalised to sum to one.

    Args:
        gamma: strengths ``exp(u)``, shape (K,).
        wins: ``W_i``, total wins of each item, shape (K,).
        counts: ``n_ij``, symmetric comparison counts with zero diagonal, (K, K).
    """
    denom = (counts / (gamma[:, None] + gamma[None, :])).sum(axis=1)
    new = wins / denom
    return new / new.sum()


def rao_kupper_probs(u_i: float, u_j: float, theta: float) -> tuple[float, float, float]:
    """[eq-rao-kupper]: (Pr(i > j), Pr(j > i), Pr(tie)), theta >= 1."""
    a, b = np.exp(u_i), np.exp(u_j)
    p_i = a / (a + theta * b)
    p_j = b / (b + theta * a)
    tie = (theta**2 - 1) * a * b / ((a + theta * b) * (b + theta * a))
    return p_i, p_j, tie


def davidson_probs(u_i: float, u_j: float, nu: float) -> tuple[float, float, float]:
    """[eq-davidson]: (Pr(i > j), Pr(j > i), Pr(tie)), nu >= 0."""
    a, b = np.exp(u_i), np.exp(u_j)
    tie_mass = nu * np.sqrt(a * b)
    denom = a + b + tie_mass
    return a / denom, b / denom, tie_mass / denom


def copeland_scores(p: np.ndarray) -> np.ndarray:
    """[eq-copeland]: number of other arms beaten with probability > 1/2."""
    beats = p > 0.5
    np.fill_diagonal(beats, False)
    return beats.sum(axis=1)


def borda_scores(p: np.ndarray) -> np.ndarray:
    """[eq-borda]: average probability of beating a uniformly drawn other arm."""
    k = p.shape[0]
    return (p.sum(axis=1) - np.diag(p)) / (k - 1)


# --------------------------------------------------------------------------
# Chapter 7: KL-regularised optimum, DPO, best-of-n
# --------------------------------------------------------------------------


def kl_regularised_optimum(pi_ref: np.ndarray, r: np.ndarray, beta: float) -> np.ndarray:
    """[eq-kl-optimum]: ``pi*(y) = pi_ref(y) exp(r(y)/beta) / Z``, along the last axis."""
    logits = np.log(pi_ref) + r / beta
    return np.exp(logits - logsumexp(logits, axis=-1, keepdims=True))


def dpo_loss(
    logp_w: np.ndarray,
    logp_l: np.ndarray,
    ref_logp_w: np.ndarray,
    ref_logp_l: np.ndarray,
    beta: float,
) -> float:
    """[eq-dpo-loss]: ``-mean log sigma(beta log(pi/pi_ref)(y_w) - beta log(pi/pi_ref)(y_l))``."""
    margin = beta * ((logp_w - ref_logp_w) - (logp_l - ref_logp_l))
    return float(-np.mean(log_expit(margin)))


def dpo_grad_tabular(
    theta: np.ndarray,
    ref_logp: np.ndarray,
    prompts: np.ndarray,
    chosen: np.ndarray,
    rejected: np.ndarray,
    beta: float,
) -> np.ndarray:
    """[eq-dpo-grad] for a tabular softmax policy ``pi(y|x) = softmax(theta[x])_y``.

    ``grad = -beta mean[ sigma(rhat_l - rhat_w) (grad log pi(y_w|x) - grad log pi(y_l|x)) ]``
    with ``rhat = beta log(pi/pi_ref)`` and ``grad_theta[x] log pi(y|x) = e_y - pi(.|x)``.
    """
    logp = theta - logsumexp(theta, axis=1, keepdims=True)
    rhat = beta * (logp - ref_logp)
    weight = expit(rhat[prompts, rejected] - rhat[prompts, chosen])
    n_actions = theta.shape[1]
    e_w = np.eye(n_actions)[chosen]
    e_l = np.eye(n_actions)[rejected]
    # grad log pi(y_w|x) - grad log pi(y_l|x) = e_{y_w} - e_{y_l}: the pi(.|x) terms cancel.
    per_pair = -beta * weight[:, None] * (e_w - e_l)
    grad = np.zeros_like(theta)
    np.add.at(grad, prompts, per_pair)
    return grad / len(prompts)


def best_of_n_probs(q_sorted: np.ndarray, n: int) -> np.ndarray:
    """[eq-bon-discrete]: best-of-n distribution over atoms sorted by increasing reward.

    ``p_k = C_k^n - C_{k-1}^n`` with ``C_k = q_1 + ... + q_k`` (distinct rewards).
    """
    cdf = np.concatenate([[0.0], np.cumsum(q_sorted)])
    cdf[-1] = 1.0
    return cdf[1:] ** n - cdf[:-1] ** n


def best_of_n_kl(q_sorted: np.ndarray, n: int) -> float:
    """Exact ``KL(pi_bon || pi_ref)`` for a discrete base distribution."""
    p = best_of_n_probs(q_sorted, n)
    mask = p > 0
    return float(np.sum(p[mask] * np.log(p[mask] / q_sorted[mask])))


def best_of_n_kl_formula(n: int) -> float:
    """[eq-bon-kl]: ``log n - (n - 1)/n``."""
    return float(np.log(n) - (n - 1) / n)


# --------------------------------------------------------------------------
# Chapter 1: the drift model of compounding error
# --------------------------------------------------------------------------


def drift_cost_bc(eps: float, horizon: int) -> float:
    """[eq-drift-bc]: ``sum_{t=0}^{T-1} (1 - (1 - eps)^t)``, absorbing failure."""
    t = np.arange(horizon)
    return float(np.sum(1.0 - (1.0 - eps) ** t))


def drift_cost_dagger(eps: float, horizon: int) -> float:
    """[eq-drift-dagger]: ``eps (T - 1)``, recoverable failure."""
    return eps * (horizon - 1)
