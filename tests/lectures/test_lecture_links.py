"""Every labelled equation in lectures/ has a test, and every test's digest matches the equation.

How the link works is explained in ``tests/lecture_links.py`` and in
CONTRIBUTING.md ("Lecture equations and their tests"). This module checks the
link itself: the parser, and the coverage of every chapter, new ones included.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import lecture_links as ll  # noqa: E402

# Labels that no test checks yet, each to be removed from this set by the commit that adds its test.
# The coverage test fails for a label missing from here and for a label here that is already covered.
PENDING: set[str] = set()


def _current_and_covered():
    current = ll.equations()
    ll.load_test_modules()
    return current, ll.coverage(current)


def test_every_labelled_equation_has_a_test():
    current, covered = _current_and_covered()
    missing = [f"{label} ({current[label].where}, digest {current[label].digest})"
               for label, cites in covered.items() if label in current and not cites and label not in PENDING]
    assert not missing, ("labelled equations no test checks (add @checks(label, digest) to the test that "
                         "checks each; python tests/lecture_links.py --missing lists them):\n  " + "\n  ".join(missing))


def test_pending_labels_exist_and_are_not_yet_covered():
    current, covered = _current_and_covered()
    gone = sorted(PENDING - set(current))
    done = sorted(label for label in PENDING & set(current) if covered[label])
    assert not gone, f"PENDING names labels no lecture has: {gone}"
    assert not done, f"PENDING names labels that now have a test (remove them): {done}"


def test_every_citation_is_current():
    current, _ = _current_and_covered()
    stale = [message for c in ll.REGISTRY.values() if (message := ll.stale_message(c, current))]
    assert not stale, "\n".join(stale)


def test_formulas_in_lecture_math_cite_labels_that_exist():
    cited = set(re.findall(r"\[(eq-[a-z0-9-]+)\]", (Path(__file__).parent / "lecture_math.py").read_text()))
    assert cited, "lecture_math.py cites no equation label"
    missing = sorted(cited - set(ll.equations()))
    assert not missing, f"lecture_math.py cites labels no lecture defines: {missing}"


# ---------------------------------------------------------------------------
# the parser and the decorator on synthetic pages
# ---------------------------------------------------------------------------

PAGE = """\
# A chapter

$$
a = b + c
$$ (eq-one)

```{prf:theorem} Inside a directive
:label: thm-x

$$
x^2 \\ge 0
$$ (eq-two)
```

```python
$$
not = math
$$ (eq-in-code)
```

````{exercise} Nested
```{math}
:label: eq-three
y =  z
```
````

$$ q = r $$ (eq-four)

$$
unlabelled
$$

  $$
  indented
  $$ (eq-five)
"""


def test_parser_reads_both_syntaxes_inside_directives_and_skips_code():
    found = {eq.label: eq for eq in ll.parse_equations(PAGE, Path("page.md"))}
    assert list(found) == ["eq-one", "eq-two", "eq-three", "eq-four", "eq-five"]
    assert found["eq-one"].source == "a = b + c" and found["eq-one"].line == 3
    assert found["eq-two"].source == "x^2 \\ge 0"
    assert found["eq-three"].source == "y =  z"
    assert found["eq-four"].source == "q = r"
    assert found["eq-five"].source == "indented"


def test_digest_ignores_layout_but_not_content():
    assert ll.digest("a = b\n  + c") == ll.digest("a = b + c")
    assert ll.digest("a = b + c") != ll.digest("a = b - c")
    assert ll.digest("T^2 \\epsilon") != ll.digest("T \\epsilon")


def test_unterminated_display_and_duplicate_labels_are_errors(tmp_path):
    with pytest.raises(ll.LectureParseError, match="never closed"):
        ll.parse_equations("$$\na = b\n", Path("bad.md"))
    (tmp_path / "a.md").write_text("$$\nx\n$$ (eq-same)\n")
    (tmp_path / "b.md").write_text("$$\ny\n$$ (eq-same)\n")
    with pytest.raises(ll.LectureParseError, match="used twice"):
        ll.equations(tmp_path)


def test_a_test_fails_when_its_equation_changes(tmp_path, monkeypatch):
    page = tmp_path / "ch.md"
    page.write_text("$$\nJ \\le T^2 \\epsilon\n$$ (eq-demo)\n")
    monkeypatch.setattr(ll, "LECTURES", tmp_path)
    ran = []

    @ll.checks("eq-demo", ll.digest("J \\le T^2 \\epsilon"))
    def demo_test():
        ran.append(True)

    try:
        demo_test()
        assert ran == [True]
        page.write_text("$$\nJ \\le T \\epsilon\n$$ (eq-demo)\n")  # someone drops a T
        with pytest.raises(AssertionError, match="eq-demo .* changed since"):
            demo_test()
        page.write_text("$$\nJ \\le T^2 \\epsilon\n$$ (eq-renamed)\n")
        with pytest.raises(AssertionError, match="no lecture labels"):
            demo_test()
        assert ran == [True]  # the body never ran against a changed equation
    finally:
        ll.REGISTRY.pop(("eq-demo", f"{__name__}.demo_test"), None)


def test_bad_digest_is_refused():
    with pytest.raises(ValueError, match="8 lowercase hex"):
        ll.checks("eq-x", "not-hex")


# ---------------------------------------------------------------------------
# links from the notebooks into the notes
# ---------------------------------------------------------------------------

NOTEBOOKS = sorted((ll.REPO / "solutions").glob("*/*.ipynb")) + sorted((ll.REPO / "assignments").glob("*/*.ipynb"))
# Assignments whose notebooks do not point into the notes yet, each to be removed by the commit that adds links.
UNLINKED: set[str] = set()


def test_every_notebook_link_into_the_notes_names_a_page_and_a_label_that_exist():
    links = [link for nb in NOTEBOOKS for link in ll.notebook_links(nb)]
    assert links, "no notebook links into lectures/"
    broken = [p for link in links if (p := link.problem())]
    assert not broken, "notebook links that do not resolve:\n  " + "\n  ".join(broken)


def test_every_notebook_links_its_lectures_unless_listed_as_pending():
    ids = sorted({nb.parent.name for nb in NOTEBOOKS})
    solution = {i: ll.REPO / "solutions" / i / f"{i}.ipynb" for i in ids}
    unlinked = {i for i in ids if not any(link.anchor for link in ll.notebook_links(solution[i]))}
    assert not unlinked - UNLINKED, f"notebooks with no link to a lecture section or equation: {sorted(unlinked - UNLINKED)}"
    linked_now = sorted(UNLINKED - unlinked)
    assert not linked_now, f"UNLINKED names notebooks that now link their lectures (remove them): {linked_now}"


def test_a_link_to_a_missing_label_or_page_is_reported(tmp_path, monkeypatch):
    (tmp_path / "lectures").mkdir()
    (tmp_path / "lectures" / "ch.md").write_text(
        "(sec-a)=\n# A\n\n$$\nx = 1\n$$ (eq-x)\n\n```{prf:theorem} T\n:label: thm-t\n```\n\n"
        "(sec-b2)=\n## Best-of-$n$, and `code`\n\n```python\n# not a heading\n```\n")
    nb_dir = tmp_path / "solutions" / "hw"
    nb_dir.mkdir(parents=True)
    cells = [{"cell_type": "markdown", "metadata": {}, "source": [
        "[ok](../../lectures/ch.md#sec-a) [eq](../../lectures/ch.md#eq-x) [thm](../../lectures/ch.md#thm-t) "
        "[page](../../lectures/ch.md) [bad](../../lectures/ch.md#sec-b) [gone](../../lectures/no.md#sec-a) "
        "[lab](../../lectures/ch.md#Best-of-$n$,-and-code) [code](../../lectures/ch.md#not-a-heading)"]},
             {"cell_type": "code", "metadata": {}, "source": ["# [not markdown](../../lectures/ch.md#zzz)"], "outputs": []}]
    (nb_dir / "hw.ipynb").write_text(__import__("json").dumps({"cells": cells, "metadata": {}, "nbformat": 4,
                                                               "nbformat_minor": 5}))
    monkeypatch.setattr(ll, "REPO", tmp_path)
    links = ll.notebook_links(nb_dir / "hw.ipynb")
    assert [(link.target.split("/")[-1], link.anchor) for link in links] == [
        ("ch.md", "sec-a"), ("ch.md", "eq-x"), ("ch.md", "thm-t"), ("ch.md", ""), ("ch.md", "sec-b"), ("no.md", "sec-a"),
        ("ch.md", "Best-of-$n$,-and-code"), ("ch.md", "not-a-heading")]
    problems = [link.problem() for link in links]
    assert problems[:4] == [None] * 4 and problems[6] is None
    assert "no heading, target or label 'sec-b'" in problems[4] and "is not a file" in problems[5]
    assert "'not-a-heading'" in problems[7], "a comment in a code block is not a heading"
    assert ll.headings(tmp_path / "lectures" / "ch.md") == {"A": "sec-a", "Best-of-$n$,-and-code": "sec-b2"}


# Stubs whose Markdown does not yet link the lecture equation they implement ("<id>:<grade_id>"), each to be removed
# by the commit that adds the link.
STUBS_UNLINKED: set[str] = set()


def test_every_stubs_markdown_links_the_lecture_it_implements():
    import nbformat

    missing = set()
    for nb_path in sorted((ll.REPO / "solutions").glob("*/*.ipynb")):
        if nb_path.parent.name == "hw0_setup":  # the tour of the course: no lecture behind its two stubs
            continue
        cells = nbformat.read(nb_path, as_version=4).cells
        for i, cell in enumerate(cells):
            if cell.cell_type == "code" and cell.metadata.get("nbgrader", {}).get("solution"):
                text = next(c.source for c in reversed(cells[:i]) if c.cell_type == "markdown")
                if "../../lectures/" not in text:
                    missing.add(f"{nb_path.parent.name}:{cell.metadata['nbgrader']['grade_id']}")
    assert not missing - STUBS_UNLINKED, f"stubs whose Markdown links no lecture: {sorted(missing - STUBS_UNLINKED)}"
    assert not STUBS_UNLINKED - missing, f"STUBS_UNLINKED names stubs that now link (remove them): {sorted(STUBS_UNLINKED - missing)}"
