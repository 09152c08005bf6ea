"""Benchmark of hw2b (adversarial imitation and reward transfer): the transfer table, the notebook's budgets, and a
check of the three stubs against the `imitation` library's GAIL and AIRL code on the same problem.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_hw2b_adversarial.py [--seeds 5] [--notebook] [--grade]
    .venv/bin/python bench/bench_hw2b_adversarial.py --budgets-only --notebook --grade   # budgets only, merged in
    .venv/bin/python bench/bench_hw2b_adversarial.py --findings   # the notebook's findings paragraph, from the file

1. **Transfer table.** For each seed, ``rlcourse.adversarial.transfer_experiment`` with hw2b's full budgets (its
   parameters cell with ``FAST = False``, repeated in ``BUDGET`` below and checked against the notebook by
   ``tests/hw2b_adversarial``) and the reference solutions of the five stubs (the solution notebook's setup and
   stub cells, executed here: the planner and forward pass every learner plans and is scored with, the
   discriminator loss, AIRL's logits, the policy reward): demonstrations in the training world, BC, MaxEnt IRL, GAIL and AIRL fitted on
   them, then in each of the four worlds (``WORLD_NAMES``, fixed in ``transfer_worlds`` before any learner was
   run) the normalised true return of each carried-over policy and of each policy retrained from scratch on a
   recovered reward. Seeds 0..4 are the notebook's seeds, so the notebook's table is seed for seed this one.
2. **Budgets** (``--notebook``): the solution notebook executed with ``FAST = True`` and with ``FAST = False``,
   wall time of each; (``--grade``) the complete sample graded once, wall time with the grader's start-up.
3. **imitation** (version pinned in ``bench/requirements-hw2.txt``; its own venv, ``--bench-python``): seed 0's
   trained discriminators, evaluated on its demonstrations and on a batch of the final policy's transitions,
   are handed to imitation's ``ShapedRewardNet`` + ``AIRL.logits_expert_is_high`` (AIRL's logits),
   ``RewardNetFromDiscriminatorLogit`` (GAIL's policy reward) and its discriminator loss expression
   (``binary_cross_entropy_with_logits`` over the pooled batch); the largest differences from ours are
   recorded. imitation's trainers themselves (PPO generators on a gym environment) are not run: they would need
   an environment wrapper and minutes of PPO per seed, and this problem's learners are exact-planning ones.

Writes ``bench/results/hw2b_adversarial.json``: per seed and learner the score in every world, per seed the
adversarial learners' final training-world scores and the wall time, the mean and standard deviation over
seeds, the imitation check, the notebook budgets, and ``meta``.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

NOTEBOOK = REPO / "solutions" / "hw2b_adversarial" / "hw2b_adversarial.ipynb"
RESULTS = REPO / "bench" / "results" / "hw2b_adversarial.json"
# hw2b's full budgets (its parameters cell with FAST = False).
BUDGET = dict(GRID_SIZE=10, HORIZON=25, N_DEMOS=100, N_ITERS=150, N_SEEDS=5, AIRL_GAMMA=0.9)


def solution_namespace(path: Path = NOTEBOOK) -> dict:
    """The solution notebook's setup and stub cells, executed in a fresh namespace."""
    import nbformat

    ns: dict = {"__name__": "__bench__"}
    for cell in nbformat.read(path, as_version=4).cells:
        info = cell.metadata
        if cell.cell_type == "code" and ("setup" in info.get("tags", []) or info.get("nbgrader", {}).get("solution")):
            with contextlib.redirect_stdout(io.StringIO()):
                exec(compile(cell.source, f"<{info.get('nbgrader', {}).get('grade_id')}>", "exec"), ns)
    return ns


def run_seed(ns: dict, worlds: dict, seed: int) -> tuple[dict, dict]:
    """One seed of the transfer test: its row for the results file and the raw run (for the imitation check)."""
    from rlcourse.adversarial import normalised_return

    start = time.perf_counter()
    run = ns["transfer_experiment"](worlds, seed, BUDGET["N_DEMOS"], ns["discriminator_loss"], ns["policy_reward"],
                                    ns["airl_logits"], ns["soft_policy"], ns["state_distributions"],
                                    n_iters=BUDGET["N_ITERS"], airl_gamma=BUDGET["AIRL_GAMMA"])
    row = {"scores": run["scores"], "wall_s": round(time.perf_counter() - start, 2),
           "maxent_weights": run["maxent_weights"].tolist(),
           "final_training_score": {k: float(run[k]["history"]["score"][-1]) for k in ("gail", "airl")},
           "final_discriminator_accuracy": {k: [float(run[k]["history"]["expert_accuracy"][-1]),
                                                float(run[k]["history"]["policy_accuracy"][-1])] for k in ("gail", "airl")},
           "own_policy_training_world": {k: normalised_return(worlds["original"], run[k]["policy"],
                                                              ns["state_distributions"]) for k in ("gail", "airl")}}
    return row, run


def imitation_inputs(ns: dict, worlds: dict, run: dict, path: Path) -> dict:
    """Seed 0's discriminators on its demonstrations and on as many transitions of its final policies, and our
    three stubs' outputs on them, saved for the worker."""
    import torch

    from rlcourse.adversarial import sample_transitions

    train = worlds["original"]
    demos = run["demos"]
    horizon = train.horizon
    out = {"n_states": train.n_states, "n_actions": train.n_actions, "gamma": BUDGET["AIRL_GAMMA"]}
    for kind in ("gail", "airl"):
        res = run[kind]
        rollout = sample_transitions(train.P, res["policy"], train.p0, demos.states.shape[0], np.random.default_rng(99))
        log_pi = np.log(np.maximum(res["policy"], 1e-300))
        sides = {}
        for side, batch in (("expert", demos), ("policy", rollout)):
            t = np.broadcast_to(np.arange(horizon), batch.states.shape).ravel()
            s, a, s2 = (x.ravel() for x in batch)
            done = (t == horizon - 1).astype(float)
            sides[side] = dict(s=s, a=a, s2=s2, done=done, log_pi=log_pi[t, s, a])
            out[f"{kind}_{side}_s"], out[f"{kind}_{side}_a"], out[f"{kind}_{side}_s2"] = s, a, s2
            out[f"{kind}_{side}_done"], out[f"{kind}_{side}_log_pi"] = done, log_pi[t, s, a]
        disc = res["discriminator"]
        with torch.no_grad():
            if kind == "gail":
                table = disc.table()
                out["gail_table"] = table.numpy()
                logits = {k: table[torch.as_tensor(v["s"]), torch.as_tensor(v["a"])] for k, v in sides.items()}
                out["gail_reward_ours"] = ns["policy_reward"](logits["policy"], "gail").numpy()
            else:
                g, h = disc.g(), disc.h
                out["airl_g"], out["airl_h"] = g.numpy(), h.numpy()
                logits = {k: ns["airl_logits"](g[v["s"]], h[v["s"]], h[v["s2"]], torch.as_tensor(v["log_pi"]),
                                               BUDGET["AIRL_GAMMA"], torch.as_tensor(v["done"])) for k, v in sides.items()}
            for side in sides:
                out[f"{kind}_{side}_logits_ours"] = logits[side].numpy()
            out[f"{kind}_loss_ours"] = float(ns["discriminator_loss"](logits["expert"], logits["policy"]))
    np.savez(path, **out)
    return out


def imitation_worker(path_in: str, path_out: str) -> None:
    """Runs under the bench venv: imitation's reward nets, AIRL logits and discriminator loss on our inputs."""
    import gymnasium as gym
    import imitation
    import torch as th
    import torch.nn.functional as F
    from imitation.algorithms.adversarial.airl import AIRL
    from imitation.algorithms.adversarial.gail import RewardNetFromDiscriminatorLogit
    from imitation.rewards.reward_nets import RewardNet, ShapedRewardNet

    d = dict(np.load(path_in))
    obs_space, act_space = gym.spaces.Discrete(int(d["n_states"])), gym.spaces.Discrete(int(d["n_actions"]))

    class Table(RewardNet):
        """A reward r(s, a) read from a table (states and actions as integer tensors)."""

        def __init__(self, table):
            super().__init__(obs_space, act_space)
            self.table = th.as_tensor(table)

        def forward(self, state, action, next_state, done):
            return self.table[state.long(), action.long()]

    g = d["airl_g"][:, None].repeat(int(d["n_actions"]), axis=1)
    h = th.as_tensor(d["airl_h"])
    shaped = ShapedRewardNet(Table(g), lambda s: h[s.long()], float(d["gamma"]))

    class Stand:  # what AIRL.logits_expert_is_high reads of its trainer
        _reward_net = shaped

    report = {"imitation_version": imitation.__version__}
    gail_net = RewardNetFromDiscriminatorLogit(Table(d["gail_table"]))
    for kind in ("gail", "airl"):
        logits = {}
        for side in ("expert", "policy"):
            s, a, s2, done = (th.as_tensor(d[f"{kind}_{side}_{k}"]) for k in ("s", "a", "s2", "done"))
            if kind == "gail":
                logits[side] = gail_net.base(s, a, s2, done)
            else:
                logits[side] = AIRL.logits_expert_is_high(Stand(), s, a, s2, done, th.as_tensor(d[f"airl_{side}_log_pi"]))
            if kind == "airl":  # (GAIL's logits are the table itself on both sides: nothing to compare)
                report[f"{kind}_{side}_logits_max_abs_diff"] = float((logits[side] - th.as_tensor(d[f"{kind}_{side}_logits_ours"])).abs().max())
        pooled = th.cat([logits["expert"], logits["policy"]])
        labels = th.cat([th.ones_like(logits["expert"]), th.zeros_like(logits["policy"])])
        theirs = float(F.binary_cross_entropy_with_logits(pooled, labels))   # imitation's train_disc loss
        # with equal batch sizes the pooled mean is half our sum of the two sides' means
        report[f"{kind}_loss_theirs_pooled_mean"] = theirs
        report[f"{kind}_loss_ours"] = float(d[f"{kind}_loss_ours"])
        report[f"{kind}_loss_ratio_ours_over_theirs"] = float(d[f"{kind}_loss_ours"]) / theirs
        if kind == "gail":
            s, a, s2, done = (th.as_tensor(d[f"gail_policy_{k}"]) for k in ("s", "a", "s2", "done"))
            report["gail_reward_max_abs_diff"] = float((gail_net(s, a, s2, done) - th.as_tensor(d["gail_reward_ours"])).abs().max())
    Path(path_out).write_text(json.dumps(report))


def run_imitation(ns: dict, worlds: dict, run: dict, bench_python: str) -> dict | str:
    if not Path(bench_python).exists():
        return (f"not run: no bench venv at {bench_python} (python3.11 -m venv .venv-bench && "
                ".venv-bench/bin/pip install -r bench/requirements-hw2.txt)")
    with tempfile.TemporaryDirectory() as tmp:
        imitation_inputs(ns, worlds, run, Path(tmp) / "in.npz")
        proc = subprocess.run([bench_python, __file__, "--imitation-worker", str(Path(tmp) / "in.npz"),
                               str(Path(tmp) / "out.json")], capture_output=True, text=True, cwd=REPO)
        if proc.returncode:
            return "the imitation worker failed: " + (proc.stderr.strip().splitlines() or ["?"])[-1]
        return json.loads((Path(tmp) / "out.json").read_text())


def notebook_budgets() -> dict:
    """Wall time of the solution notebook executed with FAST = True and with FAST = False."""
    import nbformat
    from nbclient import NotebookClient

    import os

    times = {"load_before": [round(x, 2) for x in os.getloadavg()]}
    for fast in (True, False):
        nb = nbformat.read(NOTEBOOK, as_version=4)
        at = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
        nb.cells.insert(at + 1, nbformat.v4.new_code_cell(f"FAST = {fast}"))
        start = time.perf_counter()
        NotebookClient(nb, timeout=1800, kernel_name="python3", resources={"metadata": {"path": str(REPO)}}).execute()
        times["fast_s" if fast else "full_s"] = round(time.perf_counter() - start, 1)
    times["load_after"] = [round(x, 2) for x in os.getloadavg()]
    return times


def grading_time() -> dict:
    """One complete submission (the complete sample) graded by ``python -m autograder grade``: wall time with the
    grader's start-up, and the execution time the grader reports, with the load around it."""
    import os

    with tempfile.TemporaryDirectory() as tmp:
        load, start = os.getloadavg(), time.perf_counter()
        subprocess.run([sys.executable, "-m", "autograder", "grade", "hw2b_adversarial",
                        str(REPO / "autograder" / "samples" / "hw2b_adversarial" / "complete.ipynb"), "--out", tmp],
                       check=True, capture_output=True, cwd=REPO)
        wall = time.perf_counter() - start
        result = json.loads((Path(tmp) / "results.json").read_text())
    return {"wall_s": round(wall, 2), "execution_time_s": result["execution_time"], "score": result["score"],
            "load_before": [round(x, 2) for x in load]}


def summary(seeds: dict) -> dict:
    from rlcourse.adversarial import LEARNERS, WORLD_NAMES

    return {learner: {world: {"mean": float(np.mean([s["scores"][learner][world] for s in seeds.values()])),
                              "std": float(np.std([s["scores"][learner][world] for s in seeds.values()]))}
                      for world in WORLD_NAMES} for learner in LEARNERS}


FINDINGS_HEAD = "**What the course's benchmark found**"


def findings(record: dict) -> str:
    """The notebook's paragraph on the recorded transfer table, written from ``record`` alone (the test
    ``tests/hw2b_adversarial`` checks that the notebook's cell is exactly this text for the recorded file)."""
    s = record["summary"]
    changed = [w for w in record["worlds"] if w != "original"]

    def ms(learner, world):
        return f"{s[learner][world]['mean']:.2f} ± {s[learner][world]['std']:.2f}"

    def row(learner):
        return " / ".join(ms(learner, w) for w in changed)

    rewards = [name for name in record["learners"] if "policy" not in name]
    per_seed = list(record["seeds"].values())
    n = len(per_seed)

    def ahead(a: str, b: str, world: str) -> int:
        """On how many seeds ``a`` beat ``b`` (each seed fits every learner on the same demonstrations)."""
        return sum(seed["scores"][a][world] > seed["scores"][b][world] for seed in per_seed)

    def gap(a: str, b: str, world: str) -> str:
        d = np.array([seed["scores"][a][world] - seed["scores"][b][world] for seed in per_seed])
        return f"{d.mean():+.2f} ± {d.std():.2f}"

    best = {w: max(rewards, key=lambda name: s[name][w]["mean"]) for w in changed}
    clear = [w for w in changed if all(ahead(best[w], o, w) == n for o in rewards if o != best[w])]
    close = [(w, o) for w in changed for o in rewards if o != best[w] and ahead(best[w], o, w) < n]
    best_text = ("The highest mean among the recovered rewards: "
                 + "; ".join(f"{b} ({w})" for w, b in best.items())
                 + (f". Seed by seed (each seed fits every learner on the same demonstrations), that reward beat every other "
                    f"recovered reward on all {n} seeds in {', '.join(clear)}" if clear else "")
                 + ("; not separated by the seeds: " + "; ".join(
                     f"{best[w]} against {o} in {w} (ahead on {ahead(best[w], o, w)} of {n} seeds, "
                     f"by {gap(best[w], o, w)})" for w, o in close) if close else ""))

    def verdict(a: str, b: str, worse: bool) -> str:
        counts = [n - ahead(a, b, w) if worse else ahead(a, b, w) for w in changed]
        where = ("in every changed world, on every seed" if min(counts) == n else
                 ", ".join(f"{w} on {k} of {n} seeds" for w, k in zip(changed, counts)))
        return where

    verdict_g = "AIRL's disentangled $g$ transferred worse than MaxEnt's reward " + verdict("AIRL g(s)", "MaxEnt r(s)", True)
    verdict_f = "and better than AIRL's own shaped $f$ " + verdict("AIRL g(s)", "AIRL f(s, a, s')", False)
    f_row = row("AIRL f(s, a, s')")
    return (f"{FINDINGS_HEAD} ({n} seeds of Part D at the full budget, `bench/results/hw2b_adversarial.json`; "
            "each figure is the true return as a fraction of the re-planned expert's, mean ± standard deviation "
            f"over seeds, in the worlds {' / '.join(changed)}). Retrained from MaxEnt's $r(s)$: {row('MaxEnt r(s)')}; "
            f"from GAIL's summed reward: {row('GAIL sum of r')}; from AIRL's $g(s)$: {row('AIRL g(s)')}; from AIRL's "
            f"$f$: {f_row}; from GAIL's final discriminator: {row('GAIL r(s, a)')}. Policies "
            f"carried over: BC {row('BC policy')}, GAIL's {row('GAIL policy')}, AIRL's {row('AIRL policy')}. In the "
            f"training world itself AIRL's own policy scored {ms('AIRL policy', 'original')} and MaxEnt's retrained "
            f"policy {ms('MaxEnt r(s)', 'original')}. {best_text}. So {verdict_g}, {verdict_f}. At the full budget "
            f"your run has these {n} seeds too (one with `FAST = True`, whose figures mean little), so it should "
            "land within about a spread of them.")


def write_findings(record: dict) -> None:
    """Put ``findings(record)`` in the solution notebook, in the cell that starts with ``FINDINGS_HEAD``."""
    import nbformat

    nb = nbformat.read(NOTEBOOK, as_version=4)
    cell = next(c for c in nb.cells if c.cell_type == "markdown" and c.source.startswith(FINDINGS_HEAD))
    cell.source = findings(record)
    nbformat.write(nb, NOTEBOOK)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=BUDGET["N_SEEDS"])
    parser.add_argument("--notebook", action="store_true", help="also time the solution notebook (FAST and full)")
    parser.add_argument("--grade", action="store_true", help="also time the grading of the complete sample")
    parser.add_argument("--bench-python", default=str(REPO / ".venv-bench" / "bin" / "python"))
    parser.add_argument("--imitation-worker", nargs=2, metavar=("IN", "OUT"))
    parser.add_argument("--budgets-only", action="store_true",
                        help="only --notebook and --grade, merged into the recorded file (the seeds are not rerun)")
    parser.add_argument("--findings", action="store_true",
                        help="only rewrite the notebook's findings paragraph from the recorded file")
    args = parser.parse_args()
    if args.imitation_worker:
        imitation_worker(*args.imitation_worker)
        return
    if args.findings:
        write_findings(json.loads(RESULTS.read_text()))
        return
    if args.budgets_only:
        record = json.loads(RESULTS.read_text())
        for key, wanted, measure in (("notebook", args.notebook, notebook_budgets), ("grading", args.grade, grading_time)):
            if wanted:
                record[key] = {**measure(), "meta": meta(["rlcourse/adversarial.py", "solutions/hw2b_adversarial",
                                                          "autograder/suites/hw2b_adversarial"])}
                print(key, record[key], flush=True)
        RESULTS.write_text(json.dumps(record, indent=1) + "\n")
        return
    import torch

    from rlcourse.adversarial import LEARNERS, WORLD_NAMES, transfer_worlds

    torch.set_num_threads(1)
    ns = solution_namespace()
    worlds = transfer_worlds(size=BUDGET["GRID_SIZE"], horizon=BUDGET["HORIZON"], seed=0)
    seeds, first = {}, None
    for seed in range(args.seeds):
        seeds[str(seed)], run = run_seed(ns, worlds, seed)
        first = first or run
        print(f"seed {seed}: {seeds[str(seed)]['wall_s']} s", flush=True)
    record = {"meta": meta(["rlcourse/adversarial.py", "solutions/hw2b_adversarial", "bench/bench_hw2b_adversarial.py"]),
              "settings": BUDGET, "worlds": list(WORLD_NAMES), "learners": list(LEARNERS),
              "score": "(J(pi) - J(uniform)) / (J(expert re-planned in that world) - J(uniform)), exact expectations",
              "seeds": seeds, "summary": summary(seeds),
              "imitation_check": run_imitation(ns, worlds, first, args.bench_python)}
    old = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    for key, wanted, measure in (("notebook", args.notebook, notebook_budgets), ("grading", args.grade, grading_time)):
        if wanted:
            record[key] = measure()
        elif key in old:
            record[key] = old[key]
    RESULTS.write_text(json.dumps(record, indent=1) + "\n")
    print(f"{'':18}" + "".join(f"{w:>16}" for w in WORLD_NAMES))
    for learner, row in record["summary"].items():
        print(f"{learner:18}" + "".join(f"{row[w]['mean']:>10.2f} ± {row[w]['std']:.2f}" for w in WORLD_NAMES))
    print("imitation check:", json.dumps(record["imitation_check"], indent=1))
    print("notebook:", record.get("notebook"), "grading:", record.get("grading"))


if __name__ == "__main__":
    main()
