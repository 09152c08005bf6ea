"""Text a submission controls never stops a writer (issue 35): lone surrogates, invalid UTF-8 file names,
NUL and very long messages reach every output encodable, through ``grade``, the batch, Gradescope's and
PrairieLearn's entry points."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import FIXTURE_COURSE, with_cells

pytestmark = pytest.mark.slow

HOSTILE = r'''
def scaled_sum(x):
    raise ValueError("lone \ud800 surrogate, a NUL \x00, an escape \x1b[2J and " + "very long " * 50_000)
'''
BAD_NAME = os.fsdecode(b"caf\xe9 \xff\xfe")  # not UTF-8: Python holds it as lone surrogates


def _submission(folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    return with_cells(FIXTURE_COURSE / "assignments/fx/fx.ipynb", folder / f"{name}.ipynb", {"scaled_sum": HOSTILE})


def _env() -> dict[str, str]:
    return {**os.environ, "RLCOURSE_REPO": str(FIXTURE_COURSE)}


def _readable(path: Path) -> str:
    text = path.read_bytes().decode("utf-8")  # strict: the file is valid UTF-8
    assert "\ud800" not in text and "\x00" not in text
    return text


def test_batch_and_grade_write_every_output_for_hostile_text(open_tmp):
    folder = open_tmp / "class"
    _submission(folder, BAD_NAME)
    _submission(folder, "plain")
    out = open_tmp / "out"
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "fx", str(folder), "--out", str(out),
                           "--jobs", "1"], env=_env(), capture_output=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = list(csv.DictReader(_readable(out / "gradebook.csv").splitlines()))
    assert len(rows) == 2 and {r["status"] for r in rows} == {"graded"}
    for sub in (p for p in out.iterdir() if p.is_dir() and not p.name.startswith("_")):
        for name in ("result.json", "results.json", "feedback.md"):
            text = _readable(sub / name)
            assert len(text) < 200_000, f"{name} is not capped"
        json.loads(_readable(sub / "results.json"))
    one = open_tmp / "one"
    done = subprocess.run([sys.executable, "-m", "autograder", "grade", "fx", str(folder / f"{BAD_NAME}.ipynb"),
                           "--out", str(one)], env=_env(), capture_output=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    done.stdout.decode("utf-8")
    assert (one / "results.json").exists() and (one / "feedback.md").exists()


def test_gradescope_and_prairielearn_write_results_for_hostile_text(open_tmp, monkeypatch):
    from autograder.core import course
    from autograder.outputs import gradescope, prairielearn

    monkeypatch.setattr(course, "REPO", FIXTURE_COURSE)
    monkeypatch.setenv("RLCOURSE_REPO", str(FIXTURE_COURSE))
    gs = open_tmp / "gs"
    _submission(gs / "submission", BAD_NAME)
    assert gradescope.run("fx", gs) == 0
    json.loads(_readable(gs / "results" / "results.json"))
    pl = open_tmp / "pl"
    _submission(pl / "student", BAD_NAME)
    assert prairielearn.run("fx", pl) == 0
    results = json.loads(_readable(pl / "results" / "results.json"))
    assert results["gradable"] is True and len(json.dumps(results)) < 1_000_000


@pytest.mark.parametrize("hidden", ["\u00ad", "\u034f", "\u115f", "\u180e", "\u2060", "\u2064", "\u3164", "\ufe0f",
                                    "\U000e0041", "\U000e007f"])
def test_invisible_characters_are_shown_as_question_marks(hidden):
    """Red team B passed Unicode tags, joiners and fillers through into feedback.md and results.json: text that
    shows nothing where a student wrote something. Visible text (accents, emoji) is kept."""
    from autograder.outputs.text import markdown_text, plain

    assert plain(f"score{hidden}8/8") == "score?8/8"
    assert hidden not in markdown_text(f"a{hidden}b")
    assert plain("é 😀 ∑") == "é 😀 ∑"
