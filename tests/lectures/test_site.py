"""The lecture site builds from scratch with no warning, every formula parses, nothing loads remotely."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it


@pytest.mark.skipif(shutil.which("node") is None, reason="the formula check needs Node.js")
def test_site_builds_cleanly_offline(tmp_path):
    book = Path(sys.executable).parent / "jupyter-book"
    build = subprocess.run([str(book), "build", str(REPO / "lectures"), "--path-output", str(tmp_path),
                            "--warningiserror", "--nitpick", "--keep-going"], capture_output=True, text=True,
                           timeout=900)
    assert build.returncode == 0, (build.stdout + build.stderr)[-4000:]
    html = tmp_path / "_build" / "html"
    assert (html / "03_maxent_irl.html").exists() and (html / "search.html").exists()
    check = subprocess.run([sys.executable, str(REPO / "lectures/check_site.py"), str(html)], capture_output=True,
                           text=True, timeout=600)
    assert check.returncode == 0, check.stdout[-3000:] + check.stderr[-2000:]
    assert "0 math errors, 0 remote resources" in check.stdout
    # every chapter ends with its assignment's notebook, downloadable from the site
    import re

    import nbformat

    for chapter in sorted((REPO / "lectures").glob("0*.md")):
        page = (html / f"{chapter.stem}.html").read_text(encoding="utf-8")
        links = re.findall(r'<a class="reference download internal" download="" href="(_downloads/[^"]+\.ipynb)"', page)
        assert links, f"{chapter.name}: no link to its assignment's notebook on the site"
        for link in links:
            nb = nbformat.read(html / link, as_version=4)
            assert any(c.metadata.get("nbgrader", {}).get("solution") for c in nb.cells), f"{link} is not a student notebook"
