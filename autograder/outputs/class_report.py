"""The class report of one assignment, from what ``batch`` (or a regrade) wrote: item analysis and similar code.

``python -m autograder class-report ID [FOLDER] --results DIR`` writes ``DIR/_class_report/``:
``report.md`` (beside its two PNGs), ``report.html`` (one self-contained page: the plots inlined as
data URIs, no script, every piece of student text escaped) and, when the submissions ``FOLDER`` is
given, ``similarity/pair-NNN.html``, one side-by-side page per flagged pair.

Items are the stubs and each stub's hidden tests. Over the N submissions with a score (graded or
ungradable, the latter at zero everywhere, as in ``gradebook.csv``; grader errors have no score and
are left out), each item gets:

- attempted: graded submissions whose stub was there and no longer raised ``NotImplementedError`` (an
  ungradable one attempted nothing the grader could see);
- mean score and the fraction with full marks, over all N;
- discrimination: the Pearson correlation of the item's score with the rest of the score (the
  total minus the item; for a hidden test, the total minus its whole stub, so that the stub's
  other tests, which pass and fail with it, do not count as the "rest"). When the item or the rest
  takes one value across the class the correlation is undefined, and the report says "n/a" rather
  than inventing a 0.

When the batch was recorded in the course's nbgrader gradebook (``nbgrader-sync``) and the course is
given (``--course``, default this repository), each written answer is an item too, with the score a
person gave in formgrader: the totals are then the automatic score plus the written one, an answer
not graded yet counts 0 in the totals and is left out of its own item's figures (the report says
how many wait). A stub score a person changed in formgrader counts in the totals too, as in
``export`` (the report names them); the stub and test items stay the hidden tests' scores.

Grader errors are counted and named in the report's first paragraph. Names in the similarity part
(its tables, pages and ``similarity.csv``) are pseudonyms by default, as formgrader's grading pages
start with names hidden (``Submission #N``; nbgrader has no setting for it): ``anon-`` and a keyed
digest of the name, the same in every report of the batch; the key to them is
``DIR/_pseudonyms.csv``, outside the report folder, so the folder can be shared as it is.
``--names`` shows the submissions' names instead.
"""
from __future__ import annotations

import base64
import csv
import hashlib
import hmac
import html
import io
import secrets
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autograder.outputs.batch_output import read_results
from autograder.outputs.similarity import (NEVER_A_GRADE, Pair, StubCode, pair_page, read_stub_code, release_code,
                                           similar_pairs, THRESHOLD)
from autograder.core.store import atomic_write
from autograder.outputs.text import cap, csv_cell, listed, markdown_text, plain
from autograder.core.results import GRADED, GradeResult

REPORT_DIR = "_class_report"
"""The report's folder inside the batch folder (a name no submission's safe name takes; see batch_output)."""
TOP_FAILURES = 10
MESSAGE_SHOWN = 160
"""A failure message is counted and shown by its first line, cut here (it may quote a student's exception)."""
CLOSEST_SHOWN = 5
MAX_PAGES = 200
"""Side-by-side pages are written for the most similar flagged pairs up to this many (a class that shares one
solution flags thousands of pairs, and thousands of pages help no one)."""


@dataclass
class Item:
    """One stub, or one hidden test of a stub (``test`` set), and its figures over the class."""

    stub: str
    test: str | None
    max_points: float
    attempted: int
    mean: float
    full_marks: float
    discrimination: float | None


@dataclass
class Failure:
    stub: str
    test: str
    hint: str
    count: int


@dataclass
class ClassTable:
    """The scores of the class as arrays: one row per submission with a score, one column per item."""

    names: list[str]
    totals: np.ndarray
    max_total: float
    stubs: list[str]
    stub_scores: np.ndarray
    stub_max: np.ndarray
    tests: list[tuple[str, str]]
    test_scores: np.ndarray
    test_max: np.ndarray
    attempted: np.ndarray
    """(N, stubs) bools."""
    statuses: Counter = field(default_factory=Counter)
    suite_versions: set[str] = field(default_factory=set)
    """The versions of the suite that graded the scored results, where recorded."""
    grader_errors: list[str] = field(default_factory=list)
    """The submissions with no score because the grader failed on them."""
    written: list[str] = field(default_factory=list)
    """The written answers (from the gradebook), when the batch was synced."""
    written_scores: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(N, written) scores a person gave; NaN where not graded yet."""
    written_max: np.ndarray = field(default_factory=lambda: np.zeros(0))
    written_answered: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    hand_stubs: dict[str, dict[str, tuple[float | None, float]]] = field(default_factory=dict)
    """Stub scores a person changed in formgrader, per submission: in the totals (as in ``export``), not in the
    stub and test items (those are the hidden tests')."""


def _attempted(stub_tests: list) -> bool:
    """Whether any of a stub's tests shows an attempt (its recorded :class:`Reason`, never its message)."""
    return any(t.reason.attempted for t in stub_tests)


WrittenGrades = dict[str, dict[str, tuple[float | None, bool]]]
"""Per submission, per written answer: (the score given, or None while it waits; whether it was answered)."""


def class_table(results: dict[str, GradeResult], written: WrittenGrades | None = None,
                written_max: dict[str, float] | None = None,
                hand_stubs: dict[str, dict[str, tuple[float | None, float]]] | None = None) -> ClassTable:
    """Arrange the results of a batch folder by submission and item (a missing stub or test scores 0); with
    ``written`` (from the gradebook), the written answers as items too and in the totals; with ``hand_stubs``,
    the stub scores a person changed in formgrader in the totals (the gradebook's and ``export``'s)."""
    from autograder.outputs.gradebook import hand_stub_delta

    scored = {n: r for n, r in sorted(results.items()) if r.has_score}
    stubs = list(dict.fromkeys(s.name for r in scored.values() for s in r.stubs))
    tests = list(dict.fromkeys((t.stub, t.name) for r in scored.values() for s in r.stubs for t in s.tests))
    test_max = {key: 0.0 for key in tests}
    for r in scored.values():
        for s in r.stubs:
            for t in s.tests:
                test_max[(t.stub, t.name)] = max(test_max[(t.stub, t.name)], t.points)
    n = len(scored)
    stub_scores, attempted = np.zeros((n, len(stubs))), np.zeros((n, len(stubs)), dtype=bool)
    test_scores = np.zeros((n, len(tests)))
    stub_col, test_col = {s: j for j, s in enumerate(stubs)}, {k: j for j, k in enumerate(tests)}
    for i, r in enumerate(scored.values()):
        for s in r.stubs:
            stub_scores[i, stub_col[s.name]] = s.score
            attempted[i, stub_col[s.name]] = r.status == GRADED and _attempted(s.tests)
            for t in s.tests:
                test_scores[i, test_col[(t.stub, t.name)]] = t.points if t.passed else 0.0
    test_max_arr = np.array([test_max[k] for k in tests])
    stub_max = np.array([sum(test_max[k] for k in tests if k[0] == s) for s in stubs])
    written, written_max = written or {}, written_max or {}
    answers = list(written_max)
    given = np.full((n, len(answers)), np.nan)
    answered = np.zeros((n, len(answers)), dtype=bool)
    for i, name in enumerate(scored):
        for j, gid in enumerate(answers):
            score, was_answered = written.get(name, {}).get(gid, (0.0, False))
            given[i, j] = np.nan if score is None else score
            answered[i, j] = was_answered
    hand_stubs = {name: h for name, h in (hand_stubs or {}).items() if name in scored and h}
    by_hand = np.array([hand_stub_delta({s.name: s.score for s in r.stubs}, hand_stubs.get(name, {}))
                        for name, r in scored.items()]) if n else np.zeros(0)
    totals = np.array([r.score for r in scored.values()]) + np.nan_to_num(given).sum(axis=1) + by_hand
    maxima = np.array([written_max[g] for g in answers])
    return ClassTable(list(scored), totals, float(stub_max.sum() + maxima.sum()), stubs,
                      stub_scores, stub_max, tests, test_scores, test_max_arr, attempted,
                      Counter(r.status for r in results.values()),
                      {v for r in scored.values() if (v := getattr(r, "suite_version", ""))},
                      sorted(n for n, r in results.items() if not r.has_score), answers, given, maxima, answered,
                      hand_stubs)


def item_rest_correlation(scores: np.ndarray, totals: np.ndarray, parts: np.ndarray | None = None) -> np.ndarray:
    """Per column of ``scores`` (N, M), Pearson's r between the item and ``totals`` minus ``parts`` (default: minus
    the item itself; for a test, its whole stub); NaN where the item or the rest is constant over the class (no
    spread, no correlation), or fewer than two submissions."""
    scores = np.asarray(scores, dtype=float)
    if len(totals) < 2:
        return np.full(scores.shape[1], np.nan)
    rest = np.asarray(totals, dtype=float)[:, None] - (scores if parts is None else np.asarray(parts, dtype=float))
    constant = (np.ptp(scores, axis=0) == 0) | (np.ptp(rest, axis=0) == 0)
    x, y = scores - scores.mean(axis=0), rest - rest.mean(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (x * y).sum(axis=0) / np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
    return np.where(constant, np.nan, np.clip(r, -1.0, 1.0))


WRITTEN = "written: "
"""The label of a written answer's row among the stubs."""


def items(table: ClassTable) -> tuple[list[Item], list[Item]]:
    """The figures of each stub (then each written answer, if any) and of each hidden test (see the module)."""
    def figures(scores: np.ndarray, maxima: np.ndarray, attempted: np.ndarray, keys: list[tuple[str, str | None]],
                parts: np.ndarray | None = None):
        n = len(table.names)
        means = scores.mean(axis=0) if n else np.zeros(len(keys))
        full = (scores >= maxima[None, :]).mean(axis=0) if n else np.zeros(len(keys))
        disc = item_rest_correlation(scores, table.totals, parts)
        return [Item(stub, test, float(m), int(a), float(mu), float(f), None if np.isnan(d) else float(d))
                for (stub, test), m, a, mu, f, d in zip(keys, maxima, attempted, means, full, disc)]

    col = {s: j for j, s in enumerate(table.stubs)}
    stub_items = figures(table.stub_scores, table.stub_max, table.attempted.sum(axis=0),
                         [(s, None) for s in table.stubs])
    test_attempted = np.array([table.attempted[:, col[s]].sum() for s, _ in table.tests], dtype=int)
    whole_stub = table.stub_scores[:, [col[s] for s, _ in table.tests]] if table.tests else None
    test_items = figures(table.test_scores, table.test_max, test_attempted, list(table.tests), whole_stub)
    return stub_items + written_items(table), test_items


def written_items(table: ClassTable) -> list[Item]:
    """Each written answer's figures over the submissions a person has graded it for (NaN: not graded yet)."""
    out = []
    for j, gid in enumerate(table.written):
        scores, maximum = table.written_scores[:, j], float(table.written_max[j])
        graded = ~np.isnan(scores)
        g = scores[graded]
        disc = item_rest_correlation(g[:, None], table.totals[graded])[0] if graded.sum() else np.nan
        out.append(Item(WRITTEN + gid, None, maximum, int(table.written_answered[:, j].sum()),
                        float(g.mean()) if len(g) else 0.0, float((g >= maximum).mean()) if len(g) else 0.0,
                        None if np.isnan(disc) else float(disc)))
    return out


def written_from_gradebook(assignment: str, results_dir: Path, course_root: Path | None = None
                           ) -> tuple[WrittenGrades, dict[str, float]]:
    """Per synced submission, its written answers' scores in the course's gradebook (None while one waits), and
    each answer's points; empty when the batch was never synced."""
    from autograder.outputs.gradebook import synced_grades

    out: WrittenGrades = {}
    maxima: dict[str, float] = {}
    for name, grades in synced_grades(assignment, results_dir, course_root):
        per = {}
        for g in grades:
            if g.cell_type == "code":
                continue
            maxima[g.name] = float(g.max_score)
            waiting = g.manual_score is None and g.auto_score is None
            unanswered = g.manual_score is None and g.auto_score is not None and not g.needs_manual_grade
            per[g.name] = (None if waiting else float(g.score), not unanswered)
        out[name] = per
    return out, maxima


def failures(results: dict[str, GradeResult]) -> tuple[list[Failure], list[tuple[str, str, int]]]:
    """The hidden tests failed most often by those who attempted the stub (with the test's hint), and the
    failure messages met most often (first line, counted once per submission and stub), each with its count."""
    by_test: Counter = Counter()
    hints: dict[tuple[str, str], str] = {}
    messages: Counter = Counter()
    for r in results.values():
        if r.status != GRADED:  # an ungradable one failed every test for one reason, listed in its feedback
            continue
        for s in r.stubs:
            if not _attempted(s.tests):
                continue
            seen = set()
            for t in s.tests:
                if not t.passed:
                    by_test[(t.stub, t.name)] += 1
                    hints[(t.stub, t.name)] = t.hint or ""
                    seen.add((t.stub, cap((t.message.strip().splitlines() or ["(no message)"])[0], MESSAGE_SHOWN)))
            messages.update(seen)  # a message counts once per submission and stub, however many tests it failed
    ordered = sorted(by_test.items(), key=lambda kv: (-kv[1], kv[0]))[:TOP_FAILURES]
    top = [Failure(stub, test, hints[(stub, test)], count) for (stub, test), count in ordered]
    common = [(stub, msg, c) for (stub, msg), c in sorted(messages.items(), key=lambda kv: (-kv[1], kv[0]))]
    return top, common[:TOP_FAILURES]


def distribution(table: ClassTable, bands: int = 10) -> tuple[dict[str, float], np.ndarray, np.ndarray]:
    """Summary statistics of the totals, and the count per band of the percentage (``bands`` equal bands,
    the last one closed: a full score falls in 90-100)."""
    t = table.totals
    stats = {"submissions": float(len(t))}
    if len(t):
        q1, median, q3 = np.percentile(t, [25, 50, 75])
        stats.update(mean=float(t.mean()), std=float(t.std()), min=float(t.min()), q1=float(q1),
                     median=float(median), q3=float(q3), max=float(t.max()))
    edges = np.linspace(0, 100, bands + 1)
    percent = 100 * t / table.max_total if table.max_total else np.zeros_like(t)
    counts, _ = np.histogram(percent, bins=edges)
    return stats, edges, counts


# ------------------------------------------------------------------ plots


def _png(fig) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    buffer = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buffer)
    return buffer.getvalue()


def totals_plot(table: ClassTable, edges: np.ndarray, counts: np.ndarray, assignment: str) -> bytes:
    """A histogram of the totals, in percent of the maximum (PNG bytes, drawn off-screen with Agg)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3.2), dpi=100)
    ax = fig.add_subplot()
    ax.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="#4c72b0", edgecolor="white")
    ax.set(xlabel="total score (% of maximum)", ylabel="submissions", xlim=(0, 100),
           title=f"{assignment}: totals of {len(table.names)} submissions")
    ax.yaxis.get_major_locator().set_params(integer=True)
    fig.tight_layout()
    return _png(fig)


def stubs_plot(stub_items: list[Item], assignment: str) -> bytes:
    """A bar per stub: mean score as a fraction of its points, and the fraction with full marks."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(4.0, 1.1 * len(stub_items) + 2), 3.6), dpi=100)
    ax = fig.add_subplot()
    x = np.arange(len(stub_items))
    mean = [i.mean / i.max_points if i.max_points else 0.0 for i in stub_items]
    ax.bar(x - 0.2, mean, width=0.4, label="mean score / points", color="#4c72b0")
    ax.bar(x + 0.2, [i.full_marks for i in stub_items], width=0.4, label="full marks", color="#55a868")
    ax.set_xticks(x, [i.stub for i in stub_items], rotation=30, ha="right")
    ax.set(ylim=(0, 1.05), ylabel="fraction of the class", title=f"{assignment}: per stub")
    ax.legend(loc="upper right", fontsize="small")
    fig.tight_layout()
    return _png(fig)


# ------------------------------------------------------------------ the report


@dataclass
class Similarity:
    """What the similarity pass found: flagged pairs with their page, the closest unflagged pairs, and
    the submissions it could not compare."""

    pairs: list[tuple[Pair, str]]
    closest: list[tuple[str, str, float, float]]
    compared: int
    unread: list[StubCode]
    threshold: float
    pseudonyms: bool = False
    """Whether the names shown are pseudonyms (the key: the batch folder's ``_pseudonyms.csv``)."""


@dataclass
class ClassReport:
    assignment: str
    table: ClassTable
    stub_items: list[Item]
    test_items: list[Item]
    top_failures: list[Failure]
    messages: list[tuple[str, str, int]]
    stats: dict[str, float]
    edges: np.ndarray
    counts: np.ndarray
    similarity: Similarity | None


def analyse(assignment: str, results: dict[str, GradeResult], written: WrittenGrades | None = None,
            written_max: dict[str, float] | None = None,
            hand_stubs: dict[str, dict[str, tuple[float | None, float]]] | None = None) -> ClassReport:
    """Every figure of the report, from a batch folder's results (and the written answers' grades and stub scores
    changed by hand, if given)."""
    table = class_table(results, written, written_max, hand_stubs)
    stub_items, test_items = items(table)
    top, messages = failures(results)
    stats, edges, counts = distribution(table)
    return ClassReport(assignment, table, stub_items, test_items, top, messages, stats, edges, counts, None)


def _num(x: float | None, digits: int = 2) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def _rows(report: ClassReport) -> dict[str, tuple[list[str], list[list[str]]]]:
    """The report's tables as plain strings (escaped by each renderer)."""
    t = report.table
    n = len(t.names)
    item_head = ["stub", "points", "attempted", "mean", "full marks", "discrimination"]
    stubs = [[i.stub, f"{i.max_points:g}", f"{i.attempted}/{n}", _num(i.mean), f"{i.full_marks:.0%}",
              _num(i.discrimination)] for i in report.stub_items]
    tests = [[i.stub, i.test or "", f"{i.max_points:g}", f"{i.attempted}/{n}", _num(i.mean), f"{i.full_marks:.0%}",
              _num(i.discrimination)] for i in report.test_items]
    fails = [[f.stub, f.test, str(f.count), f.hint] for f in report.top_failures]
    msgs = [[stub, msg, str(c)] for stub, msg, c in report.messages]
    stats = [[k, f"{v:g}" if k == "submissions" else f"{v:.2f}"] for k, v in report.stats.items()]
    bands = [[f"{lo:g}–{hi:g}%", str(c)] for lo, hi, c in zip(report.edges[:-1], report.edges[1:], report.counts)]
    return {"stubs": (item_head, stubs),
            "tests": (["stub", "hidden test", *item_head[1:]], tests),
            "failures": (["stub", "hidden test", "failed by", "hint"], fails),
            "messages": (["stub", "message (first line)", "submissions"], msgs),
            "stats": (["total score", "value"], stats),
            "bands": (["band", "submissions"], bands)}


def _similarity_rows(sim: Similarity) -> tuple[list[str], list[list[str]]]:
    return (["submission", "submission", "share of the first's code", "share of the second's", "side by side"],
            [[p.a, p.b, f"{p.similarity_a:.0%}", f"{p.similarity_b:.0%}", page] for p, page in sim.pairs])


def _intro(report: ClassReport) -> tuple[str, str]:
    t, s = report.table, report.table.statuses
    counted = (f"{len(t.names)} submissions with a score ({s.get('graded', 0)} graded, {s.get('ungradable', 0)} "
               f"ungradable and counted at 0); maximum {t.max_total:g} points.")
    errors = t.grader_errors
    left = (f" {len(errors)} submission(s) where the grader failed are left out: they have no score (run the batch "
            f"again): {listed(errors)}."
            if errors else " The grader failed on no submission.")
    if t.written:
        waiting = int(np.isnan(t.written_scores).sum())
        left += (f" Written answers ({', '.join(t.written)}) from the gradebook are items and in the totals"
                 + (f"; {waiting} not graded yet count 0 there and are left out of their item." if waiting else "."))
    if t.hand_stubs:
        changed = "; ".join(f"{n}: {', '.join(h)}" for n, h in sorted(t.hand_stubs.items())[:20])
        left += (f" Stub scores changed by hand in formgrader ({sum(map(len, t.hand_stubs.values()))}: {changed}) "
                 "count in the totals, as in export; the per-stub and per-test figures are the hidden tests'.")
    if len(t.suite_versions) > 1:
        left += (f" Warning: these results come from {len(t.suite_versions)} versions of the hidden suite (a "
                 "regrade of some submissions after the suite changed): per-test figures mix them; regrade all.")
    return counted, left


DISCRIMINATION_NOTE = ("Discrimination: Pearson's correlation of the item's score with the rest of the score (the "
                       "total minus the item), over all submissions with a score. Near 0 or negative: the item does "
                       "not separate strong from weak submissions (too easy, too hard, or testing something else). "
                       "n/a: the item, or the rest, has the same value for everyone, so no correlation exists.")


def markdown(report: ClassReport, images: dict[str, str]) -> str:
    """``report.md``: every table, student text escaped; images by file name."""
    def table(head: list[str], rows: list[list[str]], link_last: bool = False) -> list[str]:
        def cell(c: str, last: bool) -> str:  # the link is the report's own file name, never student text
            if link_last and last:
                return f"[side by side]({c})" if c else f"not written (after the first {MAX_PAGES})"
            return markdown_text(c)
        out = ["| " + " | ".join(markdown_text(h) for h in head) + " |", "|" + "---|" * len(head)]
        out += ["| " + " | ".join(cell(c, j == len(row) - 1) for j, c in enumerate(row)) + " |" for row in rows]
        return out + [""]

    rows = _rows(report)
    counted, left = _intro(report)
    out = [f"# Class report: {report.assignment}", "", counted + left, "",
           "## Score distribution", "", f"![totals]({images['totals']})", ""]
    out += table(*rows["stats"]) + table(*rows["bands"])
    out += ["## Per stub", "", f"![stubs]({images['stubs']})", ""] + table(*rows["stubs"])
    out += [DISCRIMINATION_NOTE, "", "## Per hidden test", ""] + table(*rows["tests"])
    out += ["## Hidden tests failed most often (by those who attempted the stub)", ""] + table(*rows["failures"])
    out += ["## Failure messages met most often", ""] + table(*rows["messages"])
    out += _similarity_markdown(report.similarity, table)
    return "\n".join(out)


def _similarity_markdown(sim: Similarity | None, table) -> list[str]:
    out = ["## Similar stub code", ""]
    if sim is None:
        return out + ["Not computed: give the submissions folder (`class-report ID FOLDER --results DIR`).", ""]
    out += [f"**{markdown_text(NEVER_A_GRADE)}**", "", markdown_text(_similarity_summary(sim)), ""]
    head, rows = _similarity_rows(sim)
    out += table(head, rows, link_last=True) if rows else []
    if sim.closest:
        out += ["Closest pairs below the threshold:", ""]
        out += table(["submission", "submission", "share of the first's", "share of the second's"],
                     [[a, b, f"{x:.0%}", f"{y:.0%}"] for a, b, x, y in sim.closest])
    return out


def _similarity_summary(sim: Similarity) -> str:
    unread = (f" Not compared ({len(sim.unread)}): " + "; ".join(plain(f"{c.name}: {cap(c.problem, 120)}")
                                                                for c in sim.unread[:10]) + "."
              if sim.unread else "")
    names = (f" Names are pseudonyms, as formgrader hides names while grading; the key is {PSEUDONYMS_NAME} in the "
             "batch folder (class-report --names shows names)." if sim.pseudonyms else "")
    return (f"{sim.compared} submissions compared on their stub code (the released notebook's code set aside); "
            f"{len(sim.pairs)} pair(s) flagged, each sharing at least {sim.threshold:.0%} of both submissions' "
            f"compared code.{unread}{names}")


STYLE = ("body{font-family:system-ui,sans-serif;max-width:72em;margin:1.5em auto;padding:0 1em}"
         "table{border-collapse:collapse;margin:.6em 0 1.2em}td,th{border:1px solid #ccc;padding:.25em .5em;"
         "text-align:left;vertical-align:top}th{background:#f0f0f0}.note{border-left:4px solid #888;"
         "padding-left:.8em}img{max-width:100%}")


def html_page(report: ClassReport, images: dict[str, bytes]) -> str:
    """``report.html``: one offline page, the PNGs as data URIs, no script, every text cell escaped."""
    def table(head: list[str], rows: list[list[str]], link_last: bool = False) -> str:
        def cell(c: str, last: bool) -> str:
            if link_last and last:
                return (f"<a href='{html.escape(c)}'>side by side</a>" if c
                        else f"not written (after the first {MAX_PAGES})")
            return html.escape(c)
        body = "".join("<tr>" + "".join(f"<td>{cell(c, j == len(row) - 1)}</td>" for j, c in enumerate(row))
                       + "</tr>" for row in rows)
        return ("<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + f"</tr>{body}</table>"
                if rows else "<p>(none)</p>")

    def img(name: str, alt: str) -> str:
        return f"<img alt='{alt}' src='data:image/png;base64,{base64.b64encode(images[name]).decode()}'>"

    rows = _rows(report)
    counted, left = _intro(report)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Class report: "
             f"{html.escape(report.assignment)}</title><style>{STYLE}</style></head><body>",
             f"<h1>Class report: {html.escape(report.assignment)}</h1><p>{html.escape(counted + left)}</p>",
             "<h2>Score distribution</h2>", img("totals", "histogram of totals"), table(*rows["stats"]),
             table(*rows["bands"]), "<h2>Per stub</h2>", img("stubs", "per stub"), table(*rows["stubs"]),
             f"<p class='note'>{html.escape(DISCRIMINATION_NOTE)}</p>", "<h2>Per hidden test</h2>",
             table(*rows["tests"]), "<h2>Hidden tests failed most often (by those who attempted the stub)</h2>",
             table(*rows["failures"]), "<h2>Failure messages met most often</h2>", table(*rows["messages"]),
             "<h2>Similar stub code</h2>"]
    sim = report.similarity
    if sim is None:
        parts.append("<p>Not computed: give the submissions folder (class-report ID FOLDER --results DIR).</p>")
    else:
        parts += [f"<p class='note'><strong>{html.escape(NEVER_A_GRADE)}</strong></p>",
                  f"<p>{html.escape(_similarity_summary(sim))}</p>", table(*_similarity_rows(sim), link_last=True)]
        if sim.closest:
            parts += ["<p>Closest pairs below the threshold:</p>",
                      table(["submission", "submission", "share of the first's", "share of the second's"],
                            [[a, b, f"{x:.0%}", f"{y:.0%}"] for a, b, x, y in sim.closest])]
    return "".join(parts) + "</body></html>"


PSEUDONYM_KEY = "_pseudonym_key"
"""In the batch folder: the secret the pseudonyms are keyed with (so they cannot be recomputed from a class list)."""
PSEUDONYMS_NAME = "_pseudonyms.csv"
"""In the batch folder, outside the report folder: pseudonym → submission, for the instructor."""


def pseudonyms(results_dir: Path, names: list[str]) -> dict[str, str]:
    """A stable pseudonym per submission name (``anon-`` and an HMAC of the name under the batch's own key, made
    longer if two collide), and the key to them written to ``results_dir/_pseudonyms.csv``."""
    key_path = Path(results_dir) / PSEUDONYM_KEY
    if not key_path.is_file():
        atomic_write(key_path, secrets.token_hex(32))
    key = key_path.read_text(encoding="utf-8").strip().encode()
    digests = {n: hmac.new(key, n.encode("utf-8", "surrogateescape"), hashlib.sha256).hexdigest() for n in names}
    length = 6
    while len({d[:length] for d in digests.values()}) < len(digests):
        length += 2
    out = {n: f"anon-{d[:length]}" for n, d in digests.items()}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["pseudonym", "submission"])
    writer.writerows([p, csv_cell(n)] for n, p in sorted(out.items(), key=lambda kv: kv[1]))
    atomic_write(Path(results_dir) / PSEUDONYMS_NAME, buffer.getvalue())
    return out


def find_similar(assignment: str, folder: Path, out_dir: Path, threshold: float = THRESHOLD,
                 jobs: int = 2, rename: dict[str, str] | None = None) -> Similarity:
    """Compare the stub code of every submission in ``folder``; write a side-by-side page per flagged pair
    into ``out_dir/similarity/`` (earlier pages removed) and ``out_dir/similarity.csv``, and return what to list.
    With ``rename`` (name → pseudonym) no name appears in any of them."""
    codes = read_stub_code(assignment, folder, jobs=jobs)
    if rename is not None:
        codes = [StubCode(rename.get(c.name, c.name), c.code, c.problem.replace(c.name, rename.get(c.name, c.name))
                          if c.name else c.problem) for c in codes]
    return compare_and_write(assignment, codes, out_dir, threshold)


def compare_and_write(assignment: str, codes: list[StubCode], out_dir: Path, threshold: float = THRESHOLD
                      ) -> Similarity:
    """The second half of :func:`find_similar`, once the stub code is read."""
    flagged, scores = similar_pairs(codes, release_code(assignment), threshold=threshold)
    pages_dir = out_dir / "similarity"
    if pages_dir.is_dir():
        for old in pages_dir.glob("pair-*.html"):
            old.unlink()
    by_name = {c.name: c.code for c in codes}
    pairs = []
    for number, pair in enumerate(flagged, start=1):
        page = f"similarity/pair-{number:03d}.html" if number <= MAX_PAGES else ""
        if page:
            atomic_write(out_dir / page, pair_page(assignment, pair, by_name[pair.a], by_name[pair.b]))
        pairs.append((pair, page))
    flagged_keys = {(p.a, p.b) for p in flagged}
    closest = sorted((s for s in scores if (s[0], s[1]) not in flagged_keys), key=lambda s: -min(s[2], s[3]))
    unread = [c for c in codes if c.problem]
    compared = sum(1 for c in codes if c.code.strip())
    out_dir.mkdir(parents=True, exist_ok=True)
    with (out_dir / ".similarity.csv.tmp").open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["submission", "submission", "share of the first's code", "share of the second's", "flagged",
                         "side by side"])
        for pair, page in pairs:
            writer.writerow([csv_cell(pair.a), csv_cell(pair.b), f"{pair.similarity_a:.3f}",
                             f"{pair.similarity_b:.3f}", "yes", page])
        for a, b, x, y in closest:
            writer.writerow([csv_cell(a), csv_cell(b), f"{x:.3f}", f"{y:.3f}", "no", ""])
    (out_dir / ".similarity.csv.tmp").replace(out_dir / "similarity.csv")
    return Similarity(pairs, closest[:CLOSEST_SHOWN], compared, unread, threshold)



def write_class_report(assignment: str, results_dir: Path, out_dir: Path | None = None,
                       submissions: Path | None = None, threshold: float | None = None, jobs: int = 2,
                       names: bool = False, course_root: Path | None = None) -> ClassReport:
    """Write ``report.md``, its PNGs and ``report.html`` (and the similarity pages and CSV when ``submissions`` is
    given, with pseudonyms unless ``names``) into ``out_dir`` (default ``results_dir/_class_report``). Reads
    results (and, for a synced batch, the written answers' grades in the gradebook of ``course_root``) only;
    changes no grade."""
    results_dir = Path(results_dir)
    out_dir = Path(out_dir) if out_dir is not None else results_dir / REPORT_DIR
    results = {n: r for n, r in read_results(results_dir).items() if r.assignment == assignment}
    if not results:
        raise SystemExit(f"no results of {assignment} in {results_dir} (run `python -m autograder batch` first)")
    from autograder.outputs.gradebook import hand_stub_scores

    report = analyse(assignment, results, *written_from_gradebook(assignment, results_dir, course_root),
                     hand_stubs=hand_stub_scores(assignment, results_dir, course_root))
    if submissions is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        rename = None
        if not names:
            from autograder.core.batch import discover
            from autograder.core import course

            every = [e.name for e in discover(Path(submissions), assignment, course.stub_names(assignment))]
            rename = pseudonyms(results_dir, sorted(set(every) | set(results)))
        report.similarity = find_similar(assignment, Path(submissions), out_dir,
                                         THRESHOLD if threshold is None else threshold, jobs, rename)
        report.similarity.pseudonyms = rename is not None
    images = {"totals": totals_plot(report.table, report.edges, report.counts, assignment),
              "stubs": stubs_plot(report.stub_items, assignment)}
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, data in images.items():
        tmp = out_dir / f".{name}.png.tmp"
        tmp.write_bytes(data)
        tmp.replace(out_dir / f"{name}.png")
    atomic_write(out_dir / "report.md", markdown(report, {k: f"{k}.png" for k in images}))
    atomic_write(out_dir / "report.html", html_page(report, images))
    return report
