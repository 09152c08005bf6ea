"""Numerical checks of claims that chapters 3b, 4 and 8 make in their prose and exercises, beside the labelled
equations that the other ``test_lecture_*`` modules check.

- ``lectures/03b_adversarial.md``: AIRL's discriminator is 1/2 on the expert's samples exactly when
  ``f = log pi_E`` (a BCE-optimal table of ``f`` against ``pi = pi_E``), and the shaped ``g + gamma h(s') - h(s)``
  fitted to ``log pi_E`` recovers the reward up to a constant with deterministic dynamics and not with slippery ones
  (section "When the disentanglement holds").
- ``lectures/04_feedback_spectrum.md``: the solution of ``ex-calibration`` (simulated), the bits per query of
  ``ex-bits`` (entropies and mutual informations by enumeration), and the demonstration case of reward-rational
  choice, exact only under deterministic dynamics (enumerating every trajectory).
- ``lectures/08_group_rl.md``: ``eq-bon-ties`` on many random atom sets (best-of-n by enumerating draws), the
  first-order agreement of the forward and reverse KL gradients near the reference, Dr. GRPO's token sum as a
  constant multiple of the policy gradient (exact enumeration over every batch of a tiny autoregressive policy)
  where GRPO's length average is not, and the answers of ``ex-ipo-certain`` and ``ex-law-peaks`` by a generic
  optimiser.

As in the other modules, each test compares the lecture's statement with an independent computation, uses
``@checks(label, digest)`` (see ``tests/lectures/lecture_links.py``) only where it checks a labelled equation, and
says in a comment which wrong version of the claim it would catch.
"""
from __future__ import annotations

import itertools
import sys
from math import factorial
from pathlib import Path

import numpy as np
import torch
from scipy.optimize import minimize, minimize_scalar
from scipy.special import expit, log_expit
from scipy.stats import norm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lecture_checks import discounted_soft_vi  # noqa: E402
from lecture_links import checks  # noqa: E402

from rlcourse import group_rl as G  # noqa: E402


def softmax(z, axis=-1):
    z = np.asarray(z, float)
    e = np.exp(z - z.max(axis=axis, keepdims=True))
    return e / e.sum(axis=axis, keepdims=True)


# ---------------------------------------------------------------------------
# chapter 3b: AIRL
# ---------------------------------------------------------------------------


def airl_bce(f, log_pi, weight):
    """Population BCE of AIRL's discriminator D = exp f / (exp f + pi), expert and policy pairs drawn with the same
    weights (pi = pi_E): sum w [-log D - log(1 - D)], with its gradient in f."""
    u = f - log_pi                                               # the logit log D - log(1 - D)
    loss = float((weight * (np.logaddexp(0, -u) + np.logaddexp(0, u))).sum())
    return loss, weight * np.tanh(u / 2)                         # d/du [softplus(-u) + softplus(u)] = tanh(u/2)


@checks("eq-airl-discriminator", "b0e2edee")
def test_the_bce_optimal_airl_discriminator_against_the_expert_sets_f_to_log_pi_e():
    """Section "AIRL separates the reward from the shaping": against pi = pi_E the discriminator is optimal when D = 1/2
    on the expert's samples, that is when f = log pi_E. A table f(s, a, s') fitted by L-BFGS to the population BCE
    equals log pi_E(a|s) on every transition; D(log pi_E + c) = 1/2 only for c = 0.
    Rules out: a discriminator whose optimum is f = 0 (GAIL's D = sigmoid(f), no pi in it) or f = log pi_E + const."""
    rng = np.random.default_rng(0)
    n_s, n_a = 4, 3
    P = rng.dirichlet(np.full(n_s, 4.0), size=(n_s, n_a))
    pi_e = rng.dirichlet(np.full(n_a, 2.0), size=n_s)
    d = rng.dirichlet(np.full(n_s, 4.0))                         # any state distribution with full support
    weight = d[:, None, None] * pi_e[:, :, None] * P             # (s, a, s')
    log_pi = np.broadcast_to(np.log(pi_e)[:, :, None], weight.shape)

    def fit(log_pi_in_d):                                        # a trust-region Newton method, stopped on the gradient
        def hess(x):
            u = x.reshape(weight.shape) - log_pi_in_d
            return np.diag((weight * 0.5 / np.cosh(u / 2) ** 2).ravel())
        res = minimize(lambda x: airl_bce(x.reshape(weight.shape), log_pi_in_d, weight)[0], np.zeros(weight.size),
                       jac=lambda x: airl_bce(x.reshape(weight.shape), log_pi_in_d, weight)[1].ravel(),
                       hess=hess, method="trust-exact", options={"gtol": 1e-13, "maxiter": 1000})
        return res.x.reshape(weight.shape)

    f = fit(log_pi)
    assert np.allclose(f, log_pi, atol=1e-5)
    d_at = np.exp(f) / (np.exp(f) + pi_e[:, :, None])
    assert np.allclose(d_at, 0.5, atol=1e-5)
    for c in (-1.0, 0.3):                                        # "exactly when": a shifted f moves D off 1/2
        shifted = np.exp(log_pi + c) / (np.exp(log_pi + c) + pi_e[:, :, None])
        assert np.abs(shifted - 0.5).min() > 0.05
    # the same fit with the pi term left out of D (GAIL's sigmoid(f)) ends at f = 0, not at log pi_E
    gail = fit(np.zeros(weight.shape))
    assert np.allclose(gail, 0, atol=1e-5) and np.abs(gail - log_pi).max() > 0.5


def ring(n_states, n_actions, slip):
    """A ring: action a moves a steps; with probability ``slip`` the move is that of a uniformly random action."""
    P = np.zeros((n_states, n_actions, n_states))
    for s in range(n_states):
        for a in range(n_actions):
            P[s, a, (s + a) % n_states] += 1 - slip
            for b in range(n_actions):
                P[s, a, (s + b) % n_states] += slip / n_actions
    return P


def fit_shaped_f(P, log_pi, weight, gamma):
    """(g, h) minimising AIRL's BCE (pi = pi_E) over f(s, a, s') = g(s) + gamma h(s') - h(s), by L-BFGS."""
    n_s = P.shape[0]
    s, a, s1 = np.meshgrid(np.arange(n_s), np.arange(P.shape[1]), np.arange(n_s), indexing="ij")
    rows = np.zeros((*P.shape, 2 * n_s))                         # the linear map (g, h) -> f
    np.put_along_axis(rows, s[..., None], 1.0, axis=-1)
    rows[..., n_s:] += gamma * np.eye(n_s)[s1] - np.eye(n_s)[s]
    A = rows.reshape(-1, 2 * n_s)
    w, lp = weight.ravel(), np.broadcast_to(log_pi[:, :, None], P.shape).ravel()

    def objective(x):
        loss, du = airl_bce(A @ x, lp, w)
        return loss, A.T @ du

    res = minimize(objective, np.zeros(2 * n_s), jac=True, method="L-BFGS-B",
                   options={"gtol": 1e-13, "ftol": 1e-16, "maxiter": 10000})
    return res.x[:n_s], res.x[n_s:], np.abs(objective(res.x)[1]).max(), res.fun, objective


@checks("eq-airl-disentangled", "f659bbfb")
def test_the_shaped_fit_recovers_the_reward_with_deterministic_dynamics_and_not_with_slippery_ones():
    """Section "When the disentanglement holds", first condition: an expert soft-optimal for r(s) on a ring (stay, one
    step, two steps). With deterministic moves the BCE-optimal g is r up to a constant; with a slippery floor the
    shaped f cannot equal log pi_E on every realised s', the fit trades terms between g and h, and g - r is far from
    constant (while (r, V*) is not even a minimiser).
    Rules out: disentanglement that holds whatever the dynamics (the slippery g would be r + c)."""
    rng = np.random.default_rng(1)
    n_s, n_a, gamma = 8, 3, 0.9
    r = rng.normal(size=n_s)
    for slip, recovered in ((0.0, True), (0.4, False)):
        P = ring(n_s, n_a, slip)
        v, log_pi = discounted_soft_vi(P, np.repeat(r[:, None], n_a, axis=1), gamma)
        weight = np.full(n_s, 1 / n_s)[:, None, None] * np.exp(log_pi)[:, :, None] * P
        g, h, grad, loss, objective = fit_shaped_f(P, log_pi, weight, gamma)
        assert grad < 1e-7, "the fit converged"
        gap = np.ptp(g - r) / np.ptp(r)
        if recovered:
            assert gap < 1e-5
            assert np.isclose(loss, 2 * np.log(2) * weight.sum(), rtol=1e-10)     # logit 0 on every transition
        else:
            assert gap > 0.05
            assert objective(np.r_[r, v])[0] > loss + 1e-4                       # (r, V*) fits worse


# ---------------------------------------------------------------------------
# chapter 4: the feedback spectrum
# ---------------------------------------------------------------------------


def test_rater_calibration_exercise_pooled_bias_and_what_comparisons_identify():
    """ex-calibration, simulated: pooled least squares gives each item its mean score, biased by (0, 0, 2, 2) (any
    re-weighting too: (u, b_2) and (u + 2 on items 3, 4, b_2 = 0) give the same data); within-rater comparisons
    follow Phi((u_i - u_j)/sqrt 2) whatever the offset and identify u1 - u2 and u3 - u4 only, until one comparison
    across the groups connects them.
    Rules out: an unbiased pooled estimate, an offset that a weighting removes, comparisons that depend on b_k or
    identify a difference across the two raters."""
    rng = np.random.default_rng(2)
    u, b = np.array([1.0, 0.0, 0.5, -0.8]), np.array([0.0, 0.0, 2.0, 2.0])
    n = 20_000                                                   # scores per item
    noise = rng.normal(size=(n, 4))
    scores = u + b + noise
    item = np.tile(np.arange(4), n)
    X = np.eye(4)[item]
    pooled = np.linalg.lstsq(X, scores.ravel(), rcond=None)[0]
    se = 1 / np.sqrt(n)
    assert np.all(np.abs(pooled - u - b) < 4 * se)
    assert np.all(np.abs(pooled - u)[2:] > 2 - 4 * se)
    wts = rng.uniform(0.1, 3.0, size=item.size)                  # a weighted least squares: still biased by b
    weighted = np.linalg.lstsq(X * np.sqrt(wts)[:, None], scores.ravel() * np.sqrt(wts), rcond=None)[0]
    assert np.all(np.abs(weighted - u - b) < 8 * se)
    # the data cannot separate b_2 from u_3, u_4: the design of (u_1..u_4, b_2) loses one rank, along (0,0,1,1,-1)
    design = np.c_[X, (item >= 2).astype(float)]
    assert np.linalg.matrix_rank(design[:8]) == 4
    assert np.allclose(design[:8] @ np.array([0, 0, 1, 1, -1.0]), 0)
    # comparisons: rater 1 compares items 1 and 2, rater 2 items 3 and 4, the same noise with and without offsets
    for offset in (2.0, 0.0):
        y = u + np.array([0, 0, offset, offset]) + noise
        wins = np.array([np.mean(y[:, 0] > y[:, 1]), np.mean(y[:, 2] > y[:, 3])])
        want = norm.cdf(np.array([u[0] - u[1], u[2] - u[3]]) / np.sqrt(2))
        assert np.all(np.abs(wins - want) < 4 * np.sqrt(want * (1 - want) / n))
        recovered = np.sqrt(2) * norm.ppf(wins)                  # Thurstone's inversion
        assert np.allclose(recovered, [u[0] - u[1], u[2] - u[3]], atol=0.05)
    within = np.array([[1, -1, 0, 0], [0, 0, 1, -1.0]])
    assert np.linalg.matrix_rank(within) == 2                    # two of the three free differences
    assert np.allclose(within @ np.array([1, 1, 0, 0.0]), 0)     # u1 - u3 moves nothing: not identified
    connected = np.r_[within, [[0, 1, -1, 0.0]]]
    assert np.linalg.matrix_rank(connected) == 3                 # all differences; only the common level is free


def entropy_bits(p):
    p = np.asarray(p, float).ravel()
    p = p[p > 0]
    return float(-(p * np.log2(p)).sum())


def test_bits_per_query_exercise_by_enumeration():
    """ex-bits: the largest information is log2 of the number of possible answers (the entropy of the answer of a
    noiseless respondent whose true order is uniform): a comparison 1 bit, a ranking of K = 4 log2 4! = 4.585 (the
    outcome patterns of the 6 pairwise comparisons that are transitive), a 7-point rating log2 7, a demonstration
    T log2 |A|. A comparison with P = sigma(Delta), |Delta| known and even odds on the sign carries
    I = 1 - H_b(sigma(Delta)) bits about which item is better: about 0.0018 at Delta = 0.1 and 0.725 at 3.
    Rules out: K(K-1)/2 bits for a ranking (all six comparisons), K log2 K, H_b itself, or the value in nats."""
    k = 4
    # a ranking: enumerate the 2^6 outcomes of the pairwise comparisons; the consistent ones are the orders
    pairs = list(itertools.combinations(range(k), 2))
    consistent = 0
    for outcome in itertools.product((0, 1), repeat=len(pairs)):
        beats = {(i, j) if o else (j, i) for (i, j), o in zip(pairs, outcome)}
        wins = sorted(sum((i, j) in beats for j in range(k)) for i in range(k))
        consistent += wins == list(range(k))                     # a tournament is transitive iff its scores are 0..K-1
    counts = {}
    for order in itertools.permutations(range(k)):               # true utilities in a uniformly random order
        answer = tuple(np.argsort(order))
        counts[answer] = counts.get(answer, 0) + 1
    h_rank = entropy_bits(np.array(list(counts.values())) / factorial(k))
    assert consistent == factorial(k) and np.isclose(h_rank, np.log2(consistent))
    assert np.isclose(h_rank, np.log2(24)) and not np.isclose(h_rank, 6) and not np.isclose(h_rank, k * np.log2(k))
    # a rating with L levels: a uniform utility binned into levels; a comparison is a rating with 2 levels
    grid = (np.arange(420_000) + 0.5) / 420_000
    for levels in (2, 7, 10):
        h = entropy_bits(np.bincount((grid * levels).astype(int)) / grid.size)
        assert np.isclose(h, np.log2(levels))
    # a demonstration of T actions among |A|: every action sequence once
    t_steps, n_actions = 3, 4
    seqs = list(itertools.product(range(n_actions), repeat=t_steps))
    assert np.isclose(entropy_bits(np.full(len(seqs), 1 / len(seqs))), t_steps * np.log2(n_actions))
    # one noisy comparison: the joint of (which is better, outcome), I = H(S) + H(Y) - H(S, Y)
    for delta, quoted in ((0.1, 0.0018), (3.0, 0.7246)):
        s = expit(delta)
        joint = 0.5 * np.array([[s, 1 - s], [1 - s, s]])         # rows: item 1 better / item 2 better
        info = entropy_bits(joint.sum(1)) + entropy_bits(joint.sum(0)) - entropy_bits(joint)
        h_b = entropy_bits([s, 1 - s])
        assert np.isclose(info, 1 - h_b, atol=1e-12) and abs(info - quoted) < 1e-4
        assert not np.isclose(info, h_b) and not np.isclose(info, (1 - h_b) * np.log(2), atol=1e-5)


def soft_policy(P, r, horizon):
    """Finite-horizon soft value iteration, reward r(s, a): the time-dependent soft-optimal policy (T, S, A)."""
    v, pol = np.zeros(P.shape[0]), np.empty((horizon, *r.shape))
    for t in reversed(range(horizon)):
        q = r + P @ v
        v = np.logaddexp.reduce(q, axis=1)
        pol[t] = np.exp(q - v[:, None])
    return pol


def trajectory_distributions(P, r, horizon, s0=0):
    """Over every trajectory (s0, a0, s1, ..., a_{T-1}) of positive probability: p under the soft-optimal policy,
    and exp(R(tau))/Z (reward-rational choice among all trajectories, beta_h = 1)."""
    pol = soft_policy(P, r, horizon)
    p_pol, ret = [], []
    n_s, n_a = r.shape
    for acts in itertools.product(range(n_a), repeat=horizon):
        for states in itertools.product(range(n_s), repeat=horizon - 1):
            path = (s0, *states)
            prob = np.prod([P[path[t], acts[t], path[t + 1]] for t in range(horizon - 1)])
            if prob == 0:
                continue
            p_pol.append(prob * np.prod([pol[t, path[t], acts[t]] for t in range(horizon)]))
            ret.append(sum(r[path[t], acts[t]] for t in range(horizon)))
    ret = np.array(ret)
    return np.array(p_pol), np.exp(ret - np.logaddexp.reduce(ret)), ret


@checks("eq-reward-rational", "f1600375")
def test_a_demonstration_is_a_reward_rational_choice_only_under_deterministic_dynamics():
    """Section "One model for all feedback", the demonstration case: with C all trajectories, psi the identity and
    beta_h = 1, Pr(tau) = exp(R(tau))/Z is the soft-optimal demonstrator's trajectory distribution when the dynamics
    are deterministic, and not when they are random.
    Rules out: a reading that holds for any dynamics, and one with another beta_h."""
    rng = np.random.default_rng(3)
    n_s, n_a, horizon = 3, 2, 3
    r = rng.normal(scale=1.5, size=(n_s, n_a))
    det = np.zeros((n_s, n_a, n_s))
    det[np.arange(n_s)[:, None], np.arange(n_a)[None, :], rng.integers(0, n_s, size=(n_s, n_a))] = 1.0
    p_pol, p_choice, ret = trajectory_distributions(det, r, horizon)
    assert len(p_pol) == n_a ** horizon and np.isclose(p_pol.sum(), 1)
    assert np.allclose(p_pol, p_choice, atol=1e-12)
    assert np.abs(p_pol - softmax(2 * ret)).max() > 0.01                 # beta_h = 2 is another distribution
    stoch = rng.dirichlet(np.ones(n_s), size=(n_s, n_a))
    p_pol, p_choice, _ = trajectory_distributions(stoch, r, horizon)
    assert np.isclose(p_pol.sum(), 1) and np.isclose(p_choice.sum(), 1)
    assert np.abs(p_pol - p_choice).max() > 0.01


# ---------------------------------------------------------------------------
# chapter 8: group RL
# ---------------------------------------------------------------------------


@checks("eq-bon-ties", "881f65dd")
def test_best_of_n_with_ties_on_random_atom_sets():
    """eq-bon-ties on random atom sets: p_k by enumerating every n-tuple of draws (ties broken at random, so the best
    draw's atom is the largest atom index drawn) equals C_k^n - C_{k-1}^n; p_k/q_k rises with k; KL is at most
    -log q_K and at most log n - (n-1)/n; and for large n it approaches -log q_K, however large n.
    Rules out: a ratio that falls somewhere, a bound such as -log q_1 or -(1/2) log q_K, and ties that push the KL
    above the atomless formula."""
    rng = np.random.default_rng(4)
    for _ in range(300):                                           # by enumeration
        n_atoms, n = int(rng.integers(2, 6)), int(rng.integers(1, 5))
        q = rng.dirichlet(np.ones(n_atoms) * rng.uniform(0.3, 3))
        draws = np.array(list(itertools.product(range(n_atoms), repeat=n)))
        prob = q[draws].prod(axis=1)
        p = np.bincount(draws.max(axis=1), weights=prob, minlength=n_atoms)
        c = np.r_[0, np.cumsum(q)]
        assert np.allclose(p, c[1:] ** n - c[:-1] ** n, atol=1e-12)
        ratio = p / q
        assert np.all(np.diff(ratio) >= -1e-12)
        kl = float(np.sum(p[p > 0] * np.log(p[p > 0] / q[p > 0])))
        assert kl <= -np.log(q[-1]) + 1e-12 and kl <= G.bon_kl_formula(n) + 1e-12
    worst_margin = np.inf
    for _ in range(2000):                                          # by the formula, larger n
        n_atoms, n = int(rng.integers(2, 9)), int(rng.integers(1, 200))
        q = rng.dirichlet(np.ones(n_atoms) * rng.uniform(0.3, 3))
        q = np.maximum(q, 1e-6) / np.maximum(q, 1e-6).sum()      # keeps C_k^n - C_{k-1}^n clear of cancellation
        c = np.r_[0, np.cumsum(q)]
        c[-1] = 1.0
        p = c[1:] ** n - c[:-1] ** n
        assert np.all(np.diff(p / q) >= -1e-9 * (p / q)[1:])
        kl = float(np.sum(p[p > 0] * np.log(p[p > 0] / q[p > 0])))
        assert kl <= -np.log(q[-1]) + 1e-12 and kl <= G.bon_kl_formula(n) + 1e-12
        worst_margin = min(worst_margin, -np.log(q[-1]) - kl)
    assert worst_margin < 1e-3                                     # the bound is approached, not loose by a factor
    q = np.array([0.5, 0.3, 0.2])                                  # a pass/fail-like reward: KL saturates at -log q_K
    kls = [G.best_of_n_kl(np.repeat([0.0, 1.0, 2.0], [5, 3, 2]), n) for n in (10, 100, 10_000)]
    assert np.all(np.diff(kls) > 0) and abs(kls[-1] + np.log(q[-1])) < 1e-6 and kls[-1] < G.bon_kl_formula(10_000)


def test_forward_and_reverse_kl_gradients_agree_to_first_order_near_the_reference():
    """Section "The length", the penalty: the expected autograd gradient of k3 on tokens drawn from pi_theta
    (enumerated) is that of the forward KL(ref || pi); near the reference it agrees with the reverse KL(pi || ref)'s
    gradient (central differences) to first order: the relative gap shrinks linearly with the distance. Far from it,
    the forward gradient pulls up a token the policy has almost dropped and the reference likes; the reverse does not.
    Rules out: exact agreement (a zero gap), agreement only to zeroth order (a gap that does not shrink), or a gap
    shrinking quadratically (agreement to second order)."""
    rng = np.random.default_rng(5)
    ref = rng.dirichlet(np.ones(5) * 2)
    direction = rng.normal(size=5)

    def forward_by_k3(theta):
        th = torch.tensor(theta, requires_grad=True)
        log_pi = torch.log_softmax(th, 0)
        rho = torch.as_tensor(ref) / torch.exp(log_pi)
        k3 = rho - torch.log(rho) - 1
        (torch.exp(log_pi).detach() * k3).sum().backward()     # E_{y ~ pi}[grad k3(y)], the sampled tokens enumerated
        return th.grad.numpy()

    def reverse_kl(theta):
        p = softmax(theta)
        return float(p @ np.log(p / ref))

    def central(fun, theta, h=1e-5):
        return np.array([(fun(theta + h * e) - fun(theta - h * e)) / (2 * h) for e in np.eye(len(theta))])

    theta0 = rng.normal(size=5)
    fwd_fd = central(lambda t: float(ref @ np.log(ref / softmax(t))), theta0)
    assert np.allclose(forward_by_k3(theta0), fwd_fd, atol=1e-8)
    gaps = []
    for eps in (0.1, 0.01, 0.001):
        theta = np.log(ref) + eps * direction
        fwd, rev = forward_by_k3(theta), central(reverse_kl, theta)
        gaps.append(np.linalg.norm(fwd - rev) / np.linalg.norm(rev))
    gaps = np.array(gaps)
    assert gaps[-1] > 0
    slopes = np.log10(gaps[:-1] / gaps[1:])                         # decades of gap per decade of distance
    assert np.all(np.abs(slopes - 1) < 0.15), slopes
    far = np.log(ref) + np.array([0, 0, 0, 0, -12.0])              # the policy has all but dropped the last token
    assert -forward_by_k3(far)[-1] > 0.5 * ref[-1] and abs(central(reverse_kl, far)[-1]) < 1e-3


VOCAB, EOS, T_MAX = 2, 2, 3                                        # tokens a, b and an end token; at most 3 tokens


def responses():
    """Every response: tokens from {a, b, EOS}, ending at EOS or cut at T_MAX tokens."""
    out = []
    for length in range(1, T_MAX + 1):
        for body in itertools.product(range(VOCAB), repeat=length - 1):
            out.append((*body, EOS))
        if length == T_MAX:
            out.extend(itertools.product(range(VOCAB), repeat=length))
    return out


def prefix_index():
    prefixes = [p for n in range(T_MAX) for p in itertools.product(range(VOCAB), repeat=n)]
    return {p: i for i, p in enumerate(prefixes)}


def token_log_probs(theta, resp, index):
    """log pi(y_t | y_<t) for each token of each response, (n_responses, T_MAX), zero-padded; theta (prefixes, 3)."""
    lp = torch.log_softmax(theta, dim=1)
    rows = []
    for y in resp:
        row = [lp[index[tuple(y[:t])], y[t]] for t in range(len(y))]
        rows.append(torch.stack(row + [torch.zeros((), dtype=theta.dtype)] * (T_MAX - len(y))))
    return torch.stack(rows)


@checks("eq-grpo-loss", "7a4e649a")
def test_dr_grpo_token_sum_is_a_multiple_of_the_policy_gradient_and_grpos_length_average_is_not():
    """Section "The length": a tiny autoregressive softmax policy (one logit vector per prefix, 15 responses of 1-3
    tokens). Over every batch of B = G = 3 responses of one prompt, with Dr. GRPO's advantages r_i - mean(r) and
    rho = 1, beta = 0, the exact expected gradient of -L_Dr is (G-1)/(G T) grad J, grad J by central differences of
    the enumerated expected reward. The same advantages under GRPO's per-response length average give an expected
    gradient that no constant maps onto grad J.
    Rules out: a Dr. GRPO multiple other than (G-1)/(GT) (a missing 1/B or 1/T), and a length average that is also
    unbiased up to a constant."""
    rng = np.random.default_rng(6)
    resp, index = responses(), prefix_index()
    assert len(resp) == 15 and len(index) == 7
    reward = rng.normal(size=len(resp))
    theta0 = rng.normal(scale=0.8, size=(len(index), VOCAB + 1))
    lengths = torch.tensor([len(y) for y in resp], dtype=torch.float64)
    mask = (torch.arange(T_MAX)[None] < lengths[:, None]).double()

    def expected_reward(th):
        lp = token_log_probs(torch.as_tensor(th), resp, index).sum(1).numpy()
        return float(np.exp(lp) @ reward)

    h = 1e-6
    grad_j = np.zeros_like(theta0)
    for i in np.ndindex(theta0.shape):
        e = np.zeros_like(theta0)
        e[i] = h
        grad_j[i] = (expected_reward(theta0 + e) - expected_reward(theta0 - e)) / (2 * h)

    g, eps = 3, 0.2
    batches = torch.tensor(list(itertools.product(range(len(resp)), repeat=g)))      # (15^3, G)
    theta = torch.tensor(theta0, requires_grad=True)
    lp_tok = token_log_probs(theta, resp, index)
    seq_p = torch.exp(lp_tok.sum(1)).detach()
    weight = seq_p[batches].prod(1)                                                  # Pr(batch)
    r = torch.as_tensor(reward)[batches]
    adv = (r - r.mean(1, keepdim=True))[..., None]                                  # (batches, G, 1)
    lp = lp_tok[batches]
    ratio = torch.exp(lp - lp.detach())
    per = torch.maximum(-ratio * adv, -ratio.clamp(1 - eps, 1 + eps) * adv) * mask[batches]
    loss_grpo = (per.sum(2) / lengths[batches]).sum(1) / g
    loss_dr = per.sum((1, 2)) / (g * T_MAX)
    exp_dr, = torch.autograd.grad(-(weight * loss_dr).sum(), theta, retain_graph=True)
    exp_grpo, = torch.autograd.grad(-(weight * loss_grpo).sum(), theta)
    assert np.isclose(float(weight.sum()), 1.0)
    assert np.allclose(exp_dr.numpy(), (g - 1) / (g * T_MAX) * grad_j, atol=1e-8)
    gj, gg = grad_j.ravel(), exp_grpo.numpy().ravel()
    best_c = gg @ gj / (gj @ gj)
    assert np.linalg.norm(gg - best_c * gj) > 0.1 * np.linalg.norm(gg)


@checks("eq-ipo", "3b902791")
def test_ipo_and_dpo_on_one_certain_pair():
    """ex-ipo-certain: one pair always labelled y_w > y_l, pi_ref = (1/2, 1/2), beta = 0.5. Over pi_theta(y_l) = x by a
    generic optimiser: IPO's loss (h - 1/(2 beta))^2 with h = log((1 - x)/x) is minimised at x = 1/(1 + e); DPO's
    -log sigma(beta h) has no interior minimum, and its minimiser runs into whatever lower bound x is given.
    Rules out: the IPO target 1/beta (x = 1/(1 + e^2)) or beta (x = 1/(1 + e^{1/2})), and a finite DPO optimum."""
    beta = 0.5

    def margin(x):
        return np.log((1 - x) / 0.5) - np.log(x / 0.5)

    ipo = minimize_scalar(lambda x: (margin(x) - 1 / (2 * beta)) ** 2, bounds=(1e-9, 1 - 1e-9), method="bounded",
                          options={"xatol": 1e-12})
    assert np.isclose(ipo.x, 1 / (1 + np.e), atol=1e-7)
    assert not np.isclose(ipo.x, 1 / (1 + np.e ** 2), atol=1e-3)
    assert not np.isclose(ipo.x, 1 / (1 + np.sqrt(np.e)), atol=1e-3)
    for lower in (1e-3, 1e-6, 1e-9):
        dpo = minimize_scalar(lambda x: -log_expit(beta * margin(x)), bounds=(lower, 1 - 1e-9), method="bounded",
                              options={"xatol": lower / 100})
        assert dpo.x < 2 * lower
    xs = np.logspace(-1, -12, 12)
    assert np.all(np.diff(-log_expit(beta * margin(xs))) < 0)     # the loss keeps falling as x -> 0


@checks("eq-law-peaks", "2fbae672")
def test_where_the_best_of_n_law_peaks_in_n():
    """ex-law-peaks: alpha = 0.5, beta = 0.1. Maximising the gold reward d(alpha - beta d), d = sqrt(KL) and
    KL = log n - (n-1)/n, over n by a generic optimiser puts the peak at n of about 1.4e3, where d = alpha/(2 beta)
    and the gold reward is alpha^2/(4 beta); the RL law's peak value is beta e^(alpha/beta - 1).
    Rules out: reading d as the KL itself (n of about 33) or n = e^(d*) (about 12)."""
    alpha, beta = 0.5, 0.1

    def gold(log_n):
        d = np.sqrt(G.bon_kl_formula(np.exp(log_n)))
        return d * (alpha - beta * d)

    best = minimize_scalar(lambda ln: -gold(ln), bounds=(0.1, 20), method="bounded", options={"xatol": 1e-10})
    n_star = np.exp(best.x)
    assert 1.35e3 < n_star < 1.45e3
    assert np.isclose(np.sqrt(G.bon_kl_formula(n_star)), alpha / (2 * beta), rtol=1e-5)
    assert np.isclose(-best.fun, alpha ** 2 / (4 * beta), rtol=1e-9)
    assert np.isclose(n_star, np.exp((alpha / (2 * beta)) ** 2 + 1 - 1 / n_star), rtol=1e-4)
    rl = minimize_scalar(lambda d: -d * (alpha - beta * np.log(d)), bounds=(1e-6, 1e3), method="bounded",
                         options={"xatol": 1e-10})
    assert np.isclose(-rl.fun, beta * np.exp(alpha / beta - 1), rtol=1e-8)
