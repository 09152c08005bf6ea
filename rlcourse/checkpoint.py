"""One file format for every trained model the course saves: policies, reward models, language models.

A checkpoint is the dict ``{"config": ..., "state_dict": ..., "metadata": ...}``: ``config`` holds the
constructor arguments (plain values), ``state_dict`` the tensors, ``metadata`` plain values about the
run (measured return, steps, seed). It is read back with ``torch.load(weights_only=True)``, so loading
never unpickles arbitrary objects. :func:`rlcourse.nets.save_policy`,
:func:`rlcourse.rlhf.save_reward_model` and :func:`rlcourse.lm.save_lm` all write it.

Every write is atomic (:func:`atomic_save`): the bytes go to a temporary file beside the target, are
flushed to disk, and the temporary file is renamed over the target with ``os.replace``. A crash or an
exception mid-write leaves the old file (or no file) in place, never a truncated one.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TypeVar

import torch
from torch import nn

Model = TypeVar("Model", bound=nn.Module)


@dataclass
class Checkpoint:
    """The three parts of a checkpoint file."""

    config: dict[str, Any]
    """constructor arguments of the model (plain values only)"""
    state_dict: dict[str, torch.Tensor]
    """the model's ``state_dict()``"""
    metadata: dict[str, Any] = field(default_factory=dict)
    """plain values about how the model was made and how well it does"""


def atomic_save(obj: Any, path: str | Path) -> None:
    """``torch.save(obj)`` to ``path`` through a temporary file in the same folder and ``os.replace``.

    Makes the folder if needed. If writing fails, the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(obj, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_checkpoint(path: str | Path, checkpoint: Checkpoint) -> None:
    """Write ``checkpoint`` to ``path`` atomically."""
    atomic_save({"config": checkpoint.config, "state_dict": checkpoint.state_dict,
                 "metadata": dict(checkpoint.metadata)}, path)


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint file (tensors and plain values only, on the CPU)."""
    blob = torch.load(Path(path), map_location="cpu", weights_only=True)
    return Checkpoint(config=blob["config"], state_dict=blob["state_dict"], metadata=dict(blob.get("metadata", {})))


def save_model(model: nn.Module, path: str | Path, config: dict[str, Any], **metadata: Any) -> None:
    """Save ``model``'s weights with ``config`` (what rebuilds it: see :func:`load_model`) and ``metadata``."""
    save_checkpoint(path, Checkpoint(config, model.state_dict(), metadata))


def load_model(path: str | Path, build: Callable[..., Model]) -> Model:
    """The model saved at ``path``: ``build(**config)`` with the saved weights, ``.metadata`` set, in eval mode."""
    checkpoint = load_checkpoint(path)
    model = build(**checkpoint.config)
    model.load_state_dict(checkpoint.state_dict)
    model.metadata = checkpoint.metadata
    return model.eval()
