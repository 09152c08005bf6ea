"""Every results file's ``meta`` comes from one function (``bench/run_record.py``), so the pages can read it."""
from __future__ import annotations

import re

from conftest import REPO

from bench.run_record import meta


def test_meta_names_the_code_the_time_and_the_load():
    record = meta()
    assert {"commit", "uncommitted_files", "date", "load", "machine", "python"} <= set(record)
    assert re.fullmatch(r"[0-9a-f]{7,}|unknown", record["commit"])
    assert len(record["load"]) == 3 and record["machine"].endswith("-core CPU")


def test_meta_names_the_commit_a_paired_run_was_built_from(monkeypatch):
    monkeypatch.setenv("BENCH_COMMIT", "abc1234")
    assert meta()["commit"] == "abc1234" and meta()["uncommitted_files"] == 0


def test_no_bench_script_writes_a_meta_of_its_own():
    own = [p.name for p in (REPO / "bench").glob("*.py") if p.name != "run_record.py"
           and "rev-parse" in p.read_text()]
    assert not own, f"these benches build their own meta instead of bench.run_record.meta: {own}"


def test_make_tests_two_pytest_runs_are_read_apart():
    """``make test`` runs pytest twice (the parallel part, then the serial tests): both summaries and times count."""
    from bench.bench_test_fast import pytest_runs

    output = ("....\n12.51s call     tests/test_x.py::test_y\n"
              "880 passed, 2 skipped, 9 deselected in 512.3s (0:08:32)\n"
              "=========== 9 passed, 909 deselected in 80.1s (0:01:20) ===========\n")
    runs = pytest_runs(output)
    assert [r["seconds"] for r in runs] == [512.3, 80.1]
    assert runs[0]["counts"] == {"passed": 880, "skipped": 2, "deselected": 9}
    assert runs[1]["summary_line"] == "9 passed, 909 deselected in 80.1s (0:01:20)"
