"""The figures of the lecture chapter `lectures/01b_multimodal.md`, from closed forms (no training) and, for
`multimodal_averaging.png`, from the benchmark's recorded results (`bench/results/hw1b_multimodal.json`):

    python bench/figures_hw1b_multimodal.py      # writes lectures/figures/multimodal_*.png

A one-dimensional "steering" distribution with two modes (a mixture of two Gaussians) stands for the
demonstrators' actions at one observation. Straight paths from a standard normal to it have a marginal
velocity in closed form (the chapter's equation eq-mm-marginal-velocity), so the flow, its density and
Euler's samples are exact. Kept out of the student release (bench/ is instructor-side): it integrates the
flow, which the notebook asks students to write.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "lectures" / "figures"
RESULTS = Path(__file__).resolve().parent / "results" / "hw1b_multimodal.json"
WEIGHTS, MEANS, SCALE = np.array([0.5, 0.5]), np.array([-1.0, 1.0]), 0.15   # the two demonstrated modes


def path_moments(t: np.ndarray):
    """Per component m: the mean t mu_m and variance (1 - t)^2 + t^2 s^2 of a_t given m."""
    t = np.asarray(t, dtype=float)[..., None]
    return t * MEANS, (1 - t) ** 2 + t**2 * SCALE**2


def density(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """p_t(a), the marginal density of a_t = (1 - t) a_0 + t a_1 (broadcast a and t)."""
    mean, var = path_moments(t)
    return (WEIGHTS * np.exp(-0.5 * (np.asarray(a)[..., None] - mean) ** 2 / var) / np.sqrt(2 * np.pi * var)).sum(-1)


def marginal_velocity(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """u_t(a) = E[a_1 - a_0 | a_t = a]: per component a Gaussian regression, weighted by the posterior of m."""
    a, t = np.asarray(a, dtype=float), np.asarray(t, dtype=float)
    mean, var = path_moments(t)
    log_w = np.log(WEIGHTS) - 0.5 * (a[..., None] - mean) ** 2 / var - 0.5 * np.log(var)
    w = np.exp(log_w - log_w.max(-1, keepdims=True))
    w /= w.sum(-1, keepdims=True)
    cov = t[..., None] * SCALE**2 - (1 - t[..., None])        # Cov(a_1 - a_0, a_t | m)
    return (w * (MEANS + cov / var * (a[..., None] - mean))).sum(-1)


def euler(a0: np.ndarray, n_steps: int) -> np.ndarray:
    """Euler's K-step solution of da/dt = u_t(a) from t = 0 to 1."""
    a = a0.copy()
    for j in range(n_steps):
        a = a + marginal_velocity(a, np.full_like(a, j / n_steps)) / n_steps
    return a


def flow_figure(path: Path) -> None:
    rng = np.random.default_rng(0)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), gridspec_kw={"width_ratios": [1.3, 1]})
    ts = np.linspace(0, 1, 201)
    grid = np.linspace(-2.5, 2.5, 301)
    axes[0].imshow(density(grid[:, None], ts[None, :]), origin="lower", aspect="auto", cmap="Greys",
                   extent=(0, 1, grid[0], grid[-1]), vmax=1.2)
    a = np.sort(rng.normal(size=40))
    trajectory = [a]
    for j in range(200):
        a = a + marginal_velocity(a, np.full_like(a, j / 200)) / 200
        trajectory.append(a)
    trajectory = np.array(trajectory)
    for i in range(trajectory.shape[1]):
        axes[0].plot(np.linspace(0, 1, 201), trajectory[:, i], color="tab:blue" if trajectory[-1, i] > 0 else "tab:orange",
                     linewidth=0.8)
    axes[0].set_xlabel("t"); axes[0].set_ylabel("action a")
    axes[0].set_title("the flow of $u_t$ carries N(0, 1) onto both modes")
    axes[1].hist(np.r_[rng.normal(-1, SCALE, 500), rng.normal(1, SCALE, 500)], bins=60, density=True, color="grey",
                 alpha=0.6, label="demonstrated actions")
    axes[1].axvline(0.0, color="tab:red", linewidth=2, label="L2 clone: the conditional mean")
    axes[1].plot(grid, density(grid, np.ones_like(grid)), color="tab:blue", label="$p_1$ of the flow")
    axes[1].set_xlabel("action a"); axes[1].legend(frameon=False, fontsize=8)
    axes[1].set_title("what each policy outputs at this observation")
    plt.tight_layout(); fig.savefig(path, dpi=110); plt.close(fig)


def euler_figure(path: Path) -> None:
    rng = np.random.default_rng(1)
    a0 = rng.normal(size=4000)
    fig, axes = plt.subplots(1, 4, figsize=(11, 2.6), sharey=True)
    for ax, K in zip(axes, (1, 2, 4, 20)):
        ax.hist(euler(a0, K), bins=np.linspace(-2, 2, 81), density=True, color="tab:green")
        ax.set_title(f"K = {K} Euler step{'s' if K > 1 else ''}"); ax.set_xlabel("sampled action")
    axes[0].set_ylabel("density")
    plt.tight_layout(); fig.savefig(path, dpi=110); plt.close(fig)


def averaging_figure(path: Path) -> None:
    """Success per setting of the averaging protocol: one dot per training seed, a bar at the mean."""
    import json

    record = json.loads(RESULTS.read_text())
    settings = record["averaging"]["settings"]
    followup = {s["name"]: s for s in record.get("averaging_followup", {}).get("settings", [])}
    policies = [("l2", "L2, H=k=8", "tab:red"), ("mixture", "mixture, H=k=8", "tab:purple"),
                ("flow", "flow, H=k=8", "tab:green"), ("flow_12k", "flow, H=k=8, 4x steps (follow-up)", "tab:olive"),
                ("l2_one_step", "L2, one step", "tab:grey")]
    fig, ax = plt.subplots(figsize=(9, 3.6))
    width = 0.8 / len(policies)
    for j, (key, label, colour) in enumerate(policies):
        for i, s in enumerate(settings):
            values = followup.get(s["name"], {}).get(key) if key == "flow_12k" else s[key]
            if values is None:
                continue
            x = i + (j - (len(policies) - 1) / 2) * width
            ax.bar(x, np.mean(values), width * 0.9, color=colour, alpha=0.55, label=label if i == 0 else None)
            ax.plot(np.full(len(values), x), values, "o", color=colour, markersize=3)
    ax.axhline(0.9, color="tab:green", linestyle=":", linewidth=1)
    ax.axhline(0.6, color="tab:red", linestyle=":", linewidth=1)
    ax.set_xticks(range(len(settings)), [f"{s['name']} swerve (rise {s['swerve_rise']:g})" for s in settings])
    ax.set_ylabel("success (expert: 1.00)"); ax.set_ylim(0, 1.05); ax.grid(alpha=0.3, axis="y")
    ax.legend(frameon=False, fontsize=7, ncols=3, loc="upper center", bbox_to_anchor=(0.5, -0.12))
    ax.set_title("Committing where the demonstrators split: 5 seeds per bar (dotted: the targets)", fontsize=9)
    plt.tight_layout(); fig.savefig(path, dpi=110); plt.close(fig)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    flow_figure(OUT / "multimodal_flow.png")
    euler_figure(OUT / "multimodal_euler.png")
    averaging_figure(OUT / "multimodal_averaging.png")
    print(f"wrote {OUT / 'multimodal_flow.png'}, {OUT / 'multimodal_euler.png'} and {OUT / 'multimodal_averaging.png'}")


if __name__ == "__main__":
    main()
