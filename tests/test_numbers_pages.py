"""The numbers pages (docs/numbers/) agree with bench/results/, and the check would see it if they did not."""
from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

from conftest import REPO

RESULTS = REPO / "bench" / "results"
PAGES = REPO / "docs" / "numbers"


def load_generator():
    spec = importlib.util.spec_from_file_location("numbers_pages", REPO / "bench" / "numbers_pages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


numbers_pages = load_generator()


def first_number(value, path=()):
    """The path to the first finite float (or int that is not a bool) in a JSON value, depth first."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    else:
        return path if isinstance(value, (int, float)) and not isinstance(value, bool) else None
    for key, item in items:
        if key == "meta":
            continue
        found = first_number(item, path + (key,))
        if found is not None:
            return found
    return None


def test_every_committed_page_matches_its_results_file(tmp_path):
    """Regenerated in a temporary folder, every page equals the committed one, and no page is missing or stale."""
    assert numbers_pages.main(["--out", str(tmp_path)]) == 0
    generated = sorted(p.name for p in tmp_path.glob("*.md"))
    committed = sorted(p.name for p in PAGES.glob("*.md"))
    assert generated == committed, "docs/numbers/ has missing or stale pages: run `make numbers` and commit them"
    for name in generated:
        assert (PAGES / name).read_text() == (tmp_path / name).read_text(), \
            f"docs/numbers/{name} disagrees with bench/results/: run `make numbers` and commit the page"
    assert numbers_pages.differences(numbers_pages.render_all(RESULTS), PAGES) == []


def test_a_changed_figure_in_a_results_file_is_caught(tmp_path):
    """Plant a different number in a copy of each results file in turn: the check names exactly that page."""
    sources = sorted(p for p in RESULTS.glob("*.json") if not p.name.endswith(".partial.json"))
    assert sources, "no results files to check"
    pages = tmp_path / "pages"
    numbers_pages.write(numbers_pages.render_all(RESULTS), pages)
    assert numbers_pages.differences(numbers_pages.render_all(RESULTS), pages) == []
    for source in sources:
        results = tmp_path / source.stem
        shutil.copytree(RESULTS, results)
        data = json.loads(source.read_text())
        path = first_number(data)
        if path is None:
            continue
        holder = data
        for key in path[:-1]:
            holder = holder[key]
        holder[path[-1]] = holder[path[-1]] * 3 + 7.25
        (results / source.name).write_text(json.dumps(data))
        problems = numbers_pages.differences(numbers_pages.render_all(results), pages)
        assert any(f"{source.stem}.md" in p for p in problems), f"a changed {path} in {source.name} went unseen"
        assert all(f"{source.stem}.md" in p for p in problems), problems


def test_a_hand_edited_page_and_a_stale_page_are_caught(tmp_path):
    pages = tmp_path / "numbers"
    numbers_pages.write(numbers_pages.render_all(RESULTS), pages)
    victim = pages / "class_throughput.md"
    text = victim.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| hw0_setup"))
    victim.write_text(text.replace(row, row.replace("| 20 |", "| 21 |", 1)))
    assert victim.read_text() != text
    stale = pages / "gone.md"
    stale.write_text(numbers_pages.MARK.format(source="bench/results/gone.json") + "\n")
    hand_written = pages / "notes.md"
    hand_written.write_text("# a page nobody generated\n")
    problems = numbers_pages.differences(numbers_pages.render_all(RESULTS), pages)
    assert any("class_throughput.md" in p and "differs" in p for p in problems)
    assert any("gone.md" in p for p in problems)
    assert not any("notes.md" in p for p in problems), "only generated pages are the generator's business"
    assert numbers_pages.main(["--out", str(pages), "--check"]) == 1


def test_new_keys_appear_without_code_and_provenance_comes_from_meta(tmp_path):
    """A key no renderer knows is shown; meta gives commit, date and load; a file without it says so."""
    results = tmp_path / "results"
    results.mkdir()
    (results / "newbench.json").write_text(json.dumps({
        "meta": {"commit": "abc1234", "date": "2026-12-03", "load": [1.5, 2.25, 3.0], "machine": "2-core CPU"},
        "knob": 0.125,
        "per_seed": {"0": {"gold": 1.0, "curve": [1, 2]}, "1": {"gold": 3.0, "curve": [3, 4]}},
        "runs": [{"name": "a", "score": 41.5, "detail": {"x": [1, 2, {"y": 3}]}}],
        "section": {"meta": {"commit": "def5678", "date": "2026-12-04", "load": [9.0, 8.0, 7.0]}, "figure": 12.5},
    }))
    (results / "oldbench.json").write_text(json.dumps({"value": 2.5}))
    pages = numbers_pages.render_all(results)
    new = pages["newbench.md"]
    assert "`knob`" in new and "0.125" in new
    assert "2.0 ± 1.0" in new, "a seed dict gets its mean ± sd row"
    assert "41.5" in new and '"y": 3' in new, "nested values reach the page as a JSON listing"
    assert "commit `abc1234`, 2026-12-03, load average 1.50 / 2.25 / 3.00" in new
    assert "commit `def5678`, 2026-12-04, load average 9.00 / 8.00 / 7.00" in new and "12.5" in new
    old = pages["oldbench.md"]
    assert "2.5" in old and "not recorded" in old
    assert "[newbench](newbench.md)" in pages["README.md"] and "[oldbench](oldbench.md)" in pages["README.md"]


@pytest.mark.parametrize("value, text", [(3265.434, "3,265"), (0.8658453, "0.8658"), (None, "–"), (True, "yes"),
                                         (float("inf"), "inf"), (12345, "12,345"), (0.00012, "0.00012")])
def test_values_are_written_as_the_pages_show_them(value, text):
    assert numbers_pages.fmt(value) == text


def test_mean_and_sd_keep_the_sds_precision():
    assert numbers_pages.mean_sd([3265.4, 3209.8, 1627.9]) == "2,701 ± 759"
    assert numbers_pages.mean_sd([1.0, float("inf"), None]) == "1, inf, –", "no seed is dropped from a mean"


def test_the_experts_page_follows_the_manifest(tmp_path):
    """A changed expert return in a copy of datasets/MANIFEST.json changes experts.md, and the check sees it."""
    manifest = json.loads((REPO / "datasets" / "MANIFEST.json").read_text())
    name = next(n for n in manifest["files"] if n.startswith("experts/") and "return_mean" in manifest["files"][n]["info"])
    manifest["files"][name]["info"]["return_mean"] += 123.0
    planted = tmp_path / "MANIFEST.json"
    planted.write_text(json.dumps(manifest))
    pages = tmp_path / "pages"
    numbers_pages.write(numbers_pages.render_all(RESULTS), pages)
    problems = numbers_pages.differences(numbers_pages.render_all(RESULTS, planted), pages)
    assert problems and all("experts.md" in p for p in problems), problems
