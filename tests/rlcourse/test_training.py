"""rlcourse.training: the log, the evaluation hook and the copies the fine-tuning loops share."""
from __future__ import annotations

import torch
from torch import nn

from rlcourse.training import EvaluationHook, TrainingLog, due, fine_tuning_copies


def test_evaluation_hook_records_a_row_in_eval_mode_and_restores_train_mode(capsys):
    log, model, modes = TrainingLog(config={}), nn.Linear(2, 1).train(), []
    hook = EvaluationHook(log, lambda m: modes.append(m.training) or {"return": 3.0}, verbose=True)
    hook(model, 40)
    assert modes == [False] and model.training
    assert log.evals == [{"step": 40, "time": log.evals[0]["time"], "return": 3.0}]
    assert 0 <= log.evals[0]["time"] <= hook.elapsed()
    assert capsys.readouterr().out == "  step      40  return 3\n"


def test_evaluation_hook_without_evaluate_does_nothing():
    log = TrainingLog(config={})
    EvaluationHook(log, None)(nn.Linear(2, 1), 0)
    assert log.evals == []


def test_due_on_multiples_and_on_the_last_iteration():
    assert [i for i in range(1, 11) if due(i, 4, 10)] == [4, 8, 10]


def test_fine_tuning_copies_train_one_and_freeze_the_other():
    policy, reference = nn.Linear(2, 1).eval(), nn.Linear(2, 1).train()
    actor, frozen = fine_tuning_copies(policy, reference)
    assert actor is not policy and frozen is not reference
    assert actor.training and all(p.requires_grad for p in actor.parameters())
    assert not frozen.training and not any(p.requires_grad for p in frozen.parameters())
    assert not policy.training and reference.training, "the caller's modules are left as they were"
    assert torch.equal(actor.weight, policy.weight) and torch.equal(frozen.weight, reference.weight)
