"""The MANIFEST loader: each kind of damage gets a message that names the file and the fix."""
from __future__ import annotations

import json

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
