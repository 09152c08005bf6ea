"""Learning-curve plots: a mean line and a band of one standard deviation over seeds."""
from __future__ import annotations

from typing import Mapping, Sequence

import matplotlib.pyplot as plt
import numpy as np


def plot_curves(
    curves: Mapping[str, tuple[Sequence[float], np.ndarray]],
    xlabel: str,
    ylabel: str,
    title: str | None = None,
    hlines: Mapping[str, float] | None = None,
    ax: plt.Axes | None = None,
) -> plt.Axes:
    """Plot each named curve ``(x, y)``, where ``y`` is ``(len(x),)`` or ``(n_seeds, len(x))``.

    With several seeds the line is the mean and the band one standard deviation.
    ``hlines`` draws labelled reference levels (an expert's return, a ceiling).
    """
    ax = ax or plt.subplots(figsize=(6, 3.5))[1]
    for name, (x, y) in curves.items():
        y = np.atleast_2d(np.asarray(y, dtype=float))
        mean = y.mean(axis=0)
        (line,) = ax.plot(x, mean, label=name if y.shape[0] == 1 else f"{name} (n={y.shape[0]})")
        if y.shape[0] > 1:
            std = y.std(axis=0)
            ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    for name, level in (hlines or {}).items():
        ax.axhline(level, linestyle="--", color="grey", linewidth=1)
        ax.annotate(name, (1.0, level), xycoords=("axes fraction", "data"), ha="right", va="bottom", fontsize=8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(frameon=False)
    return ax
