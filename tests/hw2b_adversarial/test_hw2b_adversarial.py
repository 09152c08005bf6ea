"""hw2b's given tools (rlcourse.adversarial), its budgets and its recorded benchmark."""
from __future__ import annotations

import json
import re

import nbformat
import numpy as np
import pytest
import torch.nn.functional as F

from conftest import REPO
from rlcourse import adversarial as A


def discriminator_loss(e, p):
    return F.softplus(-e).mean() + F.softplus(p).mean()


def airl_logits(g, h, h_next, log_pi, gamma, done):
    return g + gamma * (1 - done) * h_next - h - log_pi


def policy_reward(logits, kind):
    return {"gail": F.softplus, "airl": lambda x: x}[kind](logits)


def plan(P, reward, horizon):
    """Soft backward pass for a (T, S, A) reward, written here independently of the notebook's."""
    v, policy = np.zeros(P.shape[0]), np.empty((horizon, *P.shape[:2]))
    for t in reversed(range(horizon)):
        q = reward[t] + P @ v
        v = np.logaddexp.reduce(q, axis=1)
        policy[t] = np.exp(q - v[:, None])
    return policy


def visits(P, policy, p0):
    d = [np.asarray(p0, dtype=float)]
    for t in range(policy.shape[0] - 1):
        d.append(np.einsum("s,sa,sab->b", d[-1], policy[t], P))
    return np.stack(d)


@pytest.fixture(scope="module")
def worlds():
    return A.transfer_worlds()


def test_the_four_worlds_differ_only_where_they_say(worlds):
    base = worlds["original"]
    assert list(worlds) == list(A.WORLD_NAMES)
    for name, world in worlds.items():
        assert np.allclose(world.P.sum(axis=-1), 1.0)
        assert np.array_equal(world.features, base.features) and np.array_equal(world.true_reward, base.true_reward)
        blocked = A.blocked_cells(world)
        assert blocked.sum() == world.size - 2                         # a wall column less its two-cell gap
        assert np.allclose(world.P[~blocked][:, :, blocked], 0.0)                  # no move enters the wall
        assert world.p0[blocked].sum() == 0 and np.isclose(world.p0.sum(), 1.0)
    gap = lambda w: sorted(np.flatnonzero(~A.blocked_cells(w).reshape(w.size, w.size)[:, w.size // 2]))  # noqa: E731
    assert gap(base) == [1, 2] and gap(worlds["wall moved"]) == [base.size - 3, base.size - 2]
    assert np.array_equal(worlds["slippery"].p0, base.p0) and not np.allclose(worlds["slippery"].P, base.P)
    assert np.allclose(worlds["new start"].P, base.P)
    start_cols = np.flatnonzero(worlds["new start"].p0) % base.size
    assert start_cols.min() > base.size // 2 and not (worlds["new start"].p0 * base.p0).any()


def test_the_module_plans_and_evaluates_only_through_the_functions_it_is_given():
    """hw2's backward and forward passes are stubs there: rlcourse.adversarial must not compute them itself."""
    import inspect

    source = inspect.getsource(A)
    assert "logsumexp" not in source and "logaddexp" not in source and "log_z" not in source
    names = {n for n, f in inspect.getmembers(A, inspect.isfunction) if f.__module__ == A.__name__}
    assert not names & {"soft_optimal_policy", "occupancy", "mirror_descent_step", "soft_value_iteration",
                        "state_visitation_frequency", "maxent_irl"}


def test_occupancy_matches_monte_carlo_and_the_score_is_normalised(worlds):
    world = worlds["original"]
    policy = world.expert_policy()
    d = visits(world.P, policy, world.p0)
    assert d.shape == (world.horizon, world.n_states) and np.allclose(d.sum(axis=1), 1.0)
    batch = A.sample_transitions(world.P, policy, world.p0, 4000, np.random.default_rng(0))
    mc = np.stack([np.bincount(batch.states[:, t], minlength=world.n_states) / 4000 for t in range(world.horizon)])
    assert np.abs(mc - d).max() < 0.04
    assert np.array_equal(batch.states[:, 1:], batch.next_states[:, :-1])
    assert np.isclose(A.normalised_return(world, policy, visits), 1.0)
    uniform = np.full_like(policy, 1 / world.n_actions)
    assert np.isclose(A.normalised_return(world, uniform, visits), 0.0, atol=1e-12)


def test_behaviour_cloning_counts():
    demos = A.Transitions(np.array([[0, 0, 1]]), np.array([[2, 2, 1]]), np.array([[0, 1, 1]]))
    pi = A.behaviour_cloning(demos, 3, 3, 4, prior=1.0)
    assert pi.shape == (4, 3, 3) and np.allclose(pi[0, 0], [1 / 5, 1 / 5, 3 / 5]) and np.allclose(pi[:, 2], 1 / 3)


def test_maxent_weights_match_the_expert_features(worlds):
    world = worlds["original"]
    demos = A.sample_transitions(world.P, world.expert_policy(), world.p0, 100, np.random.default_rng(0))
    w = A.fit_maxent_weights(world, demos, plan, visits)
    mu_d = world.features[demos.states].sum(axis=1).mean(axis=0)
    reward = A.as_time_table(world.features @ w, world.horizon, world.n_states, world.n_actions)
    mu_w = world.features.T @ visits(world.P, plan(world.P, reward, world.horizon), world.p0).sum(axis=0)
    assert np.abs(mu_d - mu_w).max() < 0.05 * world.horizon


def test_gail_and_airl_learn_in_the_training_world(worlds):
    world = worlds["original"]
    demos = A.sample_transitions(world.P, world.expert_policy(), world.p0, 100, np.random.default_rng(0))
    gail = A.train_adversarial(world, demos, "gail", discriminator_loss, policy_reward, None, plan, visits, n_iters=20)
    airl = A.train_adversarial(world, demos, "airl", discriminator_loss, policy_reward, airl_logits, plan, visits,
                               n_iters=20, gamma=0.9)
    for res in (gail, airl):
        assert len(res["history"]["score"]) == 20 and res["history"]["score"][-1] > res["history"]["score"][0] + 0.3
        assert np.allclose(res["policy"].sum(axis=-1), 1.0)
    rewards = A.transfer_rewards(airl, policy_reward, airl_logits, worlds["wall moved"])
    assert set(rewards) == {"AIRL g(s)", "AIRL f(s, a, s')"} and all(r.shape == (25, 100, 5) for r in rewards.values())
    gail_rewards = A.transfer_rewards(gail, policy_reward, None, world)
    assert np.allclose(plan(world.P, gail_rewards["GAIL sum of r"], 25), gail["policy"])     # its own policy's reward
    with pytest.raises(ValueError, match="kind"):
        A.train_adversarial(world, demos, "wgan", discriminator_loss, policy_reward, None, plan, visits)


def test_the_loop_calls_the_students_functions():
    """A loss that ignores the policy side leaves the discriminator blind to it: the loop really uses the stub."""
    world = A.transfer_worlds(size=6, horizon=8)["original"]
    demos = A.sample_transitions(world.P, world.expert_policy(), world.p0, 20, np.random.default_rng(0))
    calls = []

    def counting_loss(e, p):
        calls.append((e.shape, p.shape))
        return discriminator_loss(e, p)

    A.train_adversarial(world, demos, "gail", counting_loss, policy_reward, None, plan, visits, n_iters=3, n_policy=30,
                        disc_steps=2)
    assert calls == [((20 * 8,), (30 * 8,))] * 6


def _parameters(fast: bool) -> dict:
    nb = nbformat.read(REPO / "solutions" / "hw2b_adversarial" / "hw2b_adversarial.ipynb", as_version=4)
    cell = next(c for c in nb.cells if c.cell_type == "code" and "N_ITERS" in c.source and "experiment" in c.metadata.get("tags", []))
    ns = {"FAST": fast}
    exec(cell.source, ns)
    return {k: v for k, v in ns.items() if k.isupper() and k != "FAST"}


def test_the_bench_runs_the_notebooks_full_budgets():
    import sys

    sys.path.insert(0, str(REPO))
    from bench.bench_hw2b_adversarial import BUDGET

    assert _parameters(False) == BUDGET


def test_the_recorded_transfer_table():
    record = json.loads((REPO / "bench" / "results" / "hw2b_adversarial.json").read_text())
    assert {"commit", "date", "load", "machine"} <= set(record["meta"])
    assert record["settings"] == _parameters(False) and len(record["seeds"]) == record["settings"]["N_SEEDS"] == 5
    assert record["worlds"] == list(A.WORLD_NAMES) and record["learners"] == list(A.LEARNERS)
    for learner in A.LEARNERS:
        for world in A.WORLD_NAMES:
            values = [s["scores"][learner][world] for s in record["seeds"].values()]
            assert np.isclose(record["summary"][learner][world]["mean"], np.mean(values))
            assert np.isclose(record["summary"][learner][world]["std"], np.std(values))
    check = record["imitation_check"]
    if isinstance(check, dict):
        assert re.fullmatch(r"\d+\.\d+\.\d+", check["imitation_version"])
        assert max(check[k] for k in check if k.endswith("max_abs_diff")) < 1e-9
        assert np.isclose(check["gail_loss_ratio_ours_over_theirs"], 2.0) and np.isclose(check["airl_loss_ratio_ours_over_theirs"], 2.0)
    budgets = record["notebook"]
    assert budgets["fast_s"] < 90 and budgets["full_s"] < 20 * 60


def test_the_notebooks_findings_are_the_recorded_ones():
    """The solution notebook's paragraph on the benchmark is exactly what ``bench/bench_hw2b_adversarial.py
    --findings`` writes from the recorded file, and the student release carries the same paragraph: a rerun of the
    benchmark that changes a figure fails here until the paragraph is rewritten from it."""
    import sys

    sys.path.insert(0, str(REPO))
    from bench.bench_hw2b_adversarial import FINDINGS_HEAD, findings

    want = findings(json.loads((REPO / "bench" / "results" / "hw2b_adversarial.json").read_text()))
    for tree in ("solutions", "assignments"):
        nb = nbformat.read(REPO / tree / "hw2b_adversarial" / "hw2b_adversarial.ipynb", as_version=4)
        cells = [c.source for c in nb.cells if c.cell_type == "markdown" and c.source.startswith(FINDINGS_HEAD)]
        assert cells == [want], f"{tree}: the findings paragraph differs from the recorded benchmark's"
