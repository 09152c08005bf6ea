"""Everything graded turns into files here: Gradescope JSON, student feedback, the gradebook.

All writes are atomic (a temporary file renamed into place), so a batch that is
killed at any moment never leaves a half-written result behind.
"""
from __future__ import annotations

import csv
import json
import os
import re
from pathlib import Path
from typing import Any, Iterable

from autograder.results import GradeResult, StubResult, result_to_dict

RESULT_NAME, FEEDBACK_NAME, GRADESCOPE_NAME = "result.json", "feedback.md", "results.json"
TERMINAL_MESSAGE_CHARS = 90
"""A failure's message in the terminal summary is cut here (the feedback file has it whole)."""
MESSAGE_CHARS, NOTE_CHARS, NAME_CHARS = 2000, 600, 200
"""Student text shown at most this long: a failure's message, a note, a submission's name."""
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\u200b-\u200f\ufeff]")
_MARKDOWN = re.compile(r"([\\`*_{}\[\]()#+!|<>~&$:=-])")
QUOTE = "    | "
"""Each line of a failure's message in Gradescope's plain text starts with this, so no student text can pass
for a line of the grader's (a check mark, a score)."""


def cap(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters, saying how much was left out."""
    text = str(text)
    return text if len(text) <= limit else text[:limit] + f"… ({len(text) - limit} more characters not shown)"


def plain(text: str) -> str:
    """``text`` without control characters (terminal escapes, carriage returns, bidirectional overrides,
    invisible characters): messages quote a student's exception text, which must not rewrite a terminal
    or forge a line."""
    return _CONTROL.sub("?", str(text))


def markdown_text(text: str) -> str:
    """``text`` shown literally in Markdown: no link, image, heading, HTML, entity, emoji code, math or emphasis
    a student could forge (every Markdown punctuation is backslash-escaped; lines break with ``<br>``)."""
    return _MARKDOWN.sub(r"\\\1", plain(text)).replace("\n", "<br>")


def quoted_lines(text: str) -> list[str]:
    """``text`` as plain-text lines, each behind :data:`QUOTE`."""
    return [QUOTE + line for line in plain(text).split("\n")]


def _cell(text: str) -> str:
    """A CSV cell that a spreadsheet shows as text, never runs as a formula."""
    text = _one_line(text)
    return "'" + text if text[:1] in ("=", "+", "-", "@", "\t", "\r", "|", "%") else text


def _one_line(text: str) -> str:
    return plain(text).replace("\n", " ⏎ ").replace("\t", " ")


def atomic_write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _fmt(points: float) -> str:
    return f"{points:g}"


def _stub_output(stub: StubResult) -> str:
    lines = []
    for test in stub.tests:
        mark = "✓" if test.passed else "✗"
        lines.append(f"{mark} {test.name} ({_fmt(test.points if test.passed else 0)}/{_fmt(test.points)})")
        if not test.passed:
            lines += quoted_lines(cap(test.message, MESSAGE_CHARS))
            if test.hint:
                lines.append(f"    hint: {test.hint}")
    return "\n".join(lines)


def gradescope_results(result: GradeResult) -> dict[str, Any]:
    """Gradescope's ``results.json``: one test entry per stub, with each check listed in its output.

    Every output is plain text (``output_format`` and the tests' formats say so: Gradescope renders
    nothing in it as Markdown or HTML), and a student's text is quoted line by line and cut.
    """
    tests = []
    for number, stub in enumerate(result.stubs, start=1):
        tests.append({
            "name": stub.name, "number": str(number), "score": stub.score, "max_score": stub.max_score,
            "status": "passed" if stub.tests and stub.score == stub.max_score else "failed",
            "output": _stub_output(stub), "output_format": "text", "visibility": "visible",
        })
    return {
        "score": result.score, "execution_time": round(result.seconds, 2), "output": _overall_output(result),
        "output_format": "text", "test_output_format": "text", "test_name_format": "text",
        "visibility": "visible", "stdout_visibility": "hidden", "tests": tests,
    }


def _overall_output(result: GradeResult) -> str:
    parts = []
    if result.error:
        parts.append("This submission could not be graded automatically:")
        parts += quoted_lines(cap(result.error, MESSAGE_CHARS))
    for note in result.notes:
        parts.append("Note:")
        parts += quoted_lines(cap(note, NOTE_CHARS))
    if result.manual:
        total = sum(points for _, points in result.manual)
        parts.append(f"Written answers graded by hand later ({_fmt(total)} points): "
                     + ", ".join(f"{gid} ({_fmt(points)})" for gid, points in result.manual))
    return "\n".join(parts)


def feedback_markdown(result: GradeResult) -> str:
    """The per-student feedback file: per stub, what passed, what failed and a hint."""
    out = [f"# Feedback: {result.assignment} · {markdown_text(cap(result.submission, NAME_CHARS))}", "",
           f"**Automatic score: {_fmt(result.score)} / {_fmt(result.max_score)}**", ""]
    if result.error:
        out += [f"> This submission could not be graded automatically: {markdown_text(cap(result.error, MESSAGE_CHARS))}",
                ""]
    for note in result.notes:
        out.append(f"- note: {markdown_text(cap(note, NOTE_CHARS))}")
    if result.notes:
        out.append("")
    for stub in result.stubs:
        out += [f"## `{stub.name}`: {_fmt(stub.score)} / {_fmt(stub.max_score)}", ""]
        for test in stub.tests:
            if test.passed:
                out.append(f"- ✓ {test.name}")
            else:
                out.append(f"- ✗ {test.name}: {markdown_text(cap(test.message, MESSAGE_CHARS))}")
                if test.hint:
                    out.append(f"  - *hint:* {test.hint}")
        out.append("")
    if result.manual:
        out += ["## Written answers (graded by hand)", ""]
        out += [f"- `{gid}`: {_fmt(points)} point(s), pending" for gid, points in result.manual]
        out.append("")
    return "\n".join(out)


def write_outputs(result: GradeResult, out_dir: Path) -> None:
    """``results.json`` (Gradescope), ``feedback.md`` and ``result.json`` (the full record) into ``out_dir``.

    The full record is written last: its presence marks the submission as graded. A grader error
    writes the record alone (its status says to retry) and removes any score left from before.
    """
    if not result.has_score:
        for name in (GRADESCOPE_NAME, FEEDBACK_NAME):
            (out_dir / name).unlink(missing_ok=True)
        atomic_write(out_dir / RESULT_NAME, json.dumps(result_to_dict(result), indent=2, ensure_ascii=False))
        return
    atomic_write(out_dir / GRADESCOPE_NAME, json.dumps(gradescope_results(result), indent=2, ensure_ascii=False))
    atomic_write(out_dir / FEEDBACK_NAME, feedback_markdown(result))
    atomic_write(out_dir / RESULT_NAME, json.dumps(result_to_dict(result), indent=2, ensure_ascii=False))


def summary_lines(result: GradeResult) -> list[str]:
    """A short per-stub table for the terminal."""
    if not result.has_score:
        return [f"{result.assignment} · {_one_line(cap(result.submission, NAME_CHARS))}: NOT GRADED: the grader "
                "failed, no score was given", f"  {_one_line(cap(result.error or '', MESSAGE_CHARS))}"]
    width = max([len(s.name) for s in result.stubs] + [4])
    lines = [f"{result.assignment} · {_one_line(cap(result.submission, NAME_CHARS))}: "
             f"{_fmt(result.score)}/{_fmt(result.max_score)}"
             + (f"  (ungradable: {_one_line(cap(result.error, TERMINAL_MESSAGE_CHARS))})" if result.error else "")]
    for stub in result.stubs:
        failed = [t for t in stub.tests if not t.passed]
        why = f"  {_one_line(failed[0].message)[:TERMINAL_MESSAGE_CHARS]}" if failed else ""
        lines.append(f"  {stub.name:<{width}}  {_fmt(stub.score):>4}/{_fmt(stub.max_score):<4}{why}")
    return lines


def write_gradebook(results: Iterable[GradeResult], path: Path, stubs: list[str] = ()) -> None:
    """The CSV gradebook: one row per submission, ungradable ones included with their reason, and grader
    errors with empty score cells (never a zero: the student was not graded)."""
    results = list(results)
    stubs = list(dict.fromkeys([*stubs, *(s.name for r in results for s in r.stubs)]))
    rows = [["submission", "score", "max_score", "percent", *stubs, "status", "reason"]]
    for r in sorted(results, key=lambda r: r.submission):
        if not r.has_score:
            rows.append([_cell(r.submission), "", "", "", *[""] * len(stubs), r.status, _cell(cap(r.error or "", NOTE_CHARS))])
            continue
        per = {s.name: s.score for s in r.stubs}
        percent = 100 * r.score / r.max_score if r.max_score else 0.0
        rows.append([_cell(r.submission), _fmt(r.score), _fmt(r.max_score), f"{percent:.1f}",
                     *[_fmt(per.get(s, 0)) for s in stubs], r.status, _cell(cap(r.error or "", NOTE_CHARS))])
    tmp = path.with_name(f".{path.name}.tmp")
    path.parent.mkdir(parents=True, exist_ok=True)
    with tmp.open("w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows(rows)
    os.replace(tmp, path)
