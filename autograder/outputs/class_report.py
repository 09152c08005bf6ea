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
  total minus the item), so an item is not correlated with itself. When the item or the rest takes
  one value across the class the correlation is undefined, and the report says "n/a" rather than
  inventing a 0.
"""
from __future__ import annotations

import base64
import html
import io
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autograder.outputs.batch_output import read_results
from autograder.outputs.similarity import (NEVER_A_GRADE, Pair, StubCode, pair_page, read_stub_code, release_code,
                                           similar_pairs, THRESHOLD)
from autograder.core.store import atomic_write
from autograder.outputs.text import cap, markdown_text, plain
from autograder.core.results import GRADED, GRADER_ERROR, GradeResult

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


def _attempted(stub_tests: list) -> bool:
    """Whether any of a stub's tests shows an attempt (its recorded :class:`Reason`, never its message)."""
    return any(t.reason.attempted for t in stub_tests)


def class_table(results: dict[str, GradeResult]) -> ClassTable:
    """Arrange the results of a batch folder by submission and item (a missing stub or test scores 0)."""
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
    return ClassTable(list(scored), np.array([r.score for r in scored.values()]), float(stub_max.sum()), stubs,
                      stub_scores, stub_max, tests, test_scores, test_max_arr, attempted,
                      Counter(r.status for r in results.values()),
                      {v for r in scored.values() if (v := getattr(r, "suite_version", ""))})


def item_rest_correlation(scores: np.ndarray, totals: np.ndarray) -> np.ndarray:
    """Per column of ``scores`` (N, M), Pearson's r between the item and ``totals`` minus it; NaN where the item
    or the rest is constant over the class (no spread, no correlation), or fewer than two submissions."""
    scores = np.asarray(scores, dtype=float)
    if len(totals) < 2:
        return np.full(scores.shape[1], np.nan)
    rest = np.asarray(totals, dtype=float)[:, None] - scores
    constant = (np.ptp(scores, axis=0) == 0) | (np.ptp(rest, axis=0) == 0)
    x, y = scores - scores.mean(axis=0), rest - rest.mean(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (x * y).sum(axis=0) / np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
    return np.where(constant, np.nan, np.clip(r, -1.0, 1.0))


def items(table: ClassTable) -> tuple[list[Item], list[Item]]:
    """The figures of each stub and of each hidden test (see the module docstring)."""
    def figures(scores: np.ndarray, maxima: np.ndarray, attempted: np.ndarray, keys: list[tuple[str, str | None]]):
        n = len(table.names)
        means = scores.mean(axis=0) if n else np.zeros(len(keys))
        full = (scores >= maxima[None, :]).mean(axis=0) if n else np.zeros(len(keys))
        disc = item_rest_correlation(scores, table.totals)
        return [Item(stub, test, float(m), int(a), float(mu), float(f), None if np.isnan(d) else float(d))
                for (stub, test), m, a, mu, f, d in zip(keys, maxima, attempted, means, full, disc)]

    col = {s: j for j, s in enumerate(table.stubs)}
    stub_items = figures(table.stub_scores, table.stub_max, table.attempted.sum(axis=0),
                         [(s, None) for s in table.stubs])
    test_attempted = np.array([table.attempted[:, col[s]].sum() for s, _ in table.tests], dtype=int)
    test_items = figures(table.test_scores, table.test_max, test_attempted, list(table.tests))
    return stub_items, test_items


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


def analyse(assignment: str, results: dict[str, GradeResult]) -> ClassReport:
    """Every figure of the report, from a batch folder's results."""
    table = class_table(results)
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
    left = (f" {s[GRADER_ERROR]} submission(s) where the grader failed are left out: they have no score "
            "(run the batch again)." if s.get(GRADER_ERROR) else "")
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
    return (f"{sim.compared} submissions compared on their stub code (the released notebook's code set aside); "
            f"{len(sim.pairs)} pair(s) flagged, each sharing at least {sim.threshold:.0%} of both submissions' "
            f"compared code.{unread}")


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


def find_similar(assignment: str, folder: Path, out_dir: Path, threshold: float = THRESHOLD,
                 jobs: int = 2) -> Similarity:
    """Compare the stub code of every submission in ``folder``; write a side-by-side page per flagged pair
    into ``out_dir/similarity/`` (earlier pages removed) and return what to list."""
    return compare_and_write(assignment, read_stub_code(assignment, folder, jobs=jobs), out_dir, threshold)


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
    return Similarity(pairs, closest[:CLOSEST_SHOWN], compared, unread, threshold)


def write_class_report(assignment: str, results_dir: Path, out_dir: Path | None = None,
                       submissions: Path | None = None, threshold: float | None = None, jobs: int = 2) -> ClassReport:
    """Write ``report.md``, its PNGs and ``report.html`` (and the similarity pages when ``submissions`` is
    given) into ``out_dir`` (default ``results_dir/_class_report``). Reads results only; changes no grade."""
    results_dir = Path(results_dir)
    out_dir = Path(out_dir) if out_dir is not None else results_dir / REPORT_DIR
    results = {n: r for n, r in read_results(results_dir).items() if r.assignment == assignment}
    if not results:
        raise SystemExit(f"no results of {assignment} in {results_dir} (run `python -m autograder batch` first)")
    report = analyse(assignment, results)
    if submissions is not None:
        report.similarity = find_similar(assignment, Path(submissions), out_dir,
                                         THRESHOLD if threshold is None else threshold, jobs)
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
