"""rlcourse.checkpoint: one format (config, state_dict, metadata) for every saved model, written atomically."""
from __future__ import annotations

import hashlib

import pytest
import torch
from torch import nn

import rlcourse.checkpoint as ck
from rlcourse import data
from rlcourse.checkpoint import Checkpoint, atomic_save, load_checkpoint, load_model, save_checkpoint, save_model


class Tiny(nn.Module):
    def __init__(self, n_in: int, n_out: int):
        super().__init__()
        self.lin = nn.Linear(n_in, n_out)


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_model_round_trip_keeps_weights_config_and_metadata(tmp_path):
    torch.manual_seed(0)
    model = Tiny(3, 2)
    save_model(model, tmp_path / "sub" / "m.pt", {"n_in": 3, "n_out": 2}, steps=10, note="x")
    back = load_model(tmp_path / "sub" / "m.pt", Tiny)
    assert isinstance(back, Tiny) and not back.training
    assert back.metadata == {"steps": 10, "note": "x"}
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), back.state_dict().values()))
    raw = load_checkpoint(tmp_path / "sub" / "m.pt")
    assert raw.config == {"n_in": 3, "n_out": 2} and set(raw.state_dict) == {"lin.weight", "lin.bias"}
    assert [p.name for p in (tmp_path / "sub").iterdir()] == ["m.pt"], "no temporary file is left behind"


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "m.pt"
    save_checkpoint(path, Checkpoint({"n_in": 1, "n_out": 1}, Tiny(1, 1).state_dict(), {"version": 1}))
    before = _digest(path)
    with pytest.raises(Exception):  # a lambda cannot be pickled: torch.save fails after it began writing
        atomic_save({"config": {"f": lambda: 0}, "state_dict": {}, "metadata": {}}, path)
    assert _digest(path) == before and load_checkpoint(path).metadata == {"version": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["m.pt"]


def test_a_crash_mid_write_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "m.pt"
    save_model(Tiny(2, 2), path, {"n_in": 2, "n_out": 2}, version=1)
    before = _digest(path)
    real_save = torch.save

    def half_then_die(obj, f):
        real_save(obj, f)
        f.truncate(f.tell() // 2)
        raise KeyboardInterrupt  # the process is stopped half-way through the write

    monkeypatch.setattr(ck.torch, "save", half_then_die)
    with pytest.raises(KeyboardInterrupt):
        save_model(Tiny(2, 2), path, {"n_in": 2, "n_out": 2}, version=2)
    monkeypatch.undo()
    assert _digest(path) == before and load_model(path, Tiny).metadata == {"version": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["m.pt"]


def test_every_shipped_model_is_in_the_one_format():
    names = [n for n in data.read_manifest() if n.endswith(".pt")]
    assert {"lm/sft.pt", "hw4/reference_policy.pt", "hw4/reward_model.pt", "experts/Hopper-v5/expert.pt"} <= set(names)
    for name in names:
        checkpoint = load_checkpoint(data.verify(name))
        assert isinstance(checkpoint.config, dict) and checkpoint.state_dict, name
        assert all(isinstance(v, torch.Tensor) for v in checkpoint.state_dict.values()), name
