"""Sharded batches: the split by name, shards graded in separate processes and merged, and every refusal."""
from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.core.batch import Shard
from autograder.outputs.merge import MergeRefused, merge
from conftest import REPO

SAMPLES = REPO / "autograder/samples/hw0_setup"
KINDS = ["complete", "partial", "untouched", "broken_syntax", "broken_exception"]


def test_shard_parse_accepts_k_of_n_and_refuses_the_rest():
    assert Shard.parse("2/3") == Shard(2, 3) and Shard.parse(" 1 / 1 ") == Shard(1, 1)
    for bad in ("0/3", "4/3", "3", "a/b", "-1/2", "2/0", ""):
        with pytest.raises(ValueError, match="K/N"):
            Shard.parse(bad)


def test_every_name_falls_in_exactly_one_shard_the_same_way_every_time():
    names = [f"student{i:03d}" for i in range(300)] + ["alice_smith", "bob-2", "a_va"]
    for n in (1, 2, 3, 7):
        owners = [[k for k in range(1, n + 1) if Shard(k, n).owns(name)] for name in names]
        assert all(len(o) == 1 for o in owners), f"N = {n}: a name owned by none or by two shards"
        sizes = [sum(o == [k] for o in owners) for k in range(1, n + 1)]
        assert min(sizes) > len(names) / n / 2, f"N = {n}: a lopsided split {sizes}"
    # A hash of the name alone: the order in which names are met, or other names present, change nothing.
    assert [Shard(2, 3).owns(n) for n in names] == [Shard(2, 3).owns(n) for n in list(reversed(names))][::-1]


def _batch(folder: Path, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out),
                             "--jobs", "1", *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as f:
        return list(csv.reader(f))


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """One class of hw0 graded unsharded, and as 3 shards in 3 processes: shards 1 and 2 share a folder."""
    root = tmp_path_factory.mktemp("shards")
    folder = root / "class"
    folder.mkdir()
    for i in range(7):
        shutil.copy(SAMPLES / f"{KINDS[i % len(KINDS)]}.ipynb", folder / f"student{i:02d}.ipynb")
    (folder / "no_notebook_here").mkdir()
    runs = [_batch(folder, root / "whole"), _batch(folder, root / "shared", "--shard", "1/3"),
            _batch(folder, root / "shared", "--shard", "2/3"), _batch(folder, root / "own", "--shard", "3/3")]
    for run in runs:
        output = run.communicate(timeout=900)[0]
        assert run.returncode == 0, output[-3000:]
    return root


@pytest.mark.slow
def test_three_shards_merged_equal_the_unsharded_batch_row_by_row(graded, tmp_path):
    shared, own = graded / "shared", graded / "own"
    assert (shared / "gradebook-1-of-3.csv").exists() and (own / "gradebook-3-of-3.csv").exists()
    assert not (shared / "gradebook.csv").exists(), "a shard writes its own gradebook, never the class's"
    merged = tmp_path / "merged"
    results = merge("hw0_setup", [shared, own], merged)
    whole = _rows(graded / "whole" / "gradebook.csv")
    assert _rows(merged / "gradebook.csv") == whole
    assert len(results) == len(whole) - 1 == 8, "every submission once, the ungradable one included"
    for row in whole[1:]:  # and each submission's folder came along, with its feedback
        assert (merged / row[0] / "result.json").exists() and (merged / row[0] / "feedback.md").exists()
    # Merging into the shared folder itself copies nothing it holds already, and gives the same gradebook.
    merge("hw0_setup", [shared, own], shared)
    assert _rows(shared / "gradebook.csv") == whole


def _copy(graded: Path, tmp_path: Path) -> tuple[Path, Path]:
    shared, own = tmp_path / "shared", tmp_path / "own"
    shutil.copytree(graded / "shared", shared)
    shutil.copytree(graded / "own", own)
    return shared, own


@pytest.mark.slow
def test_merge_refuses_what_is_not_one_class(graded, tmp_path):
    shared, own = _copy(graded, tmp_path)
    out = tmp_path / "out"
    with pytest.raises(MergeRefused, match="3/3 missing"):
        merge("hw0_setup", [shared], out)
    with pytest.raises(MergeRefused, match="more than once"):
        merge("hw0_setup", [shared, own, own], out)
    with pytest.raises(SystemExit, match="unknown or ungradable"):
        merge("hw9_nothing", [shared, own], out)

    manifest = own / "_batch-3-of-3.json"
    data = json.loads(manifest.read_text())
    manifest.write_text(json.dumps(dict(data, suite_version="0123456789abcdef")))
    with pytest.raises(MergeRefused, match="different versions of the suite"):
        merge("hw0_setup", [shared, own], out)
    manifest.write_text(json.dumps(dict(data, folder_digest="feedfeedfeedfeed")))
    with pytest.raises(MergeRefused, match="different folders"):
        merge("hw0_setup", [shared, own], out)
    manifest.write_text(json.dumps(dict(data, submissions=data["submissions"] + ["student00"])))
    with pytest.raises(MergeRefused, match="graded by both"):
        merge("hw0_setup", [shared, own], out)
    manifest.write_text(json.dumps(data))

    name = data["submissions"][0]
    result = own / name / "result.json"
    saved = result.read_text()
    result.write_text(json.dumps(dict(json.loads(saved), suite_version="0123456789abcdef")))
    with pytest.raises(MergeRefused, match="regrade it"):
        merge("hw0_setup", [shared, own], out)
    result.unlink()
    with pytest.raises(MergeRefused, match="has not finished"):
        merge("hw0_setup", [shared, own], out)
    assert not out.exists() or not any(out.iterdir()), "a refused merge writes nothing"
    result.write_text(saved)
    assert len(merge("hw0_setup", [shared, own], out)) == 8


def test_merge_refuses_a_folder_without_shards(tmp_path):
    with pytest.raises(MergeRefused, match="no shard manifest"):
        merge("hw0_setup", [tmp_path], tmp_path / "out")
