"""What the course's training loops share: the log they return, and the evaluation hook they call.

:func:`rlcourse.ppo.ppo` and :func:`rlcourse.rlhf.train_dpo` both fine-tune a copy of a policy
against a frozen reference (:func:`fine_tuning_copies`), call a caller's ``evaluate(policy) -> dict``
every so often (:class:`EvaluationHook`, :func:`due`), and return a :class:`TrainingLog` whose rows a
notebook plots with :meth:`TrainingLog.series`.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from torch import nn


@dataclass
class TrainingLog:
    """What a training loop records: its ``config``, and one dict per evaluation in ``evals``
    (``step``, ``time`` and what ``evaluate`` returned). Subclasses add their per-update rows."""

    config: dict
    evals: list[dict] = field(default_factory=list)

    def series(self, key: str, source: str = "evals") -> tuple[np.ndarray, np.ndarray]:
        """``(steps, values)`` of ``key`` over the rows of ``source`` that have it (each row has a ``step``)."""
        rows = [r for r in getattr(self, source) if key in r]
        return np.array([r["step"] for r in rows]), np.array([r[key] for r in rows], dtype=float)


class EvaluationHook:
    """``hook(model, step)`` runs ``evaluate(model)`` with the model in eval mode (train mode after),
    appends ``{"step", "time", **result}`` to ``log.evals`` and, when ``verbose``, prints the result on one line.

    ``time`` is seconds since the hook was made; :meth:`elapsed` gives the same clock to the loop's own rows.
    With ``evaluate=None`` the hook does nothing.
    """

    def __init__(self, log: TrainingLog, evaluate: Optional[Callable[[nn.Module], dict]], verbose: bool = True):
        self.log, self.evaluate, self.verbose = log, evaluate, verbose
        self.start = time.perf_counter()

    def elapsed(self) -> float:
        """Seconds since the hook was made."""
        return time.perf_counter() - self.start

    def __call__(self, model: nn.Module, step: int) -> None:
        if self.evaluate is None:
            return
        result = self.evaluate(model.eval())
        model.train()
        self.log.evals.append({"step": step, "time": self.elapsed(), **result})
        if self.verbose:
            print(f"  step {step:>7d}  " + "  ".join(f"{k} {v:.3g}" for k, v in result.items()), flush=True)


def due(count: int, every: int, last: int) -> bool:
    """Whether iteration ``count`` (counted from 1) is a multiple of ``every`` or the ``last`` one."""
    return count % every == 0 or count == last


def fine_tuning_copies(policy: nn.Module, reference: nn.Module) -> tuple[nn.Module, nn.Module]:
    """``(actor, reference)``: a trainable copy of ``policy`` in train mode and a frozen copy of
    ``reference`` in eval mode; the caller's modules are left as they are."""
    actor = copy.deepcopy(policy).train().requires_grad_(True)
    return actor, copy.deepcopy(reference).eval().requires_grad_(False)
