"""README is a newcomer's page: short, its two commands real, its layout and its links true."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import REPO

README = REPO / "README.md"
DOCS = sorted((REPO / "docs").rglob("*.md"))
PAGES = [README, REPO / "CONTRIBUTING.md", *DOCS]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")


def makefile_targets() -> dict[str, str]:
    """Each target of the Makefile and its recipe."""
    targets, current = {}, None
    for line in (REPO / "Makefile").read_text().splitlines():
        match = re.match(r"^([a-z][\w-]*):", line)
        if match:
            current = match.group(1)
            targets[current] = ""
        elif current and line.startswith("\t"):
            targets[current] += line.strip() + "\n"
        elif not line.strip():
            current = None
    return targets


def slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, flags=re.M)}


def test_readme_is_short_and_opens_with_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 200
    first_block = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1)
    commands = [line.split("#")[0].strip() for line in first_block.splitlines() if line.strip()]
    assert commands == ["make demo", "make test"]
    assert text.index("```bash") < text.index("## "), "the commands come before anything else"


def test_the_two_commands_are_the_makefiles_and_ci_runs_the_second():
    targets = makefile_targets()
    assert "-m autograder demo" in targets["demo"]
    assert "-m pytest" in targets["test"]
    ci = [line for line in (REPO / ".ci" / "run").read_text().splitlines() if line and not line.startswith("#")]
    assert "make test" in ci


def test_every_make_target_the_readme_names_exists():
    targets = makefile_targets()
    named = set(re.findall(r"`make ([a-z][\w-]*)", README.read_text()))
    assert named and named <= set(targets), named - set(targets)


def test_the_layout_names_every_room_of_the_grader_and_every_top_level_folder():
    text = README.read_text()
    layout = re.search(r"## Layout\n+```\n(.*?)```", text, flags=re.S).group(1)
    rooms = [p.name for p in (REPO / "autograder").iterdir() if p.is_dir() and not p.name.startswith("_")]
    assert rooms
    for room in rooms:
        assert re.search(rf"^\s+{room}/", layout, flags=re.M), f"README's layout does not name autograder/{room}/"
    assert "suite.py" in layout
    for folder in ("rlcourse", "lectures", "solutions", "assignments", "datasets", "bench", "tests", "docs"):
        assert re.search(rf"\b{folder}/", layout), f"README's layout does not name {folder}/"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_and_anchor_resolves(page):
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    for target in LINK.findall(text):
        if re.match(r"^[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        resolved = (page.parent / path).resolve() if path else page
        assert resolved.exists(), f"{page.relative_to(REPO)} links to {target}, which does not exist"
        if anchor and resolved.suffix == ".md":
            assert anchor in anchors(resolved), f"{page.relative_to(REPO)} links to {target}: no such heading"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_test_file_and_grader_module_a_page_names_exists(page):
    """Pages name tests (the project's or a hidden suite's) by file name and grader modules by path."""
    text = page.read_text()
    tests = {p.name for folder in ("tests", "autograder/suites") for p in (REPO / folder).rglob("test_*.py")}
    for name in set(re.findall(r"\b(test_[A-Za-z0-9_*]+\.py)\b", text)):
        pattern = re.compile(re.escape(name).replace(r"\*", ".*") + "$")
        assert any(pattern.match(t) for t in tests), f"{page.relative_to(REPO)} names {name}, which is in neither tests/ nor a hidden suite"
    for module in set(re.findall(r"`(autograder/[\w/]+\.py)`", text)):
        assert (REPO / module).exists() or "suites/<id>" in module, f"{page.relative_to(REPO)} names {module}, which does not exist"


def test_every_benchmark_script_has_a_row_in_docs_benchmarks():
    """docs/benchmarks.md is where a contributor looks for how to run a benchmark: each script in bench/ has its row."""
    table = (REPO / "docs" / "benchmarks.md").read_text()
    scripts = sorted(p.name for p in (REPO / "bench").glob("bench_*.py"))
    assert scripts, "no benchmark scripts found"
    missing = [name for name in scripts if f"`{name}" not in table and f"bench/{name}" not in table]
    assert not missing, f"docs/benchmarks.md has no row for {missing}"
