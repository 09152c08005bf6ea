"""The MANIFEST loader: each kind of damage gets a message that names the file and the fix."""
from __future__ import annotations

import json
import shlex
import sys

import numpy as np
import pytest

from rlcourse import data


@pytest.fixture
def root(tmp_path):
    (tmp_path / "MANIFEST.json").write_text('{"files": {}}')
    np.savez(tmp_path / "demo.npz", x=np.arange(5))
    data.add(tmp_path / "demo.npz", command="python make_demo.py", seed=3, info_={"n": 5}, root=tmp_path)
    return tmp_path


def test_a_verified_file_loads(root):
    assert data.load_npz("demo.npz", root)["x"].tolist() == [0, 1, 2, 3, 4]
    entry = data.info("demo.npz", root)
    assert entry["seed"] == 3 and entry["command"] == "python make_demo.py" and entry["info"] == {"n": 5}
    assert data.check_all(root) == []


def test_missing_file(root):
    (root / "demo.npz").unlink()
    with pytest.raises(data.DatasetError, match=r"datasets/demo.npz is missing: regenerate it with `python make_demo"):
        data.load_npz("demo.npz", root)


def test_truncated_file(root):
    raw = (root / "demo.npz").read_bytes()
    (root / "demo.npz").write_bytes(raw[:-10])
    with pytest.raises(data.DatasetError, match="truncated"):
        data.verify("demo.npz", root)


def test_altered_file(root):
    raw = bytearray((root / "demo.npz").read_bytes())
    raw[-1] ^= 0xFF
    (root / "demo.npz").write_bytes(bytes(raw))
    with pytest.raises(data.DatasetError, match="altered"):
        data.verify("demo.npz", root)
    assert any("altered" in p for p in data.check_all(root))


def test_unlisted_files(root):
    with pytest.raises(data.DatasetError, match="not listed"):
        data.verify("other.npz", root)
    np.save(root / "stray.npy", np.zeros(2))
    assert any("stray.npy is not listed" in p for p in data.check_all(root))


def test_the_shipped_manifest_verifies():
    assert data.check_all() == []
    assert json.loads((data.DATASETS / "MANIFEST.json").read_text())["files"] is not None


def test_record_writes_the_exact_command_quoted_and_relative_to_the_repository(root, monkeypatch):
    script = data.REPO / "datasets" / "scripts" / "make_items.py"
    np.savez(root / "other.npz", x=np.zeros(2))
    entry = data.record(root / "other.npz", script, ["--note", "it's two words", "--seed", "4"], seed=4, root=root)
    assert entry["command"] == "python datasets/scripts/make_items.py --note 'it'\"'\"'s two words' --seed 4"
    assert shlex.split(entry["command"])[3] == "it's two words" and data.info("other.npz", root)["seed"] == 4
    monkeypatch.setattr(sys, "argv", ["/anywhere/make_items.py", "--seed", "0"])
    assert data.script_command(script) == "python datasets/scripts/make_items.py --seed 0"


def test_every_shipped_command_is_a_whole_command_line_of_a_script_in_the_repository():
    for name, entry in data.read_manifest().items():
        words = shlex.split(entry["command"])
        assert words[0] == "python" and "..." not in words, f"{name}: {entry['command']}"
        assert (data.REPO / words[1]).is_file(), f"{name}: {words[1]} does not exist"
