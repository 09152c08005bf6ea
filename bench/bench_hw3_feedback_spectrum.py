"""hw3's feedback spectrum: ratings, comparisons and rankings from a simulated panel, at equal annotator time.

    python bench/bench_hw3_feedback_spectrum.py        # writes bench/results/hw3_feedback_spectrum.json
    python bench/bench_hw3_feedback_spectrum.py --notebook-budgets   # hw3's notebook FAST and full, merged in

The experiment of the notebook's section C.4 at its full settings (``rlcourse.feedback_spectrum``
holds the panel, the costs per label and the five linear reward models). Settings were fixed before
the first run and are not tuned on its outcome:

* budget curve: ``BUDGETS`` seconds of annotator time, for two panels (one annotator without offset,
  scale or drift; five annotators with offsets of 1.5 points, log-scales of 0.3 and a drift of 2 points
  per 600 s);
* drift sweep: ``DRIFTS`` points per 600 s at ``SWEEP_BUDGET`` seconds, for one annotator (no offset
  or scale) and for five (offsets 1.5, log-scales 0.3);
* seeds 0-4 everywhere; every value is held-out accuracy on hw3's test labels over the Bayes ceiling.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402
from rlcourse import feedback_spectrum as F  # noqa: E402
from rlcourse.preferences import load_hopper_preferences  # noqa: E402

RESULTS = REPO / "bench" / "results" / "hw3_feedback_spectrum.json"
SEEDS = [0, 1, 2, 3, 4]
BUDGETS = [40, 80, 160, 320, 640, 1280]
CURVE_PANELS = {"one annotator, no drift": F.Panel(1, 0.0, 0.0, 0.0),
                "five annotators, offsets, scales, drift 2": F.Panel(5, 1.5, 0.3, 2.0)}
DRIFTS = [0.0, 1.0, 2.0, 4.0, 8.0]
SWEEP_BUDGET = 1280
SWEEP_SHAPES = {"one annotator": (1, 0.0, 0.0), "five annotators, offsets and scales": (5, 1.5, 0.3)}


def ratings_to_comparisons(annotator, segment, rating, window: int = 5):
    """The bench's copy of hw3's stub (the solution notebook's answer): each rating against each of the
    next ``window`` ratings by the same annotator, same-segment pairs skipped; ``(pairs, mu)``."""
    annotator, segment, rating = np.asarray(annotator), np.asarray(segment), np.asarray(rating, dtype=float)
    pairs, mu = [], []
    for k in np.unique(annotator):
        rows = np.flatnonzero(annotator == k)
        for lag in range(1, window + 1):
            a, b = rows[:-lag], rows[lag:]
            keep = segment[a] != segment[b]
            a, b = a[keep], b[keep]
            pairs.append(np.stack([segment[a], segment[b]], 1))
            mu.append(0.5 + 0.5 * np.sign(rating[a] - rating[b]))
    if not pairs:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    return np.concatenate(pairs).astype(np.int64), np.concatenate(mu).astype(float)


def summary(table: dict[str, np.ndarray]) -> dict:
    return {m: {"per_seed": np.round(v, 4).tolist(), "mean": np.round(v.mean(0), 4).tolist(),
                "sd": np.round(v.std(0, ddof=1), 4).tolist()} for m, v in table.items()}


def notebook_budgets() -> dict:
    """hw3's solution notebook, C.3 included, under a Jupyter kernel at ``FAST = True`` and at its full budget: wall
    seconds, the kernel's CPU seconds (this process's reaped children) and the load before and after each run."""
    import os
    import resource
    import tempfile

    from autograder.authoring.nbrun import run_notebook

    def cpu() -> float:
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    out = {"notebook": "solutions/hw3_preferences/hw3_preferences.ipynb", "meta": meta(["solutions/hw3_preferences"])}
    for name, fast in (("fast", True), ("full", False)):
        load, before = [round(x, 2) for x in os.getloadavg()], cpu()
        with tempfile.TemporaryDirectory() as tmp:
            report = run_notebook(REPO / out["notebook"], {"FAST": fast}, timeout=3600, cwd=tmp)
        assert report.ok, report
        out[name] = {"seconds": round(report.seconds, 1), "kernel_cpu_seconds": round(cpu() - before, 1),
                     "load_before": load, "load_after": [round(x, 2) for x in os.getloadavg()]}
        print(name, out[name], flush=True)
    return out


def main() -> None:
    if sys.argv[1:] == ["--notebook-budgets"]:  # only the notebook's budgets, merged into the recorded file
        record = json.loads(RESULTS.read_text())
        record["notebook_budgets"] = notebook_budgets()
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        return
    start = time.perf_counter()
    prefs = load_hopper_preferences()
    X = F.segment_features(prefs)
    curves = F.run_grid(prefs, X, CURVE_PANELS, BUDGETS, SEEDS, to_comparisons=ratings_to_comparisons)
    sweep = {}
    for shape, (n, off, sc) in SWEEP_SHAPES.items():
        panels = {f"drift {d:g}": F.Panel(n, off, sc, d) for d in DRIFTS}
        grid = F.run_grid(prefs, X, panels, [SWEEP_BUDGET], SEEDS, to_comparisons=ratings_to_comparisons)
        sweep[shape] = {m: np.stack([grid[p][m][:, 0] for p in panels], 1) for m in F.METHODS}  # (seeds, drifts)
    out = {"meta": meta(["rlcourse/feedback_spectrum.py", "bench/bench_hw3_feedback_spectrum.py"]),
           "settings": {"seeds": SEEDS, "budgets_seconds": BUDGETS, "seconds_per_label": F.SECONDS_PER_LABEL,
                        "rank_k": F.RANK_K, "drift_seconds": F.DRIFT_SECONDS, "window": 5,
                        "curve_panels": {k: vars(p) for k, p in CURVE_PANELS.items()},
                        "drifts": DRIFTS, "sweep_budget_seconds": SWEEP_BUDGET,
                        "sweep_shapes": {k: dict(zip(("n_annotators", "offset_sd", "scale_sd"), v))
                                         for k, v in SWEEP_SHAPES.items()},
                        "measure": "held-out accuracy on hw3's test labels / Bayes ceiling",
                        "bayes_ceiling": prefs.info["bayes_ceiling_test"]},
           "labels_per_budget": {str(b): F.labels_for_budget(b) for b in BUDGETS},
           "budget_curves": {k: summary(v) for k, v in curves.items()},
           "drift_sweep": {k: summary(v) for k, v in sweep.items()},
           "wall_seconds": round(time.perf_counter() - start, 1)}
    if RESULTS.exists() and "notebook_budgets" in (old := json.loads(RESULTS.read_text())):
        out["notebook_budgets"] = old["notebook_budgets"]
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: out[k] for k in ("wall_seconds", "labels_per_budget")}))


if __name__ == "__main__":
    main()
