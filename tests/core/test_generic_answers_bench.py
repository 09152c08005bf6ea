"""``bench/bench_generic_answers.py`` sees an answer that earns: its "none earned a point" means what it says."""
from __future__ import annotations

import importlib.util

import pytest
from conftest import REPO

pytestmark = pytest.mark.slow  # two small batches: make test-fast leaves it out


def _bench():
    spec = importlib.util.spec_from_file_location("bench_generic_answers", REPO / "bench" / "bench_generic_answers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("mode", [[], ["--one-stub"]])
def test_the_solution_passed_off_as_a_generic_answer_is_reported_as_earning(mode, monkeypatch, capsys):
    """Each stub's own solution, called by the generic stub, must be listed as earning (and the exit status 1); zeros
    beside it must not be listed. Before this test the bench read a score that result.json does not hold and saw no
    earner."""
    from autograder.authoring.samples import solution_sources

    bench = _bench()
    solved, generic = solution_sources("hw0_setup"), bench.stub_source
    monkeypatch.setattr(bench, "stub_source", lambda name, value: (  # each stub's solution under a name of its own
        solved[name].replace(f"def {name}(", f"def _solved_{name}(", 1) + "\n"
        + generic(name, value).replace("_solved(", f"_solved_{name}(")))
    monkeypatch.setattr(bench, "ANSWERS", {"the solution": "_solved(*args, **kwargs)",
                                           "zeros like it": bench.ANSWERS["zeros like it"]})
    monkeypatch.setattr("sys.argv", ["bench_generic_answers.py", "--ids", "hw0_setup", *mode])
    assert bench.main() == 1
    printed = capsys.readouterr().out
    assert "/ the solution:" in printed and "/ zeros like it:" not in printed, printed
    assert "discounted_returns" in printed and "episode_returns" in printed, printed
