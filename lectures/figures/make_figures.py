"""Regenerate every figure of the lecture notes into this folder.

Usage (from the repository root):

    .venv/bin/python lectures/figures/make_figures.py

Every figure is computed from the formulas derived in the chapters (no data
files, no network); the whole script runs in a few seconds on one CPU core.
Figures are saved as small PNGs (dpi 100).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402
from scipy.special import expit, logsumexp  # noqa: E402
from scipy.stats import norm  # noqa: E402

DPI = 100
BLUE, ORANGE, GREEN, RED, GREY = "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#7f7f7f"


def save(fig: plt.Figure, out_dir: Path, name: str) -> None:
    """Write ``fig`` as ``out_dir/name`` and close it."""
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=DPI)
    plt.close(fig)


# ---------------------------------------------------------------- chapter 1


def compounding_error(out_dir: Path) -> None:
    """Drift model: expected cost of BC (absorbing failure) vs DAgger (recoverable)."""
    eps = 0.01
    horizons = np.arange(1, 101)
    bc = np.array([np.sum(1 - (1 - eps) ** np.arange(T)) for T in horizons])
    dagger = eps * (horizons - 1)
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot(horizons, bc, color=RED, lw=2, label="behaviour cloning (exact)")
    ax.plot(horizons, dagger, color=BLUE, lw=2, label="DAgger-trained policy (exact)")
    ax.plot(horizons, eps * horizons**2, color=RED, ls=":", label=r"$\epsilon T^2$ bound")
    ax.plot(horizons, eps * horizons, color=BLUE, ls=":", label=r"$\epsilon T$")
    ax.set_ylim(0, 30)
    ax.set_xlabel("horizon $T$")
    ax.set_ylabel("expected number of off-track steps")
    ax.set_title(r"Drift model, per-step error $\epsilon = 0.01$")
    ax.legend(frameon=False)
    save(fig, out_dir, "compounding_error.png")


# ---------------------------------------------------------------- chapter 3


def gridworld_soft_vi(out_dir: Path) -> None:
    """Soft value iteration and the forward pass on a 6x6 deterministic gridworld."""
    n = 6
    moves = np.array([[0, 1], [1, 0], [0, -1], [-1, 0], [0, 0]])  # E, S, W, N, stay
    n_states, n_actions, horizon = n * n, len(moves), 14
    rows, cols = np.divmod(np.arange(n_states), n)
    nxt_r = np.clip(rows[:, None] + moves[None, :, 0], 0, n - 1)
    nxt_c = np.clip(cols[:, None] + moves[None, :, 1], 0, n - 1)
    nxt = nxt_r * n + nxt_c
    P = np.zeros((n_states, n_actions, n_states))
    P[np.arange(n_states)[:, None], np.arange(n_actions)[None, :], nxt] = 1.0

    reward_grid = np.full((n, n), -0.5)
    reward_grid[0:5, 2] = -4.0  # a wall of costly cells
    reward_grid[5, 5] = 6.0  # goal
    r = np.repeat(reward_grid.reshape(-1, 1), n_actions, axis=1)

    V = np.zeros((horizon + 1, n_states))
    pis = np.zeros((horizon, n_states, n_actions))
    for t in reversed(range(horizon)):
        Q = r + P @ V[t + 1]
        V[t] = logsumexp(Q, axis=1)
        pis[t] = np.exp(Q - V[t][:, None])
    d = np.zeros((horizon, n_states))
    d[0, 0] = 1.0  # start in the top-left corner
    for t in range(horizon - 1):
        d[t + 1] = np.einsum("s,sa,sax->x", d[t], pis[t], P)
    visits = d.sum(axis=0)

    fig, axes = plt.subplots(1, 3, figsize=(10, 3.5))
    panels = [
        (reward_grid, "reward $r(s)$", "RdBu"),
        (V[0].reshape(n, n), "soft value $V_0(s)$", "viridis"),
        (visits.reshape(n, n), r"expected visits $\sum_t d_t(s)$, start top-left", "magma"),
    ]
    for ax, (img, title, cmap) in zip(axes, panels):
        im = ax.imshow(img, cmap=cmap)
        ax.set_title(title, fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    # Mean move of the time-0 soft policy, drawn on the value panel.
    mean_move = np.einsum("sa,ak->sk", pis[0], moves)
    axes[1].quiver(
        cols, rows, mean_move[:, 1], -mean_move[:, 0], color="white", scale=9, width=0.012
    )
    save(fig, out_dir, "gridworld_soft_vi.png")


def lottery_bias(out_dir: Path) -> None:
    """Risky-vs-safe choice: trajectory-level (2008) form vs maximum causal entropy."""
    stakes = np.linspace(0, 6, 200)
    p_2008 = (0.5 * np.exp(stakes) + 0.5 * np.exp(-stakes)) / (
        0.5 * np.exp(stakes) + 0.5 * np.exp(-stakes) + 1.0
    )
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    ax.plot(stakes, p_2008, color=RED, lw=2, label=r"$p(\tau) \propto P(\tau)\,e^{R(\tau)}$ (2008 form)")
    ax.plot(stakes, np.full_like(stakes, 0.5), color=BLUE, lw=2, label="maximum causal entropy")
    ax.set_xlabel(r"stake $c$ (risky pays $\pm c$ with probability 1/2)")
    ax.set_ylabel("probability of the risky action")
    ax.set_ylim(0.4, 1.0)
    ax.legend(frameon=False, loc="lower right")
    save(fig, out_dir, "lottery_bias.png")


# ---------------------------------------------------------------- chapter 4


def feedback_spectrum(out_dir: Path) -> None:
    """Schematic: feedback types ordered by how present the human must be."""
    items = [
        (0.05, "logged\ndemonstrations", "BC, IRL"),
        (0.28, "requested\ndemonstrations", "teleoperation"),
        (0.50, "comparisons\nand rankings", "BT, RLHF, DPO"),
        (0.72, "scalar\nfeedback", "TAMER, COACH"),
        (0.95, "corrections,\ninterventions", "DAgger, physical HRI"),
    ]
    fig, ax = plt.subplots(figsize=(9, 2.6))
    ax.add_patch(
        FancyArrowPatch((0.0, 0.5), (1.02, 0.5), arrowstyle="-|>", mutation_scale=20, color=GREY, lw=2)
    )
    for x, name, example in items:
        ax.plot([x], [0.5], "o", color=BLUE, ms=10)
        ax.text(x, 0.68, name, ha="center", va="bottom", fontsize=10)
        ax.text(x, 0.32, example, ha="center", va="top", fontsize=9, color=GREY, style="italic")
    ax.text(0.0, 0.05, "human offline, no interaction", fontsize=9, ha="left")
    ax.text(1.0, 0.05, "human in the loop at every step", fontsize=9, ha="right")
    ax.set_xlim(-0.08, 1.08)
    ax.set_ylim(0, 1)
    ax.axis("off")
    save(fig, out_dir, "feedback_spectrum.png")


# ---------------------------------------------------------------- chapter 5


def bt_sigmoid(out_dir: Path) -> None:
    """Bradley-Terry (logistic) vs Thurstone (probit) link with matched slope at 0."""
    delta = np.linspace(-6, 6, 300)
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    ax.plot(delta, expit(delta), color=BLUE, lw=2, label=r"Bradley–Terry $\sigma(u_i-u_j)$")
    ax.plot(
        delta,
        norm.cdf(np.sqrt(np.pi / 8) * delta),
        color=ORANGE,
        lw=2,
        ls="--",
        label=r"Thurstone $\Phi(\sqrt{\pi/8}\,(u_i-u_j))$",
    )
    ax.axhline(0.5, color=GREY, lw=0.8)
    ax.axvline(0.0, color=GREY, lw=0.8)
    ax.set_xlabel(r"utility difference $u_i - u_j$")
    ax.set_ylabel(r"$\Pr(i \succ j)$")
    ax.legend(frameon=False, loc="upper left")
    save(fig, out_dir, "bt_sigmoid.png")


def run_rucb(p: np.ndarray, horizon: int, alpha: float, rng: np.random.Generator) -> np.ndarray:
    """Basic RUCB (Zoghi et al. 2014); returns the per-step regret of the chosen pairs."""
    k = p.shape[0]
    wins = np.zeros((k, k))
    best = int(np.argmax((p > 0.5).sum(axis=1)))  # the Condorcet winner
    delta = p[best] - 0.5
    regret = np.zeros(horizon)
    for t in range(1, horizon + 1):
        n = wins + wins.T
        with np.errstate(divide="ignore", invalid="ignore"):
            ucb = np.where(n > 0, wins / n + np.sqrt(alpha * np.log(t) / n), 1.0)
        np.fill_diagonal(ucb, 0.5)
        candidates = np.flatnonzero((ucb >= 0.5).all(axis=1))
        c = rng.choice(candidates) if len(candidates) else rng.integers(k)
        column = ucb[:, c]  # u_cc = 1/2: c duels itself when no arm looks better
        d = rng.choice(np.flatnonzero(column == column.max()))
        if rng.random() < p[c, d]:
            wins[c, d] += 1
        else:
            wins[d, c] += 1
        regret[t - 1] = 0.5 * (delta[c] + delta[d])
    return regret


def dueling_regret(out_dir: Path) -> None:
    """Cumulative regret of RUCB vs uniformly random duels on a BT instance."""
    rng = np.random.default_rng(0)
    u = np.array([1.0, 0.6, 0.4, 0.2, 0.0, -0.3])
    p = expit(u[:, None] - u[None, :])
    horizon, n_runs = 4000, 5
    delta = p[0] - 0.5
    rucb = np.mean([np.cumsum(run_rucb(p, horizon, 0.51, rng)) for _ in range(n_runs)], axis=0)
    pairs = rng.integers(len(u), size=(n_runs, horizon, 2))
    uniform = np.mean(np.cumsum(0.5 * (delta[pairs[..., 0]] + delta[pairs[..., 1]]), axis=1), axis=0)
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    steps = np.arange(1, horizon + 1)
    ax.plot(steps, uniform, color=GREY, lw=2, label="uniformly random duels")
    ax.plot(steps, rucb, color=BLUE, lw=2, label=r"RUCB, $\alpha = 0.51$")
    ax.set_xlabel("duels $t$")
    ax.set_ylabel("cumulative regret")
    ax.set_title("Bradley–Terry arms, $u = (1, .6, .4, .2, 0, -.3)$", fontsize=10)
    ax.legend(frameon=False)
    save(fig, out_dir, "dueling_regret.png")


# ---------------------------------------------------------------- chapter 6


def rlhf_pipeline(out_dir: Path) -> None:
    """Box diagram of the three-stage RLHF pipeline with its feedback loop."""
    fig, ax = plt.subplots(figsize=(9, 2.8))
    boxes = [
        (0.02, "1. supervised\nfine-tuning", "demonstrations\n$\\to \\pi^{\\mathrm{SFT}}$"),
        (0.36, "2. reward model", "comparisons\n$\\to r_\\phi$ (Bradley–Terry)"),
        (0.70, "3. RL with KL penalty", "PPO on\n$r_\\phi - \\beta \\log(\\pi_\\theta/\\pi_{\\mathrm{ref}})$"),
    ]
    width, height = 0.27, 0.5
    for x, title, body in boxes:
        ax.add_patch(
            FancyBboxPatch((x, 0.3), width, height, boxstyle="round,pad=0.02", fc="#e8f0fb", ec=BLUE)
        )
        ax.text(x + width / 2, 0.68, title, ha="center", va="center", fontsize=10, weight="bold")
        ax.text(x + width / 2, 0.45, body, ha="center", va="center", fontsize=9)
    for x0, x1 in [(0.29, 0.36), (0.63, 0.70)]:
        ax.add_patch(FancyArrowPatch((x0 + 0.01, 0.55), (x1 - 0.01, 0.55), arrowstyle="-|>", mutation_scale=15))
    ax.add_patch(
        FancyArrowPatch(
            (0.835, 0.28),
            (0.495, 0.28),
            connectionstyle="arc3,rad=-0.35",
            arrowstyle="-|>",
            mutation_scale=15,
            color=GREY,
        )
    )
    ax.text(0.665, 0.02, "new samples are labelled; iterate", ha="center", fontsize=9, color=GREY)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 0.9)
    ax.axis("off")
    save(fig, out_dir, "rlhf_pipeline.png")


# ---------------------------------------------------------------- chapter 7


def kl_tilt(out_dir: Path) -> None:
    """The KL-regularised optimum tilts pi_ref by exp(r / beta)."""
    y = np.arange(12)
    pi_ref = np.exp(-0.5 * ((y - 4.0) / 2.2) ** 2)
    pi_ref /= pi_ref.sum()
    r = 0.35 * y - 0.02 * (y - 8.0) ** 2
    fig, (ax_r, ax_p) = plt.subplots(1, 2, figsize=(9, 3.3))
    ax_r.bar(y, r, color=GREY)
    ax_r.set_title("reward $r(x, y)$", fontsize=10)
    ax_r.set_xlabel("response $y$")
    ax_p.plot(y, pi_ref, "o-", color="black", label=r"$\pi_{\mathrm{ref}}$ ($\beta = \infty$)")
    for beta, color in [(2.0, BLUE), (0.7, ORANGE), (0.25, RED)]:
        logits = np.log(pi_ref) + r / beta
        ax_p.plot(y, np.exp(logits - logsumexp(logits)), "o-", color=color, label=rf"$\pi^*$, $\beta = {beta}$")
    ax_p.set_title(r"$\pi^*(y|x) \propto \pi_{\mathrm{ref}}(y|x)\,e^{r(x,y)/\beta}$", fontsize=10)
    ax_p.set_xlabel("response $y$")
    ax_p.legend(frameon=False, fontsize=8)
    save(fig, out_dir, "kl_tilt.png")


def bon_kl(out_dir: Path) -> None:
    """KL of best-of-n: closed form, fine uniform grid, coarse discrete base."""
    ns = np.unique(np.round(np.logspace(0, 3, 25)).astype(int))

    def exact_kl(q: np.ndarray, n: int) -> float:
        cdf = np.concatenate([[0.0], np.cumsum(q)])
        p = cdf[1:] ** n - cdf[:-1] ** n
        mask = p > 0
        return float(np.sum(p[mask] * np.log(p[mask] / q[mask])))

    fine = np.full(100_000, 1e-5)
    coarse = np.full(20, 0.05)
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.plot(ns, np.log(ns), color=GREY, ls=":", label=r"$\log n$")
    ax.plot(ns, np.log(ns) - (ns - 1) / ns, color=BLUE, lw=2, label=r"$\log n - (n-1)/n$")
    ax.plot(ns, [exact_kl(fine, n) for n in ns], "o", color=BLUE, ms=4, label="exact, 100 000 equal atoms")
    ax.plot(ns, [exact_kl(coarse, n) for n in ns], "s", color=ORANGE, ms=4, label="exact, 20 equal atoms")
    ax.set_xscale("log")
    ax.set_xlabel("$n$")
    ax.set_ylabel(r"$D_{\mathrm{KL}}(\pi_{\mathrm{BoN}} \,\|\, \pi_{\mathrm{ref}})$ (nats)")
    ax.legend(frameon=False, fontsize=8)
    save(fig, out_dir, "bon_kl.png")


def overoptimisation(out_dir: Path) -> None:
    """Functional forms of Gao et al. (2022) for the gold reward, illustrative coefficients."""
    d = np.linspace(0.01, 10, 300)  # d = sqrt(KL)
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.plot(d, d * (1.0 - 0.12 * d), color=BLUE, lw=2, label=r"best-of-$n$: $d(\alpha - \beta d)$")
    ax.plot(d, d * (0.8 - 0.33 * np.log(d)), color=RED, lw=2, label=r"RL: $d(\alpha - \beta \log d)$")
    ax.plot(d, 0.9 * d, color=GREY, ls=":", label="proxy reward (keeps rising)")
    ax.set_xlabel(r"$d = \sqrt{D_{\mathrm{KL}}(\pi \,\|\, \pi_{\mathrm{init}})}$")
    ax.set_ylabel("gold reward gain (illustrative units)")
    ax.set_ylim(-0.5, 4)
    ax.legend(frameon=False, fontsize=8)
    save(fig, out_dir, "overoptimisation.png")


# ---------------------------------------------------------------- diagrams (chapters 3 and 6)


def _box(ax: plt.Axes, x: float, y: float, w: float, h: float, title: str, body: str, colour: str = BLUE) -> None:
    """A rounded box centred at (x, y) with a bold title and a smaller body."""
    ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h, boxstyle="round,pad=0.02", fc="#eef3fa", ec=colour))
    ax.text(x, y + h * 0.2, title, ha="center", va="center", fontsize=10, weight="bold")
    ax.text(x, y - h * 0.18, body, ha="center", va="center", fontsize=9)


def _arrow(ax: plt.Axes, start: tuple, end: tuple, label: str = "", rad: float = 0.0, colour: str = "black",
           offset: tuple = (0.0, 0.0)) -> None:
    """An arrow from ``start`` to ``end``, with a label at its midpoint shifted by ``offset``."""
    ax.add_patch(FancyArrowPatch(start, end, connectionstyle=f"arc3,rad={rad}", arrowstyle="-|>",
                                 mutation_scale=15, color=colour, lw=1.3))
    if label:
        ax.text((start[0] + end[0]) / 2 + offset[0], (start[1] + end[1]) / 2 + offset[1], label,
                ha="center", va="center", fontsize=8.5, color=colour)


def maxent_irl_loop(out_dir: Path) -> None:
    """One iteration of tabular MaxEnt IRL: backward soft VI, forward visitation, gradient step."""
    fig, ax = plt.subplots(figsize=(9.5, 3.6))
    _box(ax, 0.13, 0.72, 0.22, 0.3, "weights $w$", "reward $r_w(s,a) = w^\\top f(s,a)$")
    _box(ax, 0.5, 0.72, 0.26, 0.3, "backward pass", "soft value iteration\n$Q_t, V_t = \\mathrm{lse}_a Q_t$, $\\pi^w_t$")
    _box(ax, 0.87, 0.72, 0.22, 0.3, "forward pass", "$d_{t+1} = d_t \\pi^w_t P$\n$\\rho_w = \\sum_t d_t \\pi^w_t$")
    _box(ax, 0.68, 0.2, 0.3, 0.28, "gradient", "$\\hat\\mu_E - \\sum_{s,a} \\rho_w(s,a) f(s,a)$", GREEN)
    _box(ax, 0.2, 0.2, 0.26, 0.28, "demonstrations", "$\\hat\\mu_E = \\frac{1}{N}\\sum_i F(\\tau_i)$", GREY)
    _arrow(ax, (0.24, 0.72), (0.37, 0.72))
    _arrow(ax, (0.63, 0.72), (0.76, 0.72), "$\\pi^w$", offset=(0, 0.05))
    _arrow(ax, (0.87, 0.57), (0.78, 0.34), "$\\rho_w$", offset=(0.04, 0))
    _arrow(ax, (0.33, 0.2), (0.53, 0.2))
    _arrow(ax, (0.56, 0.34), (0.17, 0.57), "$w \\leftarrow w + \\eta\\,\\nabla$", rad=-0.25, colour=GREEN,
           offset=(0.08, -0.05))
    ax.text(0.5, 0.95, "repeat until the expected features match the demonstrations'", ha="center", fontsize=9,
            color=GREY)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.axis("off")
    save(fig, out_dir, "maxent_irl_loop.png")


def christiano_loop(out_dir: Path) -> None:
    """The three asynchronous processes of Christiano et al. (2017)."""
    fig, ax = plt.subplots(figsize=(9.5, 3.6))
    _box(ax, 0.14, 0.7, 0.24, 0.3, "policy $\\pi_\\theta$", "RL (A2C, TRPO, PPO)\non $\\hat r_\\phi(s, a)$")
    _box(ax, 0.5, 0.7, 0.24, 0.3, "environment", "no reward signal;\nobservations, actions")
    _box(ax, 0.86, 0.7, 0.24, 0.3, "human", "watches two clips,\nsays which is better")
    _box(ax, 0.5, 0.17, 0.34, 0.28, "reward model $\\hat r_\\phi$", "Bradley–Terry on segment returns", GREEN)
    _arrow(ax, (0.26, 0.75), (0.38, 0.75), "actions", offset=(0, 0.05))
    _arrow(ax, (0.38, 0.65), (0.26, 0.65), "observations", offset=(0, -0.05))
    _arrow(ax, (0.62, 0.7), (0.74, 0.7), "segment pairs", offset=(0, 0.05))
    _arrow(ax, (0.86, 0.55), (0.67, 0.2), "comparisons", offset=(0.08, 0.02))
    _arrow(ax, (0.33, 0.2), (0.14, 0.55), "predicted reward", offset=(-0.1, 0.0), colour=GREEN)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 0.95)
    ax.axis("off")
    save(fig, out_dir, "christiano_loop.png")


def ppo_clip(out_dir: Path) -> None:
    """One sample's clipped objective against the ratio, for a positive and a negative advantage."""
    eps = 0.2
    ratio = np.linspace(0.0, 2.0, 401)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.3), sharey=False)
    for ax, adv in zip(axes, (1.0, -1.0)):
        clipped = np.minimum(ratio * adv, np.clip(ratio, 1 - eps, 1 + eps) * adv)
        ax.plot(ratio, ratio * adv, color=GREY, ls="--", label=r"$\mathrm{ratio}\cdot\hat A$")
        ax.plot(ratio, clipped, color=BLUE if adv > 0 else RED, lw=2.2, label=r"$L^{\mathrm{CLIP}}$ term")
        for edge in (1 - eps, 1 + eps):
            ax.axvline(edge, color=GREY, lw=0.6, ls=":")
        ax.axvline(1.0, color="black", lw=0.6)
        ax.set_xlabel(r"ratio $\pi_\theta(a\mid s)/\pi_{\mathrm{old}}(a\mid s)$")
        ax.set_title(r"$\hat A = %+d$" % adv)
        ax.legend(frameon=False, loc="upper left" if adv > 0 else "lower left")
    axes[0].set_ylabel("objective (to maximise)")
    save(fig, out_dir, "ppo_clip.png")


def _gae_targets(rewards: np.ndarray, values: np.ndarray, dones: np.ndarray, last_value: float,
                 gamma: float, lam: float) -> np.ndarray:
    """Critic targets A + V from the backward recursion of chapter 6 (one environment)."""
    adv, next_adv, next_value = np.zeros_like(rewards), 0.0, last_value
    for t in reversed(range(len(rewards))):
        alive = 1.0 - dones[t]
        delta = rewards[t] + gamma * alive * next_value - values[t]
        next_adv = delta + gamma * lam * alive * next_adv
        adv[t], next_value = next_adv, values[t]
    return adv + values


def gae_truncation(out_dir: Path) -> None:
    """Value targets near a time limit: truncation treated as termination vs bootstrapped."""
    gamma, lam, limit = 0.99, 0.95, 50
    true_value = 1.0 / (1.0 - gamma)
    steps = np.arange(2 * limit)
    values = np.full(2 * limit, true_value)  # exact critic: reward 1 forever from every state
    dones = ((steps + 1) % limit == 0).astype(float)
    as_termination = _gae_targets(np.ones(2 * limit), values, dones, true_value, gamma, lam)
    bootstrapped = _gae_targets(1.0 + dones * gamma * true_value, values, dones, true_value, gamma, lam)
    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.plot(steps, as_termination, color=ORANGE, lw=2, label="time limit treated as termination")
    ax.plot(steps, bootstrapped, color=BLUE, lw=2, label=r"bootstrapped: $r + \gamma V(s^{\mathrm{final}})$")
    ax.axhline(true_value, color=GREY, ls=":", lw=1)
    ax.set_xlabel("step in the buffer (episodes of 50 steps)")
    ax.set_ylabel(r"critic target $\hat G_t$")
    ax.set_ylim(0, 110)
    ax.legend(frameon=False, loc="lower left")
    save(fig, out_dir, "gae_truncation.png")


# ---------------------------------------------------------------- chapter 2


def feature_matching_projection(out_dir: Path) -> None:
    """Abbeel and Ng's projection method in a two-feature MDP (feature expectations of all policies)."""
    rng = np.random.default_rng(4)
    n_states, n_actions, gamma = 6, 2, 0.8
    P = rng.dirichlet(np.ones(n_states) * 0.5, size=(n_states, n_actions))
    p0 = np.full(n_states, 1.0 / n_states)
    f = rng.uniform(0.0, 1.0, size=(n_states, n_actions, 2))

    def mu_of(pi: np.ndarray) -> np.ndarray:
        rho = np.linalg.solve(np.eye(n_states) - gamma * np.einsum("sa,sax->sx", pi, P).T, p0)
        return (1 - gamma) * np.einsum("s,sa,sak->k", rho, pi, f)

    corners = []  # feature expectations of all deterministic stationary policies
    for code in range(n_actions**n_states):
        acts = (code // n_actions ** np.arange(n_states)) % n_actions
        corners.append(mu_of(np.eye(n_actions)[acts]))
    corners = np.array(corners)
    expert = mu_of(rng.dirichlet(np.ones(n_actions), size=n_states))

    mu = [corners[0]]
    bar = corners[0]
    path = [bar]
    for _ in range(6):
        w = expert - bar
        mu_j = corners[np.argmax(corners @ w)]  # an optimal policy for r_w (best corner)
        step = mu_j - bar
        bar = bar + (step @ (expert - bar)) / (step @ step) * step
        mu.append(mu_j)
        path.append(bar)
    mu, path = np.array(mu), np.array(path)

    fig, ax = plt.subplots(figsize=(5.6, 4.4))
    ax.scatter(corners[:, 0], corners[:, 1], s=6, color=GREY, label="deterministic policies")
    ax.scatter(mu[:, 0], mu[:, 1], s=40, facecolors="none", edgecolors=BLUE, label=r"$\mu_j$ (RL step)")
    ax.plot(path[:, 0], path[:, 1], "-o", color=GREEN, ms=4, label=r"$\bar\mu_j$ (projections)")
    ax.scatter(*expert, marker="*", s=160, color=RED, zorder=5, label=r"$\hat\mu_E$")
    ax.annotate(r"$w_1 = \hat\mu_E - \bar\mu_0$", xy=expert, xytext=path[0] + np.array([-0.04, 0.04]),
                arrowprops=dict(arrowstyle="->", color=RED, lw=1), fontsize=9, color=RED)
    ax.set_xlabel("expected feature 1")
    ax.set_ylabel("expected feature 2")
    ax.legend(frameon=False, fontsize=8, loc="best")
    save(fig, out_dir, "feature_matching_projection.png")


# ---------------------------------------------------------------- chapter 1


def bc_multimodal(out_dir: Path) -> None:
    """Two ways around an obstacle: the squared-error fit averages them, a mixture does not."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, size=400)
    side = rng.random(400) < 0.5
    steer = np.where(side, 1.0, -1.0) * np.exp(-(x**2) / 0.3) + 0.08 * rng.normal(size=400)
    grid = np.linspace(-1, 1, 200)
    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.scatter(x, steer, s=6, color=GREY, label="demonstrations (pass left or right)")
    mean_fit = np.polyval(np.polyfit(x, steer, 6), grid)  # least squares over polynomials of degree 6
    ax.plot(grid, mean_fit, color=RED, lw=2, label="squared-error fit: the mean")
    for sign, lbl in ((1, "mixture components"), (-1, None)):
        ax.plot(grid, sign * np.exp(-(grid**2) / 0.3), color=BLUE, lw=2, ls="--", label=lbl)
    ax.axvspan(-0.12, 0.12, color=RED, alpha=0.1)
    ax.text(0, -1.35, "obstacle", ha="center", color=RED, fontsize=9)
    ax.set_xlabel("distance to the obstacle (state)")
    ax.set_ylabel("steering (action)")
    ax.set_ylim(-1.5, 2.1)
    ax.legend(frameon=False, fontsize=8, loc="upper center", ncol=2)
    save(fig, out_dir, "bc_multimodal.png")


def kl_estimators(out_dir: Path) -> None:
    """The three one-sample KL estimators against the ratio rho = pi_ref(a|s) / pi_theta(a|s)."""
    rho = np.linspace(0.05, 4.0, 400)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(rho, -np.log(rho), color=RED, lw=2, label=r"$k_1 = -\log\rho$ (unbiased, can be negative)")
    ax.plot(rho, 0.5 * np.log(rho) ** 2, color=GREEN, lw=2, label=r"$k_2 = \frac{1}{2}(\log\rho)^2$ (biased, $\geq 0$)")
    ax.plot(rho, rho - 1 - np.log(rho), color=BLUE, lw=2, label=r"$k_3 = \rho - 1 - \log\rho$ (unbiased, $\geq 0$)")
    ax.axhline(0, color=GREY, lw=0.8)
    ax.axvline(1, color=GREY, lw=0.8, ls=":")
    ax.set_xlabel(r"$\rho = \pi_{\mathrm{ref}}(a\mid s)\,/\,\pi_\theta(a\mid s)$ of the sampled action")
    ax.set_ylabel("one-sample estimate")
    ax.set_ylim(-1.5, 3)
    ax.legend(frameon=False, fontsize=8.5)
    save(fig, out_dir, "kl_estimators.png")


def token_batch(out_dir: Path) -> None:
    """One row of hw5's batch: prompt, completion and padding, with mask, rewards and values."""
    tokens = ["the", "cat", "sat", "on", "a", "mat", "<eos>", "<pad>", "<pad>"]
    kind = ["prompt"] * 2 + ["completion"] * 5 + ["padding"] * 2
    colours = {"prompt": "#eeeeee", "completion": "#e3eefb", "padding": "#fbeaea"}
    rows = [
        ("token $y_t$", tokens),
        ("mask $m_t$", ["0", "0", "1", "1", "1", "1", "1", "0", "0"]),
        ("reward $r_t$", ["0", "0"] + [r"$-\beta\ell_t$"] * 4 + [r"$-\beta\ell_t + R$", "0", "0"]),
        ("value $V_t$", ["", ""] + [r"$V_%d$" % t for t in range(2, 7)] + ["", ""]),
        ("in the loss", ["", ""] + ["yes"] * 5 + ["", ""]),
    ]
    fig, ax = plt.subplots(figsize=(10, 3.0))
    for i, (label, cells) in enumerate(rows):
        y = len(rows) - 1 - i
        ax.text(-0.65, y, label, ha="right", va="center", fontsize=9.5)
        for j, cell in enumerate(cells):
            ax.add_patch(FancyBboxPatch((j - 0.45, y - 0.38), 0.9, 0.76, boxstyle="round,pad=0.02",
                                        fc=colours[kind[j]], ec=GREY, lw=0.6))
            ax.text(j, y, cell, ha="center", va="center", fontsize=9)
    ax.text(0.5, len(rows) - 0.25, "prompt", ha="center", fontsize=9, color=GREY)
    ax.text(4.0, len(rows) - 0.25, "completion (the policy's actions)", ha="center", fontsize=9, color=BLUE)
    ax.text(7.5, len(rows) - 0.25, "padding", ha="center", fontsize=9, color=RED)
    ax.set_xlim(-2.6, len(tokens) - 0.4)
    ax.set_ylim(-0.6, len(rows) + 0.1)
    ax.axis("off")
    save(fig, out_dir, "token_batch.png")


def dpo_start_states(out_dir: Path) -> None:
    """One-step DPO with two start states of different value: same-start pairs recover pi*, mixed pairs do not."""
    from scipy.optimize import minimize
    from scipy.special import log_expit

    beta = 1.0
    reward = np.array([[2.0, 1.2, 0.4], [0.3, -0.2, -0.9]])  # start A is worth more than start B
    ref = np.full((2, 3), 1.0 / 3)
    pi_star = ref * np.exp(reward / beta)
    pi_star /= pi_star.sum(axis=1, keepdims=True)

    def fit(mixed: bool) -> np.ndarray:
        items = [(s, a) for s in range(2) for a in range(3)]
        pairs = [(i, j) for i in items for j in items if i != j and (mixed or i[0] == j[0])]

        def loss(theta: np.ndarray) -> float:
            logits = theta.reshape(2, 3)
            g = beta * (logits - logsumexp(logits, axis=1, keepdims=True) - np.log(ref))
            total = 0.0
            for (s1, a1), (s2, a2) in pairs:
                label = expit(reward[s1, a1] - reward[s2, a2])  # Bradley-Terry on the true rewards
                margin = g[s1, a1] - g[s2, a2]
                total -= ref[s1, a1] * ref[s2, a2] * (label * log_expit(margin) + (1 - label) * log_expit(-margin))
            return total

        theta = minimize(loss, np.zeros(6), method="BFGS").x.reshape(2, 3)
        return np.exp(theta - logsumexp(theta, axis=1, keepdims=True))

    fits = [("$\\pi^*$", pi_star, GREY), ("DPO, pairs share a start", fit(False), BLUE),
            ("DPO, pairs mix the starts", fit(True), RED)]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.3), sharey=True)
    for ax, s, name in zip(axes, range(2), ("start A (high value)", "start B (low value)")):
        for k, (label, pi, colour) in enumerate(fits):
            ax.bar(np.arange(3) + (k - 1) * 0.27, pi[s], width=0.27, color=colour, label=label)
        ax.set_xticks(range(3), [f"action {a + 1}\nr = {reward[s, a]:+.1f}" for a in range(3)], fontsize=8.5)
        ax.set_title(name, fontsize=10)
    axes[0].set_ylabel("probability")
    axes[1].legend(frameon=False, fontsize=8.5)
    save(fig, out_dir, "dpo_start_states.png")


FIGURES = [
    compounding_error,
    bc_multimodal,
    feature_matching_projection,
    maxent_irl_loop,
    christiano_loop,
    ppo_clip,
    gae_truncation,
    kl_estimators,
    token_batch,
    dpo_start_states,
    gridworld_soft_vi,
    lottery_bias,
    feedback_spectrum,
    bt_sigmoid,
    dueling_regret,
    rlhf_pipeline,
    kl_tilt,
    bon_kl,
    overoptimisation,
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent, help="output folder")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for make in FIGURES:
        make(args.out)
        print(f"wrote {make.__name__}")


if __name__ == "__main__":
    main()
