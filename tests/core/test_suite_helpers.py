"""The hidden suites reach the sandbox through helpers in plain Python (issue 33), and those helpers gather raw
data only (issue 35): no suite evaluates code in strings, the shared helpers of ``sandbox_common.py`` do what
their docstrings say, and every suite's helpers run after them in one module, as the grader runs them."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
import torch

from autograder.core import course

SUITES = Path(course.INSTALLED) / "autograder" / "suites"
COMMON = SUITES / "sandbox_common.py"


def code_in_strings(source: str) -> list[str]:
    """Calls in ``source`` that send code in a string to a namespace: ``x.eval("...")``, ``in_sandbox("...")``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call) or not node.args:
            continue
        name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        if name in ("eval", "in_sandbox") and isinstance(node.args[0], (ast.Constant, ast.JoinedStr, ast.BinOp, ast.Name)):
            found.append(f"line {node.lineno}: {ast.unparse(node)[:80]}")
    return found


def test_the_check_finds_code_in_strings():
    planted = 'x = student.eval("GaussianPolicy(3, 2)")\ny = reference.eval(f"f({a})", a=1)\nz = in_sandbox(EXPR)\n'
    assert len(code_in_strings(planted)) == 3
    assert code_in_strings("policy.eval()\nstudent.helpers.build('rlcourse.nets.GaussianPolicy', 3, 2)\n") == []


@pytest.mark.parametrize("path", sorted(SUITES.glob("*/*.py")), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_no_suite_sends_code_in_strings(path):
    assert code_in_strings(path.read_text()) == [], "build objects and gradients with the suite's helpers instead"


def _helpers(*sources: str, notebook: dict | None = None) -> dict:
    """The helpers module as the grader builds it: the sources run, in order, in one namespace."""
    scope = {"__name__": "suite_helpers", "notebook": notebook if notebook is not None else {}}
    for source in sources:
        exec(compile(source, "<helpers>", "exec"), scope)
    return scope


def _suite_helpers() -> list[Path]:
    return sorted(SUITES.glob("*/sandbox_helpers.py"))


def _catches(source: str) -> list[int]:
    """Lines of ``source`` that catch an exception: an ``except`` clause, or ``contextlib.suppress``. A ``try`` with
    only a ``finally`` (which restores state and lets the error through) catches nothing."""
    tree = ast.parse(source)
    handlers = [node.lineno for node in ast.walk(tree) if isinstance(node, (ast.Try, ast.TryStar)) and node.handlers]
    suppress = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Attribute) and node.attr == "suppress"]
    return sorted(handlers + suppress)


@pytest.mark.parametrize("path", [COMMON, *_suite_helpers()], ids=lambda p: p.parent.name if p != COMMON else "common")
def test_helpers_never_catch_the_submissions_errors(path):
    """A helper that catches an exception would report a verdict ("it raised ValueError") from the sandbox."""
    lines = _catches(path.read_text())
    assert lines == [], f"{path.name} catches exceptions at lines {lines}: let them reach the test"


def test_the_catch_check_tells_a_handler_from_a_finally():
    assert _catches("try:\n    f()\nexcept ValueError:\n    pass\n") == [1]
    assert _catches("import contextlib\nwith contextlib.suppress(Exception):\n    f()\n") == [2]
    assert _catches("try:\n    f()\nfinally:\n    g()\n") == []


def _top_level_names(source: str) -> set[str]:
    names = set()
    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    return names


@pytest.mark.parametrize("path", _suite_helpers(), ids=lambda p: p.parent.name)
def test_suite_helpers_run_after_the_common_ones_without_shadowing_them(path):
    common = {name for name in _top_level_names(COMMON.read_text()) if not name.startswith("_")}
    both = _helpers(COMMON.read_text(), path.read_text())
    assert common <= set(both)
    shadowed = sorted(common & _top_level_names(path.read_text()))
    assert shadowed == [], f"{path.parent.name}'s helpers redefine the common {shadowed}"


def test_build_makes_released_classes_by_full_path_only():
    helpers = _helpers(COMMON.read_text())
    a = helpers["build"]("rlcourse.nets.GaussianPolicy", 3, 2, hidden=(4,), torch_seed=5)
    b = helpers["build"]("rlcourse.nets.GaussianPolicy", 3, 2, hidden=(4,), torch_seed=5)
    assert type(a).__module__ == "rlcourse.nets" and torch.equal(a.mean.weight, b.mean.weight)
    state = helpers["module_state"](a)
    assert set(state) == set(a.state_dict()) and not any(v.requires_grad for v in state.values())
    with pytest.raises(ValueError):
        helpers["build"]("os.system", "true")


def test_gradients_of_a_stub_by_position_keyword_and_output():
    def stub(x, y, scale=1.0, *, z=None):
        loss = scale * (x**2).sum() + (x * y).sum() + (0 if z is None else (z**3).sum())
        return loss, {"term": loss.detach(), "kept": loss * 2}

    helpers = _helpers(COMMON.read_text(), notebook={"stub": stub})
    x, y, z = np.array([1.0, -2.0]), torch.tensor([3.0, 0.5], dtype=torch.float64), torch.tensor([2.0], dtype=torch.float64)
    out, (gx, gz) = helpers["value_and_grad"]("stub", [x, y, 2.0], {"z": z}, wrt=[0, "z"], output=0)
    assert torch.allclose(gx, torch.as_tensor(4 * x + y.numpy())) and torch.allclose(gz, 3 * z**2)
    assert float(out[0].detach()) == pytest.approx(2 * 5 + (3 - 1) + 8)
    assert helpers["grad"]("stub", [x, y], wrt=[0], output=[1, "term"]) == [None]          # detached: no gradient
    assert torch.allclose(helpers["grad"]("stub", [x, y], wrt=[0], output=[1, "kept"])[0], 2 * (2 * torch.as_tensor(x) + y))
    assert torch.allclose(helpers["grad"]("stub", [torch.as_tensor(x), y], wrt=[1], output=0)[0], torch.as_tensor(x))
    vector = _helpers(COMMON.read_text(), notebook={"f": lambda v: v**2})
    assert torch.allclose(vector["grad"]("f", [torch.tensor([1.0, 3.0])], grad_outputs=torch.tensor([1.0, 10.0]))[0],
                          torch.tensor([2.0, 60.0]))


def test_parameter_gradients_and_inputs_left_by_a_call():
    net = torch.nn.Linear(2, 1)
    helpers = _helpers(COMMON.read_text(), notebook={"loss": lambda m, x: m(x).sum(), "scale_": lambda x: x.mul_(2)})
    _, grads = helpers["parameter_grads"]("loss", [net, torch.ones(3, 2)])
    assert list(grads) == ["weight", "bias"] and torch.allclose(grads["bias"], torch.tensor([3.0]))
    _, only = helpers["parameter_grads"]("loss", [net, torch.ones(3, 2)], names=["weight"])
    assert list(only) == ["weight"]
    sent = torch.ones(2)
    _, args, _ = helpers["call_and_inputs"]("scale_", [sent.clone()])
    assert torch.equal(args[0], 2 * sent)        # the test sees the change and judges it
