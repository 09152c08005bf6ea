"""The class report (autograder/outputs/class_report.py): its figures against a plain computation.

A synthetic class (results made here, no grading) checks the arithmetic and the escaping; one slow test grades
a small hw0_setup class once (samples, wrong variants of the solution, an unreadable file) and recomputes every
figure from ``gradebook.csv``, the ``result.json`` files and the submitted notebooks, with numpy.corrcoef.
"""
from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import nbformat
import numpy as np
import pytest

from autograder.outputs.batch_output import read_results
from autograder.outputs.class_report import (REPORT_DIR, analyse, class_table, html_page, item_rest_correlation,
                                             markdown, write_class_report)
from autograder.outputs.text import markdown_text
from autograder.core.results import GRADED, GRADER_ERROR, UNGRADABLE, GradeResult, Reason, StubResult
from autograder.core.results import TestOutcome as Outcome
from conftest import REPO, with_cells

NOT_DONE = "not implemented yet: the stub still raises NotImplementedError"


def result(name: str, passed: dict[str, list[bool]], status: str = GRADED, message: str = "wrong value",
           reason: Reason = Reason.WRONG) -> GradeResult:
    """A result with stubs ``a`` (tests of 2, 1 points) and ``b`` (one test of 3 points): True passes, a
    failure has ``message`` and ``reason``."""
    points = {"a": [2.0, 1.0], "b": [3.0]}
    stubs = [StubResult(stub, [Outcome(f"{stub} test {i}", stub, p, ok, "" if ok else message, f"hint {stub}{i}",
                                       reason=Reason.PASSED if ok else reason)
                               for i, (p, ok) in enumerate(zip(points[stub], passed[stub]))])
             for stub in passed]
    return GradeResult("hw0_setup", name, stubs, [], [], None if status == GRADED else "unreadable", status=status)


def synthetic_class() -> dict[str, GradeResult]:
    return {"s1": result("s1", {"a": [True, True], "b": [True]}),
            "s2": result("s2", {"a": [True, False], "b": [False]}),
            "s3": result("s3", {"a": [False, False], "b": [True]}),
            "s4": result("s4", {"a": [True, True], "b": [False]}),
            "s5": result("s5", {"a": [False, False], "b": [False]}, message=NOT_DONE, reason=Reason.NOT_IMPLEMENTED),
            "s6": result("s6", {"a": [False, False], "b": [False]}, status=UNGRADABLE, message="unreadable",
                         reason=Reason.LOST),
            "s7": result("s7", {}, status=GRADER_ERROR)}


def test_item_rest_correlation_is_pearson_of_item_and_total_minus_item_and_undefined_without_spread():
    rng = np.random.default_rng(0)
    scores = rng.integers(0, 4, size=(30, 5)).astype(float)
    scores[:, 3] = 2.0  # everyone the same on item 3
    totals = scores.sum(axis=1)
    got = item_rest_correlation(scores, totals)
    for j in (0, 1, 2, 4):
        assert got[j] == pytest.approx(np.corrcoef(scores[:, j], totals - scores[:, j])[0, 1], abs=1e-12)
    assert np.isnan(got[3])
    assert np.isnan(item_rest_correlation(scores[:, :1], scores[:, 0])[0])  # the rest is 0 for everyone
    assert np.isnan(item_rest_correlation(scores[:1], totals[:1])).all()  # one submission: no correlation


def test_synthetic_class_figures_grader_errors_left_out_ungradable_at_zero():
    report = analyse("hw0_setup", synthetic_class())
    assert report.table.names == ["s1", "s2", "s3", "s4", "s5", "s6"]
    assert report.table.totals.tolist() == [6, 2, 3, 3, 0, 0] and report.table.max_total == 6
    a, b = report.stub_items
    assert (a.stub, a.max_points, a.attempted, b.attempted) == ("a", 3, 4, 4)  # s5 wrote neither, s6 is junk
    assert a.mean == pytest.approx(np.mean([3, 2, 0, 3, 0, 0])) and a.full_marks == pytest.approx(2 / 6)
    item_a = np.array([3, 2, 0, 3, 0, 0.0])
    assert a.discrimination == pytest.approx(np.corrcoef(item_a, report.table.totals - item_a)[0, 1])
    first = report.test_items[0]
    assert (first.stub, first.test, first.max_points, first.mean) == ("a", "a test 0", 2, pytest.approx(6 / 6))
    assert report.stats["median"] == pytest.approx(2.5) and report.counts.sum() == 6 and report.counts[-1] == 1
    # failures are counted among those who attempted: s5's "not implemented" is not a failure of the test
    assert [(f.stub, f.test, f.count) for f in report.top_failures] == [
        ("a", "a test 1", 2), ("b", "b test 0", 2), ("a", "a test 0", 1)]
    assert report.messages == [("a", "wrong value", 2), ("b", "wrong value", 2)]  # once per submission and stub


def test_a_tests_rest_leaves_out_its_whole_stub_and_grader_errors_are_named():
    """Sibling tests of one stub pass and fail together: counting them in the rest would make every test of a
    stub look discriminating (issue 36: 0.73 where the stub showed 0.07)."""
    report = analyse("hw0_setup", synthetic_class())
    t = report.table
    for item, j in zip(report.test_items, range(len(t.tests))):
        stub = t.stub_scores[:, t.stubs.index(item.stub)]
        rest = t.totals - stub
        assert item.discrimination == pytest.approx(np.corrcoef(t.test_scores[:, j], rest)[0, 1])
        if item.stub == "a":  # two tests: the old rest (total minus the test alone) gives another figure
            minus_test = np.corrcoef(t.test_scores[:, j], t.totals - t.test_scores[:, j])[0, 1]
            assert abs(item.discrimination - minus_test) > 0.05
    assert t.grader_errors == ["s7"]
    assert "where the grader failed are left out" in markdown(report, {"totals": "t.png", "stubs": "s.png"})
    assert "s7" in markdown(report, {"totals": "t.png", "stubs": "s.png"}).split("\n")[2]


def test_written_answers_from_the_gradebook_are_items_and_in_the_totals():
    written = {"s1": {"q": (2.0, True)}, "s2": {"q": (0.5, True)}, "s3": {"q": (None, True)},  # s3 waits
               "s4": {"q": (1.0, True)}, "s5": {"q": (0.0, False)}, "s6": {"q": (0.0, False)}}
    report = analyse("hw0_setup", synthetic_class(), written, {"q": 2.0})
    t = report.table
    assert t.totals.tolist() == [8, 2.5, 3, 4, 0, 0] and t.max_total == 8
    q = report.stub_items[-1]
    assert (q.stub, q.max_points, q.attempted) == ("written: q", 2.0, 4)
    graded = np.array([2.0, 0.5, 1.0, 0.0, 0.0])  # s3 left out: not graded yet
    assert q.mean == pytest.approx(graded.mean()) and q.full_marks == pytest.approx(1 / 5)
    rest = np.array([8, 2.5, 4, 0, 0]) - graded
    assert q.discrimination == pytest.approx(np.corrcoef(graded, rest)[0, 1])
    a = report.stub_items[0]
    assert a.discrimination == pytest.approx(np.corrcoef(t.stub_scores[:, 0], t.totals - t.stub_scores[:, 0])[0, 1])
    assert "1 not graded yet" in markdown(report, {"totals": "t.png", "stubs": "s.png"})


def test_pages_escape_student_text_inline_the_plots_and_run_no_script(tmp_path):
    hostile = "<script>alert(1)</script> [x](http://evil) ![i](http://evil/p.png) | col"
    results = synthetic_class()
    results["s2"] = result("s2", {"a": [True, False], "b": [False]}, message=hostile)
    report = analyse("hw0_setup", results)
    page = html_page(report, {"totals": b"\x89PNG fake", "stubs": b"\x89PNG fake"})
    assert "<script" not in page and "http://evil" in page and "&lt;script&gt;" in page
    assert page.count("src='data:image/png;base64,") == 2 and "src='http" not in page
    md = markdown(report, {"totals": "totals.png", "stubs": "stubs.png"})
    line = next(line for line in md.splitlines() if "alert" in line)
    assert markdown_text(hostile) in line and "](http" not in line and "<script" not in line.replace("\\<script", "")
    assert "Not computed" in md  # no submissions folder given: no similarity section figures


def _gradebook(path: Path) -> tuple[list[str], list[str], np.ndarray, np.ndarray]:
    """Names, stub columns, the stub scores and the totals of the rows with a score, read plainly from the CSV."""
    rows = [r for r in csv.DictReader(path.open()) if r["score"] != ""]
    stubs = [c for c in rows[0] if c not in ("submission", "score", "max_score", "percent", "status", "reason")]
    return ([r["submission"] for r in rows], stubs, np.array([[float(r[s]) for s in stubs] for r in rows]),
            np.array([float(r["score"]) for r in rows]))


WRONG = {  # wrong variants of the hw0 solution, each a whole stub cell
    "no_discount": {"discounted_returns": (
        "def discounted_returns(rewards, gamma):\n"
        "    r = np.asarray(rewards, dtype=float)\n"
        "    return np.cumsum(r[:, ::-1], axis=-1)[:, ::-1]\n")},
    "keeps_the_tail": {"episode_returns": (
        "def episode_returns(rewards, dones):\n"
        "    out, total = [], 0.0\n"
        "    for r, d in zip(rewards, dones):\n"
        "        total += r\n"
        "        if d:\n"
        "            out.append(total)\n"
        "            total = 0.0\n"
        "    return np.array(out + [total])\n")},
}


@pytest.fixture(scope="module")
def graded_class():
    """A small hw0_setup class graded once: samples (not the 20-second infinite loop), wrong variants, junk."""
    root = Path(tempfile.mkdtemp(prefix="rlcourse-class-", dir="/tmp"))
    folder, out = root / "in", root / "out"
    folder.mkdir()
    samples = REPO / "autograder" / "samples" / "hw0_setup"
    for kind in ("complete", "partial", "untouched", "broken_syntax"):  # not "cheating": 8 s of its own
        shutil.copy(samples / f"{kind}.ipynb", folder / f"{kind}.ipynb")
    for name, cells in WRONG.items():
        with_cells(samples / "complete.ipynb", folder / f"{name}.ipynb", cells)
    (folder / "not_json.ipynb").write_text("this is not a notebook")
    for path in [root, *root.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o644)
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    yield folder, out
    shutil.rmtree(root, ignore_errors=True)


@pytest.mark.slow
def test_report_of_a_graded_class_equals_a_plain_computation(graded_class):
    folder, out = graded_class
    from autograder.__main__ import main

    gradebook = (out / "gradebook.csv").read_bytes()
    assert main(["class-report", "hw0_setup", str(folder), "--results", str(out), "--names"]) == 0
    assert (out / "gradebook.csv").read_bytes() == gradebook
    report = analyse("hw0_setup", read_results(out))
    names, stubs, scores, totals = _gradebook(out / "gradebook.csv")
    assert report.table.names == names and report.table.stubs == stubs and "not_json" in names
    assert np.array_equal(report.table.totals, totals)
    assert report.table.max_total == float(next(csv.DictReader((out / "gradebook.csv").open()))["max_score"])
    tests, points = _test_scores(out, names)
    for j, item in enumerate(report.stub_items):
        column, rest = scores[:, j], totals - scores[:, j]
        stub_max = sum(p for (stub, _), p in points.items() if stub == item.stub)
        assert item.max_points == stub_max
        assert item.mean == pytest.approx(column.mean())
        assert item.full_marks == pytest.approx(np.mean(column == stub_max))
        assert item.discrimination == pytest.approx(np.corrcoef(column, rest)[0, 1])
        assert item.attempted == sum(_attempted_in_notebook(folder / f"{n}.ipynb", item.stub) for n in names)
    assert [i.attempted for i in report.stub_items] == [5, 4]  # by hand: untouched and not_json attempt neither,
    # partial only discounted_returns
    for item in report.test_items:
        column = tests[(item.stub, item.test)]
        assert item.mean == pytest.approx(column.mean())
        assert item.full_marks == pytest.approx(np.mean(column == item.max_points))
        rest = totals - scores[:, stubs.index(item.stub)]  # the rest leaves out the test's whole stub
        expected = np.corrcoef(column, rest)[0, 1] if column.std() and rest.std() else None
        assert item.discrimination == (pytest.approx(expected) if expected is not None else None)
    md = (out / REPORT_DIR / "report.md").read_text()
    assert (out / REPORT_DIR / "totals.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / REPORT_DIR / "stubs.png").read_bytes()[:4] == b"\x89PNG"
    assert f"{len(names)} submissions with a score" in md
    similar = md[md.index("## Similar stub code"):]
    assert "never changes a grade" in similar and markdown_text("Not compared (1): not_json") in similar
    assert "| complete | no\\_discount |" in similar  # the wrong variant is the complete sample with one cell changed
    assert "data:image/png;base64," in (out / REPORT_DIR / "report.html").read_text()


@pytest.mark.slow
def test_report_after_a_regrade_reads_the_current_results_only(graded_class, tmp_path):
    """A regrade archives earlier results in DIR/_previous/: the report counts each submission once."""
    folder, out = graded_class
    archived = out / "_previous" / "20260101T000000Z" / "complete"
    shutil.copytree(out / "complete", archived)
    try:
        report = write_class_report("hw0_setup", out, tmp_path / "report")
    finally:
        shutil.rmtree(out / "_previous")
    assert report.table.names.count("complete") == 1
    assert len(report.table.names) == len(_gradebook(out / "gradebook.csv")[0])


def _attempted_in_notebook(path: Path, stub: str) -> bool:
    """Plainly: the stub's cell exists and no longer raises NotImplementedError (junk files attempt nothing)."""
    try:
        nb = nbformat.read(str(path), as_version=4)
    except Exception:  # noqa: BLE001 (the test's own reading of a junk file)
        return False
    cells = [c.source for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == stub]
    return bool(cells) and "raise NotImplementedError" not in cells[-1]


def _test_scores(out: Path, names: list[str]) -> tuple[dict[tuple[str, str], np.ndarray], dict[tuple[str, str], float]]:
    """Per hidden test, the points each submission earned (0 where absent) and its points, from the result.json
    files."""
    earned: dict[tuple[str, str], dict[str, float]] = {}
    points: dict[tuple[str, str], float] = {}
    for name in names:
        data = json.loads((out / name / "result.json").read_text())
        for stub in data["stubs"]:
            for t in stub["tests"]:
                earned.setdefault((t["stub"], t["name"]), {})[name] = t["points"] if t["passed"] else 0.0
                points[(t["stub"], t["name"])] = t["points"]
    return {key: np.array([per.get(n, 0.0) for n in names]) for key, per in earned.items()}, points


def test_a_class_with_no_score_is_empty_and_its_figures_undefined():
    table = class_table({"s7": result("s7", {}, status=GRADER_ERROR)})
    assert table.names == [] and table.totals.size == 0
    report = analyse("hw0_setup", {"s7": result("s7", {}, status=GRADER_ERROR)})
    assert report.stub_items == [] and report.stats == {"submissions": 0.0} and report.counts.sum() == 0


def test_results_of_two_suite_versions_are_reported_with_a_warning():
    results = synthetic_class()
    for name, result_ in results.items():
        result_.suite_version = "v2" if name == "s1" else "v1"  # s1 regraded after the suite changed
    assert "2 versions of the hidden suite" in markdown(analyse("hw0_setup", results), {"totals": "", "stubs": ""})
    for result_ in results.values():
        result_.suite_version = "v1"
    assert "versions of the hidden suite" not in markdown(analyse("hw0_setup", results), {"totals": "", "stubs": ""})


def test_attempts_are_read_from_the_recorded_reason_never_from_the_words():
    """Rewording the feedback cannot change the item analysis: a stub was attempted unless every test of it
    failed as not implemented or missing."""
    reworded = {"s1": result("s1", {"a": [False, False], "b": [False]}, message="not implemented yet (reworded)",
                             reason=Reason.WRONG),
                "s2": result("s2", {"a": [False, False], "b": [False]}, message="some new wording",
                             reason=Reason.NOT_IMPLEMENTED),
                "s3": result("s3", {"a": [False, False], "b": [False]}, message="", reason=Reason.MISSING)}
    table = class_table(reworded)
    assert table.attempted.tolist() == [[True, True], [False, False], [False, False]]
