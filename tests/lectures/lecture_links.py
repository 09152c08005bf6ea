"""Ties every labelled equation of the lecture notes to the tests that check it.

The notes (``lectures/**/*.md``, MyST Markdown) label a display equation in
one of two ways::

    $$
    J(\\pi) = \\E[\\dots]
    $$ (eq-total-cost)

    ```{math}
    :label: eq-total-cost
    J(\\pi) = \\E[\\dots]
    ```

:func:`equations` reads every Markdown file under ``lectures/`` (new chapters
included, ``README.md`` and ``_build/`` excluded) and returns each labelled
equation with its TeX source and a short digest of that source (SHA-256 of
the source with runs of whitespace collapsed, first 8 hex digits), so
re-wrapping a line changes nothing but changing a symbol does.

A test names the equations it checks, with the digest of the source it was
written against, by stacking :func:`checks` decorators::

    @checks("eq-bt", "3f1c09aa")
    def test_bradley_terry(...): ...

When the test runs, the decorator first compares the digest with the
equation's current source and fails, naming the file and line, if they
differ: editing an equation fails every test tied to it until someone has
re-read the test against the new text and updated the digest.
``tests/test_lecture_links.py`` fails when a labelled equation has no test,
when a test names a label that no longer exists, or when a digest is stale.

Notebooks point into the notes with relative Markdown links, which JupyterLab
opens from the notebook's folder, scrolled to the heading whose id (its text,
spaces made hyphens) follows the ``#``::

    [lecture 6, eq. (eq-kl-estimators)](../../lectures/06_rlhf.md#The-KL-to-the-reference,-in-practice)

:func:`notebook_links` reads them from a notebook's Markdown cells and
:meth:`NotebookLink.problem` says why one does not resolve: the page is
missing, or it has no such heading id, MyST target ``(label)=``, equation
label or directive ``:label:``/``:name:``.

Command line (from the repository root)::

    .venv/bin/python tests/lecture_links.py            # every label: digest, place, tests
    .venv/bin/python tests/lecture_links.py --missing  # labels without a test, stale digests
    .venv/bin/python tests/lecture_links.py eq-bt      # one label, with its source
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import importlib
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parents[1]
LECTURES = REPO / "lectures"
TEST_GLOB = "test_lecture_*.py"  # the modules whose @checks count (all are imported by the coverage test)

_FENCE = re.compile(r"^\s*(`{3,}|~{3,})\s*(.*?)\s*$")
_DOLLARS_OPEN = re.compile(r"^\s*\$\$(.*)$")
_DOLLARS_CLOSE = re.compile(r"^(.*?)\$\$\s*(?:\((?P<label>[^()\s]+)\))?\s*$")
_CODE_DIRECTIVES = ("{code-block}", "{code-cell}", "{code}", "{literalinclude}", "{sourcecode}")


def normalise(tex: str) -> str:
    """The TeX source with runs of whitespace collapsed to one space (what the digest covers)."""
    return " ".join(tex.split())


def digest(tex: str) -> str:
    """First 8 hex digits of the SHA-256 of the normalised source."""
    return hashlib.sha256(normalise(tex).encode("utf-8")).hexdigest()[:8]


@dataclass(frozen=True)
class Equation:
    """One labelled display equation: its label, where it is, and its TeX source."""

    label: str
    path: Path
    line: int  # 1-based line of the opening $$ or ```{math}
    source: str

    @property
    def digest(self) -> str:
        return digest(self.source)

    @property
    def where(self) -> str:
        try:
            shown = self.path.relative_to(REPO)
        except ValueError:
            shown = self.path
        return f"{shown}:{self.line}"


class LectureParseError(ValueError):
    """A labelled equation that cannot be read (unterminated, duplicate label)."""


def parse_equations(text: str, path: Path = Path("<string>")) -> list[Equation]:
    """Every labelled display equation in one MyST Markdown text, in order.

    Code fences (```python, ```bash, ```{code-block} ...) are skipped, so an
    example of the syntax inside one is not an equation. Directive fences
    (```{prf:theorem}, ```{exercise} ...) are read through, since equations
    live inside them. Unlabelled displays are not returned.
    """
    lines = text.splitlines()
    found: list[Equation] = []
    fences: list[tuple[str, int, bool]] = []  # (fence char, length, is a code fence)
    i = 0
    while i < len(lines):
        line = lines[i]
        fence = _FENCE.match(line)
        if fence:
            marks, info = fence.group(1), fence.group(2)
            top = fences[-1] if fences else None
            closes = top is not None and not info and marks[0] == top[0] and len(marks) >= top[1]
            if closes:
                fences.pop()
            elif top is not None and top[2]:
                pass  # a fence-looking line inside a code block is code
            elif info.startswith("{math}"):
                i = _read_math_directive(lines, i, marks, path, found)
            else:
                is_code = not info.startswith("{") or info.startswith(_CODE_DIRECTIVES)
                fences.append((marks[0], len(marks), is_code))
            i += 1
            continue
        if fences and fences[-1][2]:
            i += 1
            continue
        opening = _DOLLARS_OPEN.match(line)
        if opening:
            i = _read_dollars(lines, i, opening.group(1), path, found)
        i += 1
    return found


def _read_dollars(lines: list[str], start: int, rest: str, path: Path, found: list[Equation]) -> int:
    """Read a $$ ... $$ block opening on line ``start``; return the index of its closing line."""
    closing = _DOLLARS_CLOSE.match(rest)
    if closing and rest.strip():  # $$ tex $$ (label) on one line
        if closing.group("label"):
            found.append(Equation(closing.group("label"), path, start + 1, closing.group(1).strip()))
        return start
    body = [rest] if rest.strip() else []
    for j in range(start + 1, len(lines)):
        closing = _DOLLARS_CLOSE.match(lines[j])
        if closing and "$$" in lines[j]:
            body.append(closing.group(1))
            if closing.group("label"):
                found.append(Equation(closing.group("label"), path, start + 1, "\n".join(body).strip()))
            return j
        body.append(lines[j])
    raise LectureParseError(f"{path}:{start + 1}: display math opened with $$ is never closed")


def _read_math_directive(lines: list[str], start: int, marks: str, path: Path, found: list[Equation]) -> int:
    """Read a ```{math} directive opening on line ``start``; return the index of its closing fence."""
    label, body = None, []
    for j in range(start + 1, len(lines)):
        stripped = lines[j].strip()
        if stripped.startswith(marks[0] * len(marks)) and not stripped.strip(marks[0]):
            if label:
                found.append(Equation(label, path, start + 1, "\n".join(body).strip()))
            return j
        option = re.match(r"^:(\w+):\s*(.*)$", stripped)
        if option and not body:
            if option.group(1) == "label":
                label = option.group(2).strip()
            continue
        body.append(lines[j])
    raise LectureParseError(f"{path}:{start + 1}: ```{{math}} directive is never closed")


def lecture_files(root: Path | None = None) -> list[Path]:
    """Every Markdown page of the notes (README.md and the build folder excluded)."""
    root = LECTURES if root is None else root
    return sorted(
        p for p in root.rglob("*.md")
        if p.name != "README.md" and "_build" not in p.relative_to(root).parts
    )


@functools.lru_cache(maxsize=None)
def _parse_file(path: Path, mtime_ns: int, size: int) -> tuple[Equation, ...]:
    return tuple(parse_equations(path.read_text(encoding="utf-8"), path))


def equations(root: Path | None = None) -> dict[str, Equation]:
    """Every labelled equation under ``root`` (default ``lectures/``), by label; a label used twice is an error."""
    result: dict[str, Equation] = {}
    for path in lecture_files(root):
        stat = path.stat()
        for eq in _parse_file(path, stat.st_mtime_ns, stat.st_size):
            if eq.label in result:
                raise LectureParseError(f"equation label {eq.label} is used twice: {result[eq.label].where} and {eq.where}")
            result[eq.label] = eq
    return result


# ---------------------------------------------------------------------------
# the registry: which test checks which equation, against which source
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Citation:
    """A test's claim to check one equation, written against the source with this digest."""

    label: str
    digest: str
    test: str  # module.function


REGISTRY: dict[tuple[str, str], Citation] = {}  # (label, test) -> citation


def stale_message(citation: Citation, current: dict[str, Equation]) -> str | None:
    """Why a citation no longer holds (unknown label, changed source), or None if it does."""
    eq = current.get(citation.label)
    if eq is None:
        return (f"{citation.test} checks {citation.label}, but no lecture labels an equation so "
                f"(renamed or removed?)")
    if eq.digest != citation.digest:
        return (f"{citation.label} ({eq.where}) changed since {citation.test} was written against it: "
                f"digest {citation.digest}, now {eq.digest}. Re-read the test against the equation as it "
                f"now stands, fix whichever is wrong, then update the digest in @checks")
    return None


def checks(label: str, source_digest: str) -> Callable[[Callable], Callable]:
    """Decorator: this test checks equation ``label``, written against the source with ``source_digest``.

    Stack one per equation. The test fails before running its body if the
    equation's source has changed (or the label is gone). Pytest marks and
    fixtures keep working (the wrapper keeps the signature via ``__wrapped__``).
    """
    if not re.fullmatch(r"[0-9a-f]{8}", source_digest):
        raise ValueError(f"@checks({label!r}, {source_digest!r}): the digest is 8 lowercase hex digits")

    def decorate(test: Callable) -> Callable:
        target = getattr(test, "__wrapped__", test)
        citation = Citation(label, source_digest, f"{target.__module__}.{target.__name__}")
        REGISTRY[(label, citation.test)] = citation

        @functools.wraps(test)
        def wrapper(*args, **kwargs):
            problem = stale_message(citation, equations())
            if problem:
                raise AssertionError(problem)
            return test(*args, **kwargs)

        wrapper.lecture_citations = (*getattr(test, "lecture_citations", ()), citation)
        return wrapper

    return decorate


def load_test_modules(tests: Path = TESTS) -> list[str]:
    """Import every ``tests/test_lecture_*.py`` so that its @checks register; return the module names."""
    if str(tests) not in sys.path:
        sys.path.insert(0, str(tests))
    names = [p.stem for p in sorted(tests.glob(TEST_GLOB))]
    for name in names:
        importlib.import_module(name)
    return names


def coverage(labels: Iterable[str]) -> dict[str, list[Citation]]:
    """The citations of each label (an empty list for a label no test checks)."""
    by_label: dict[str, list[Citation]] = {label: [] for label in labels}
    for citation in REGISTRY.values():
        by_label.setdefault(citation.label, []).append(citation)
    return by_label


# ---------------------------------------------------------------------------
# links from the notebooks into the notes
# ---------------------------------------------------------------------------

_TARGET = re.compile(r"^\s*\((?P<label>[^()\s]+)\)=\s*$")
_OPTION_LABEL = re.compile(r"^\s*:(?:label|name):\s*(?P<label>\S+)\s*$")
_MD_LINK = re.compile(r"\]\((?P<target>[^()\s]*lectures/[^()\s#]*\.md)(?:#(?P<anchor>[^()\s]*))?\)")


_HEADING = re.compile(r"^#{1,6}\s+(?P<text>.*?)\s*#*\s*$")


def heading_id(text: str) -> str:
    """The id JupyterLab gives a Markdown heading: its rendered text with every space made a hyphen (case kept;
    inline code and emphasis marks are not text, math stays as written)."""
    return re.sub(r"[`*]", "", text).strip().replace(" ", "-")


def headings(path: Path) -> dict[str, str]:
    """Each heading's JupyterLab id in one page, mapped to the MyST target just above it ('' if none)."""
    out, target, fences = {}, "", []
    for line in path.read_text(encoding="utf-8").splitlines():
        mark = _FENCE.match(line)
        if mark:              # a fence closes with its own character, as long or longer, and no info string
            marks, info = mark.group(1), mark.group(2)
            if fences and not info and marks[0] == fences[-1][0] and len(marks) >= len(fences[-1]):
                fences.pop()
            else:
                fences.append(marks)
            continue
        if fences:            # headings inside a code block or a directive are not the page's sections
            continue
        if m := _TARGET.match(line):
            target = m.group("label")
        elif m := _HEADING.match(line):
            out[heading_id(m.group("text"))], target = target, ""
        elif line.strip():
            target = ""
    return out


def anchors(path: Path) -> set[str]:
    """What a link may point at in one page: a heading's JupyterLab id (what scrolls when JupyterLab opens the
    page), a MyST target ``(label)=``, a labelled equation, or the ``:label:``/``:name:`` of a directive."""
    text = path.read_text(encoding="utf-8")
    found = {m.group("label") for line in text.splitlines() for m in [_TARGET.match(line) or _OPTION_LABEL.match(line)] if m}
    return found | {eq.label for eq in parse_equations(text, path)} | set(headings(path))


@dataclass(frozen=True)
class NotebookLink:
    """One Markdown link from a notebook cell into ``lectures/``: where it is and what it names."""

    notebook: Path
    cell: int
    target: str      # as written, relative to the notebook's folder
    anchor: str      # the part after '#', or '' for none

    def problem(self) -> str | None:
        """Why the link does not resolve (a missing page, or a label that page does not define), or None."""
        page = (self.notebook.parent / self.target).resolve()
        if not page.is_file():
            return f"{self.notebook.relative_to(REPO)} cell {self.cell}: {self.target} is not a file"
        if self.anchor and self.anchor not in anchors(page):
            return (f"{self.notebook.relative_to(REPO)} cell {self.cell}: {page.relative_to(REPO)} has no heading, "
                    f"target or label '{self.anchor}' (a heading's JupyterLab id is its text with spaces as '-')")
        return None


def notebook_links(path: Path) -> list[NotebookLink]:
    """Every link into ``lectures/`` in the Markdown cells of the notebook at ``path``."""
    import json

    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    return [NotebookLink(path, i, m.group("target"), m.group("anchor") or "")
            for i, cell in enumerate(cells) if cell["cell_type"] == "markdown"
            for m in _MD_LINK.finditer("".join(cell["source"]))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("labels", nargs="*", help="show these labels with their source")
    parser.add_argument("--missing", action="store_true", help="only labels without a test, and stale citations")
    args = parser.parse_args(argv)
    current = equations()
    load_test_modules()
    registry = importlib.import_module("lecture_links")  # the tests register there, not in __main__
    covered = registry.coverage(current)
    problems = 0
    for label in args.labels or list(current):
        eq = current.get(label)
        cited = sorted(c.test.split(".")[-1] for c in covered.get(label, []))
        if args.missing and eq is not None and cited:
            continue
        if eq is None:
            print(f"{label}: no such labelled equation")
            problems += 1
            continue
        problems += not cited
        print(f"{label:28s} {eq.digest}  {eq.where:40s} {', '.join(cited) or 'NO TEST'}")
        if args.labels:
            print("    " + eq.source.replace("\n", "\n    "))
    for citation in registry.REGISTRY.values():
        message = stale_message(citation, current)
        if message:
            print("stale: " + message)
            problems += 1
    return 1 if args.missing and problems else 0


if __name__ == "__main__":
    sys.exit(main())
