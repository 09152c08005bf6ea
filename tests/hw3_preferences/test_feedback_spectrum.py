"""hw3's feedback spectrum (rlcourse.feedback_spectrum), its recorded benchmark and the widget's rating phase."""
from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from conftest import REPO
from rlcourse import feedback_spectrum as F
from rlcourse.preferences import load_hopper_preferences


@pytest.fixture(scope="module")
def prefs():
    return load_hopper_preferences()


def _bench():
    spec = importlib.util.spec_from_file_location("bench_fs", REPO / "bench" / "bench_hw3_feedback_spectrum.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_module_does_not_define_the_stub():
    assert not hasattr(F, "ratings_to_comparisons")


def test_features_are_standardised_and_nearly_span_the_true_return(prefs):
    X = F.segment_features(prefs)
    assert X.shape == (len(prefs.obs), 15)
    assert np.allclose(X.mean(0), 0, atol=1e-8)
    # a linear reward of these features orders the held-out pairs almost as the true return does
    w = F.fit_regression(X, prefs.returns)
    assert F.accuracy_to_ceiling(X @ w, prefs) > 0.99
    assert F.accuracy_to_ceiling(-(X @ w), prefs) < 0.2


def test_regression_with_offsets_removes_per_group_intercepts():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(300, 4))
    groups = rng.integers(0, 3, 300)
    w = np.array([1.0, -2.0, 0.5, 0.0])
    y = X @ w + np.array([5.0, -3.0, 9.0])[groups] + rng.normal(0, 0.01, 300)
    assert np.allclose(F.fit_regression(X, y, groups, ridge=0.0), w, atol=0.01)
    # correlated offsets bias the pooled fit when groups see different clips
    Xb = X + np.array([1.0, 0.0, -1.0])[groups][:, None]
    yb = Xb @ w + np.array([5.0, -3.0, 9.0])[groups]
    assert np.abs(F.fit_regression(Xb, yb, ridge=0.0) - w).max() > 0.5
    assert np.allclose(F.fit_regression(Xb, yb, groups, ridge=0.0), w, atol=1e-6)


def test_bradley_terry_and_plackett_luce_fits_recover_a_linear_utility():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(200, 3))
    w = np.array([2.0, -1.0, 0.5])
    pairs = rng.integers(0, 200, (4000, 2))
    mu = (rng.random(4000) < 1 / (1 + np.exp(-(X[pairs[:, 0]] - X[pairs[:, 1]]) @ w))).astype(float)
    got = F.fit_bradley_terry_linear(X, pairs, mu, l2=0.0)
    assert np.allclose(got, w, atol=0.25)
    groups = np.stack([rng.choice(200, 4, replace=False) for _ in range(2000)])
    order = np.argsort(-(X[groups] @ w + rng.gumbel(size=groups.shape)), axis=1)
    got = F.fit_plackett_luce_linear(X, groups, order, l2=0.0)
    assert np.allclose(got, w, atol=0.25)
    # the fit is a stationary point of the Plackett-Luce likelihood (central differences, not the module's gradient)
    Fg = X[np.take_along_axis(groups, order, 1)]

    def nll(v):
        s = Fg @ v
        return np.mean((np.logaddexp.accumulate(s[:, ::-1], axis=1)[:, ::-1] - s).sum(1))
    eps = 1e-5
    numeric = np.array([(nll(got + eps * e) - nll(got - eps * e)) / (2 * eps) for e in np.eye(3)])
    assert np.abs(numeric).max() < 1e-4


def test_budgets_buy_labels_at_the_stated_costs():
    assert F.labels_for_budget(1280) == {"rating": 426, "comparison": 320, "ranking": 160}
    assert F.SECONDS_PER_LABEL == {"rating": 3.0, "comparison": 4.0, "ranking": 8.0}


def test_run_budget_uses_the_conversion_it_is_given(prefs):
    X = F.segment_features(prefs)
    conv = _bench().ratings_to_comparisons
    out = F.run_budget(prefs, X, F.Panel(3, 1.5, 0.3, 2.0), 320, 0, to_comparisons=conv)
    assert set(out) == set(F.METHODS) and all(0.4 < v <= 1.05 for v in out.values())
    assert out == F.run_budget(prefs, X, F.Panel(3, 1.5, 0.3, 2.0), 320, 0, to_comparisons=conv)  # seeded
    flipped = F.run_budget(prefs, X, F.Panel(3, 1.5, 0.3, 2.0), 320, 0,
                           to_comparisons=lambda *a: (lambda p, m: (p, 1 - m))(*conv(*a)))
    assert flipped[F.METHODS[2]] < 0.3 and flipped[F.METHODS[3]] == out[F.METHODS[3]]


def test_recorded_benchmark_has_five_seeds_and_matches_a_rerun_of_one_cell(prefs):
    res = json.loads((REPO / "bench" / "results" / "hw3_feedback_spectrum.json").read_text())
    assert {"commit", "date", "load", "machine"} <= set(res["meta"])
    assert res["settings"]["seeds"] == [0, 1, 2, 3, 4]
    curve = res["budget_curves"]["five annotators, offsets, scales, drift 2"]
    assert all(np.shape(curve[m]["per_seed"]) == (5, 6) for m in F.METHODS)
    bench = _bench()
    X = F.segment_features(prefs)
    again = F.run_budget(prefs, X, bench.CURVE_PANELS["five annotators, offsets, scales, drift 2"], 640, 3,
                         to_comparisons=bench.ratings_to_comparisons)
    for m in F.METHODS:
        assert abs(curve[m]["per_seed"][3][4] - again[m]) < 1e-3, m
    sweep = res["drift_sweep"]["one annotator"]
    assert np.shape(sweep["comparisons"]["per_seed"]) == (5, 5)


def test_retest_and_agreement_helpers():
    assert F.retest_correlation([1, 2, 3], [2, 4, 6]) == pytest.approx(1.0)
    assert np.isnan(F.retest_correlation([5, 5, 5], [1, 2, 3]))
    pairs, mu = np.array([[7, 9], [9, 8], [7, 8]]), np.array([1.0, 0.0, 0.5])
    clips, ratings = np.array([7, 8, 9]), np.array([6.0, 6.0, 2.0])
    # (7 > 9): ratings 6 > 2 agree; (9 < 8): ratings 2 < 6 agree; the tie is left out
    assert F.rating_comparison_agreement(pairs, mu, clips, ratings) == 1.0
    assert F.rating_comparison_agreement(pairs, 1 - mu, clips, ratings) == 0.0
    assert F.rating_comparison_agreement(np.array([[7, 8]]), np.array([1.0]), clips, ratings) == 0.5


def test_widget_rating_phase_runs_headless_and_reports_consistency():
    widgets = pytest.importorskip("ipywidgets")
    from rlcourse.widgets import PreferenceAnnotator

    def render(segment):
        return np.zeros((2, 8, 8, 3), dtype=np.uint8)

    seen = {}

    def rate(pairs, labels, clips, first, second):
        seen.update(pairs=pairs, labels=labels, clips=clips, first=first, second=second)
        return f"retest {F.retest_correlation(first, second):.2f}"

    obs = np.zeros((6, 3, 11), dtype=np.float32)
    ann = PreferenceAnnotator(obs, np.array([[0, 1], [2, 0]]), lambda p, m: "model", lambda model, m: "trained",
                              render=render, rate=rate, seed=3)
    box = ann.start()
    assert isinstance(box, widgets.VBox) and ann.scale_box.layout.display == "none"
    left, tie, right = ann.buttons
    left.click(); right.click()
    assert ann.labels == [1.0, 0.0]
    assert ann.choice_box.layout.display == "none" and ann.scale_box.layout.display is None
    assert "trained" in "".join(o.get("text", "") for o in ann.output.outputs)
    assert ann.status.value.startswith("clip 1 of 6")
    assert list(ann.clips) == [0, 1, 2]
    order = ann.rating_order
    assert sorted(order[:3]) == [0, 1, 2] and sorted(order[3:]) == [0, 1, 2]
    values = [3, 7, 9, 4, 7, 9]
    for v in values:
        ann.scale_buttons[v - 1].click()
    first, second = np.zeros(3), np.zeros(3)
    first[order[:3]], second[order[3:]] = values[:3], values[3:]
    assert np.array_equal(seen["first"], first) and np.array_equal(seen["second"], second)
    assert ann.status.value == f"retest {F.retest_correlation(first, second):.2f}"


def test_widget_without_rate_keeps_its_old_behaviour():
    pytest.importorskip("ipywidgets")
    from rlcourse.widgets import PreferenceAnnotator

    ann = PreferenceAnnotator(np.zeros((2, 3, 11), np.float32), np.array([[0, 1]]), lambda p, m: "m",
                              lambda model, m: "done", render=lambda s: np.zeros((2, 8, 8, 3), np.uint8))
    ann.start()
    ann.buttons[0].click()
    assert ann.status.value == "done" and ann.scale_box.layout.display == "none"
