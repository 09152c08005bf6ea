"""The grader's own peak memory and wall time stay bounded whatever a submission holds or does.

Measured by ``bench/bench_grader_limits.py`` (each submission graded alone in a fresh grading process):
here over the corpus cases that aim at the grader itself rather than at the score.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
HEAVY = ["reply_that_inflates", "many_maximal_blobs", "huge_return_value", "worker_stops_reading",
         "calls_back_for_ever", "output_flood", "json_that_inflates", "very_long_expression", "forge_the_outputs",
         "recursion_and_deep_nesting"]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_grader_limits", REPO / "bench" / "bench_grader_limits.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_grader_memory_and_time_stay_bounded_on_hostile_submissions():
    bench = _bench()
    rows = {r["submission"]: r for r in bench.measure(HEAVY)}
    assert set(HEAVY) <= set(rows), set(HEAVY) - set(rows)
    for name in HEAVY:
        row = rows[name]
        assert row["status"] in ("graded", "ungradable"), (name, row)
        assert row["within_memory"], f"{name}: the grader peaked at {row['memory_ratio']:.2f}x the untouched notebook's memory"
        assert row["within_time"], f"{name}: grading took {row['seconds']} s, over {bench.wall_bound():.0f} s"
        assert not row["score"], f"{name} scored {row['score']}"
    # each attack reached the grader (a case that failed for another reason would prove nothing)
    for name, why in {"reply_that_inflates": "header of 240000040 bytes is over the limit",
                      "many_maximal_blobs": "over the limit", "huge_return_value": "over the limit",
                      "worker_stops_reading": "timed out",
                      "json_that_inflates": "needs more than"}.items():
        assert why in rows[name]["why"], (name, rows[name]["why"])
    # a stand-in called for ever: the call budget (reference_calls) or the deadline, whichever comes first
    assert any(why in rows["calls_back_for_ever"]["why"] for why in ("the grader answers no more", "timed out")), \
        rows["calls_back_for_ever"]["why"]
