"""hw1's drift protocol: the pushed Hopper, the comparison's bookkeeping, the results file, the lecture links."""
from __future__ import annotations

import json
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rlcourse import drift

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = [REPO / "solutions/hw1_imitation/hw1_imitation.ipynb", REPO / "assignments/hw1_imitation/hw1_imitation.ipynb"]
RESULTS = REPO / "bench/results/hw1_imitation.json"


def _trajectory(env, seed: int, steps: int = 200) -> np.ndarray:
    """Observations of ``env`` (an id or an environment) under a fixed sequence of random actions."""
    env = gym.make(env) if isinstance(env, str) else env
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(0)
    states = [obs]
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, size=3).astype(np.float32))
        states.append(obs)
        if terminated or truncated:
            break
    env.close()
    return np.array(states)


def _pushes(push: float, seed: int, steps: int) -> int:
    env = drift.PushedHopper(push)
    env.reset(seed=seed)
    for _ in range(steps):  # the count does not depend on whether the hopper is still up
        env.step(np.zeros(3, dtype=np.float32))
    return env.n_pushes


def test_no_pushes_is_the_calm_hopper():
    calm = _trajectory("Hopper-v5", seed=3)
    same = _trajectory(drift.pushed_hopper(0.0), seed=3)
    assert calm.shape == same.shape and np.allclose(calm, same)


def test_pushes_are_seeded_and_change_the_motion():
    a, b, c = (_trajectory(drift.PushedHopper(0.5, rate=1.0), seed) for seed in (4, 4, 5))
    calm, other = _trajectory("Hopper-v5", seed=4), _trajectory("Hopper-v5", seed=5)
    assert a.shape == b.shape and np.allclose(a, b), "the same seed must give the same pushes"
    n = min(len(a), len(calm), 5)
    assert not np.allclose(a[1:n], calm[1:n]), "a push of 0.5 at every step should change the motion at once"
    m = min(len(c), len(other), 5)
    assert not np.allclose(c[1:m] - other[1:m], a[1:m] - calm[1:m]), "another seed, other pushes"


def test_push_rate():
    counts = [_pushes(0.01, seed, 1000) for seed in range(3)]
    assert all(5 <= c <= 45 for c in counts), f"about 20 pushes in 1,000 steps at rate 0.02, got {counts}"


def test_ids_and_bad_arguments():
    assert drift.pushed_hopper(0.1) == "rlcourse/PushedHopper-p0.10-v0" == drift.pushed_hopper(0.1)
    with pytest.raises(ValueError):
        drift.PushedHopper(-1.0)


def test_epochs_for():
    assert drift.epochs_for(1000, 2560, 256) == 112   # 2,304 training pairs: 9 minibatches an epoch
    assert drift.epochs_for(5, 100_000, 256) == 1
    assert drift.epochs_for(10, 1, 256) == 10


def _runs(bc, dagger, labels=5000):
    return [{"labels": labels, "bc_matched": b, "dagger_final": d} for b, d in zip(bc, dagger)]


def test_summarise_applies_the_bar():
    met = drift.summarise(_runs([0.5, 0.55, 0.45, 0.5, 0.5], [0.95, 0.92, 0.98, 0.94, 0.96]))
    assert met["target_met"] and met["bc"] == [0.5, 0.55, 0.45, 0.5, 0.5]
    assert np.isclose(met["dagger_mean"], 0.95)
    assert not drift.summarise(_runs([0.75] * 5, [0.95] * 5))["target_met"], "BC above 0.7"
    assert not drift.summarise(_runs([0.5] * 5, [0.85] * 5))["target_met"], "DAgger below 0.9"
    wide = drift.summarise(_runs([0.1, 0.9, 0.1, 0.9, 0.5], [0.95] * 5))
    assert wide["bc_mean"] <= 0.7 and not wide["target_met"], "a gap within twice the spread is not drift"


def test_results_file_is_consistent():
    if not RESULTS.exists() or "drift" not in json.loads(RESULTS.read_text()):
        pytest.skip("no drift results recorded yet")
    results = json.loads(RESULTS.read_text())
    assert {"commit", "date", "load", "machine"} <= set(results["meta"])
    for setting in results["drift"]["settings"]:
        n = len(setting["seeds"])
        assert len(setting["bc"]) == len(setting["dagger"]) == len(setting["labels"]) == n
        again = drift.summarise(_runs(setting["bc"], setting["dagger"]))
        assert np.isclose(again["bc_mean"], setting["bc_mean"], atol=1e-3) and np.isclose(again["dagger_mean"], setting["dagger_mean"], atol=1e-3)
        assert setting["target_met"] == (again["target_met"] and n == 5), setting["name"]
        for curve in setting["dagger_curve"] + setting["bc_curve"]:
            labels = [x for x, _ in curve]
            assert labels == sorted(labels), "labels grow along a curve"


def jupyterlab_heading_ids(markdown: str) -> set[str]:
    """The ids JupyterLab gives a Markdown file's headings: the heading's text with spaces made '-'."""
    ids, fenced = set(), False
    for line in markdown.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
        m = re.match(r"^#{1,6} +(.*?) *#* *$", line)
        if m and not fenced:
            ids.add(m.group(1).replace(" ", "-"))
    return ids


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.parent.parent.name)
def test_lecture_links_resolve_in_jupyterlab(notebook):
    text = "".join("".join(c["source"]) for c in json.loads(notebook.read_text())["cells"] if c["cell_type"] == "markdown")
    links = re.findall(r"\]\((\.\./\.\./lectures/[^)#]+)#([^)]+)\)", text)
    assert len(links) >= 6, "every stub links the lecture section it implements"
    for path, anchor in links:
        target = (notebook.parent / path).resolve()
        assert target.is_file(), f"{path} does not exist"
        assert anchor in jupyterlab_heading_ids(target.read_text()), f"{path}#{anchor}: no heading with that JupyterLab id"


class _Linear:
    """A stand-in expert (or learner): ``act(obs) = obs[:, :3] @ W``, cheap and deterministic."""

    def __init__(self, scale: float) -> None:
        self.W = scale * np.eye(11, 3)

    def act(self, obs):
        return np.asarray(obs, dtype=np.float64) @ self.W


def test_action_error_moment_by_hand():
    obs = np.zeros((2, 11))
    obs[0, 0], obs[1, 1] = 1.0, 2.0
    actions = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    # errors with W = I: (1, 0, 0) and (0, 2 - 1, 0); second moment = diag(1, 1, 0) / 2
    assert np.allclose(drift.action_error_moment(_Linear(1.0), obs, actions), np.diag([0.5, 0.5, 0.0]))


def test_noisy_expert_adds_the_asked_covariance():
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.01]])
    noisy = drift.NoisyExpert(_Linear(0.0), cov, np.random.default_rng(0))
    draws = np.concatenate([noisy(np.zeros((1000, 11))) for _ in range(20)])
    assert np.allclose(draws.mean(axis=0), 0.0, atol=0.01)
    assert np.allclose(np.cov(draws.T), cov, atol=0.004), "the noise must have the covariance asked for"
    assert np.abs(drift.NoisyExpert(_Linear(0.0), np.eye(3) * 100, np.random.default_rng(0))(np.zeros((50, 11)))).max() <= 1.0


def test_dart_demos_count_labels_and_seeding():
    expert, env_id = _Linear(-0.5), drift.pushed_hopper(0.1)
    clean = drift.dart_demos(expert, env_id, np.zeros((3, 3)), 700, seed=3, batch=2)
    assert len(clean.obs) == len(clean.actions) == int(clean.lengths.sum()) == 700, "exactly n_labels pairs"
    assert np.allclose(clean.actions, expert.act(clean.obs), atol=1e-6), "labels are the expert's clean actions"
    from rlcourse.imitation import Demonstrations
    from rlcourse.rollouts import rollout
    same = Demonstrations.from_episodes(rollout(expert.act, env_id, 2, seed=3, progress=False))
    n = min(len(same.obs), 700)
    assert np.allclose(clean.obs[:n], same.obs[:n]), "without noise, the expert's own seeded episodes"
    noisy = drift.dart_demos(expert, env_id, np.eye(3) * 0.04, 700, seed=3, batch=2)
    assert len(noisy.obs) == 700 and np.allclose(noisy.actions, expert.act(noisy.obs), atol=1e-6)
    assert not np.allclose(noisy.obs[:50], clean.obs[:50]), "the noise moves the expert off its own states"
    again = drift.dart_demos(expert, env_id, np.eye(3) * 0.04, 700, seed=3, batch=2)
    assert np.array_equal(again.obs, noisy.obs), "the same seed gives the same noise"
    with pytest.raises(ValueError):
        drift.dart_demos(expert, env_id, np.zeros((3, 3)), 0, seed=3)


def test_dart_results_agree_with_the_drift_results():
    if not RESULTS.exists() or "dart" not in json.loads(RESULTS.read_text()).get("drift", {}):
        pytest.skip("no DART results recorded yet")
    recorded = json.loads(RESULTS.read_text())["drift"]
    by_name = {s["name"]: s for s in recorded["settings"]}
    assert {"commit", "date", "load"} <= set(recorded["dart"]["meta"])
    for s in recorded["dart"]["settings"]:
        drift_setting = by_name[s["name"]]
        assert s["labels"] == [drift_setting["labels"][drift_setting["seeds"].index(x)] for x in s["seeds"]], \
            "DART gets exactly DAgger's final labels, seed by seed"
        assert np.isclose(np.mean(s["dart"]), s["dart_mean"], atol=1e-3) and np.isclose(np.std(s["dart"]), s["dart_std"], atol=1e-3)
        assert len(s["noise_std"]) == len(s["noisy_expert"]) == len(s["bc_matched_again"]) == len(s["seeds"])


def test_dart_run_on_drift_runs_own_clone_equals_fitting_it_again():
    """The notebook hands ``drift_run``'s same-labels clone to ``dart_run`` rather than fit it a second time: in one
    process the fit repeats exactly, so the DART record is the same, and the clone kept is the one scored."""
    from autograder.core.grader import build_reference

    ns = build_reference("hw1_imitation")
    expert, env_id = _Linear(-0.5), drift.pushed_hopper(0.1)
    from rlcourse.imitation import Demonstrations
    from rlcourse.rollouts import rollout
    demos = Demonstrations.from_episodes(rollout(expert.act, env_id, 2, seed=100, progress=False))
    small = dict(hidden=(8, 8), bc_demos=(1,), bc_steps=40, dagger_iters=1, dagger_episodes=1, refit_steps=20,
                 eval_episodes=2, eval_seed=1000)
    run = drift.drift_run(ns["train_bc"], ns["dagger"], expert, env_id, demos, 0, 100.0, keep_clone=True,
                          log=lambda *_: None, **small)
    clone = run.pop("matched_clone")
    assert np.isclose(drift.expert_fraction(clone, 100.0, env_id, 2, 1000), run["bc_matched"])
    labels = min(run["labels"], len(demos.obs))
    given = drift.dart_run(ns["train_bc"], expert, env_id, demos, 0, 100.0, labels, clone=clone,
                           log=lambda *_: None, **small)
    refitted = drift.dart_run(ns["train_bc"], expert, env_id, demos, 0, 100.0, labels, log=lambda *_: None, **small)
    assert given == refitted, "the clone handed over must be the one dart_run would fit"
    perfect = drift.dart_run(ns["train_bc"], expert, env_id, demos, 0, 100.0, labels, clone=expert,
                             log=lambda *_: None, **small)
    assert np.allclose(perfect["noise_cov"], 0.0) and not np.allclose(refitted["noise_cov"], 0.0), \
        "the noise must come from the clone handed over (the expert itself errs by nothing)"
    assert "matched_clone" not in drift.drift_run(ns["train_bc"], ns["dagger"], expert, env_id, demos, 0, 100.0,
                                                  log=lambda *_: None, **small)


def test_the_protocols_push_calibration_is_quoted_from_the_results_file():
    """Section 6 states what a push costs the expert with the figures ``--calibration`` recorded (20 episodes
    of the protocol), not a figure from an unrecorded run: a re-measurement that changes them fails here."""
    pushes = {p["push"]: p for p in json.loads(RESULTS.read_text())["drift"]["calibration"]["pushes"]}
    calm, small, large = pushes[0.0], pushes[0.1], pushes[0.2]
    want = [f"{small['fraction_of_calm']:.0%} of its calm return under pushes of 0.1",
            f"({small['mean']:,.0f} ± {small['std']:,.0f} against {calm['mean']:,.0f} ± {calm['std']:,.0f})",
            f"{large['fraction_of_calm']:.0%} under pushes of 0.2"]
    for path in NOTEBOOKS:
        cells = json.loads(path.read_text())["cells"]
        text = re.sub(r"\s+", " ", " ".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown"))
        for figure in want:
            assert figure in text, f"{path.relative_to(REPO)}: section 6 should say {figure!r}"
