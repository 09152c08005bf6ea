"""Benchmark of hw2 (maximum-entropy IRL): recovery, speed, and the `imitation` library's MCE-IRL.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_hw2_maxent_irl.py [--seeds 5] [--imitation-seeds 2] [--record]
    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_hw2_maxent_irl.py --sweep --record   # the notebook's sweep only

Runs the solution notebook's stubs (taken from ``solutions/hw2_maxent_irl``) and prints Markdown tables:

1. recovery on the 20 x 20 terrain grid (T = 50, 200 demonstrations) over seeds: relative
   feature-expectation gap at the learned weights, correlation of learned and true rewards over
   states, and the true return of the learned soft policy relative to the expert's;
2. speed: one full ``maxent_irl`` run on that grid, and the whole route part (fit on the training
   routes, predict the held-out ones, score them);
3. the same grid problems solved by ``imitation``'s tabular ``MCEIRL`` (version pinned in
   ``bench/requirements-hw2.txt``). That library needs gymnasium 0.29, which conflicts with the
   course's gymnasium 1.4, so it runs in its own virtual environment (``--bench-python``, default
   ``.venv-bench/bin/python``) in a subprocess; the two sides exchange arrays through ``.npz`` files.

4. ``--sweep``: the solution notebook's own data-efficiency sweep (Part B: the return ratio and the reward
   correlation against the number of demonstrations, ``N_SEEDS`` seeds at the full budget), run by executing
   the notebook up to that cell and reading its arrays, so the figures are the ones a student's full run
   draws.

``--record`` writes what ran into ``bench/results/hw2_maxent_irl.json`` (per seed), beside what was recorded
before. The script is also its own worker: ``--imitation-worker IN OUT`` (used under the bench venv).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SOLUTION = ROOT / "solutions" / "hw2_maxent_irl" / "hw2_maxent_irl.ipynb"
RESULTS = ROOT / "bench" / "results" / "hw2_maxent_irl.json"
SWEEP_CELL = "82d3eb33"
"""The id of the notebook's data-efficiency sweep cell (Part B), whose ``ratios`` and ``correlations`` --sweep reads."""


def load_solution() -> dict:
    """The namespace of the solution notebook's setup and stub cells."""
    import nbformat

    namespace: dict = {}
    for cell in nbformat.read(SOLUTION, as_version=4).cells:
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type == "code" and ("setup" in cell.metadata.get("tags", []) or
                                         (meta.get("solution") and not meta.get("grade"))):
            exec(compile(cell.source, f"{SOLUTION.name}:{meta.get('grade_id')}", "exec"), namespace)
    return namespace


def grid_problem(seed: int, n_demos: int = 200):
    from rlcourse.gridworld import terrain_grid

    mdp = terrain_grid(size=20, horizon=50, slip=0.1, seed=seed)
    return mdp, mdp.sample_expert(n_demos, np.random.default_rng(1000 + seed))


def evaluate(ns: dict, mdp, demos, reward: np.ndarray) -> dict:
    """Gap, correlation and return ratio of a learned state reward (S,)."""
    policy = ns["soft_value_iteration"](mdp.P, reward, mdp.horizon)
    mu_d = ns["feature_expectations"](demos.states, mdp.features)
    visits = ns["state_visitation_frequency"](mdp.P, policy, mdp.p0, mdp.horizon)
    expert_visits = ns["state_visitation_frequency"](mdp.P, mdp.expert_policy(), mdp.p0, mdp.horizon)
    mu_w = mdp.features.T @ visits
    return {"gap": float(np.linalg.norm(mu_d - mu_w) / np.linalg.norm(mu_d)),
            "corr": float(np.corrcoef(reward, mdp.true_reward)[0, 1]),
            "ratio": float(visits @ mdp.true_reward) / float(expert_visits @ mdp.true_reward)}


def run_imitation(problems: list, bench_python: str) -> list[dict] | str:
    """Fit imitation's MCEIRL on each (mdp, demos) in the bench venv; learned rewards and times, or why not."""
    if not Path(bench_python).exists():
        return f"{bench_python} is missing: create it with `python -m venv .venv-bench && " \
               f".venv-bench/bin/pip install -r bench/requirements-hw2.txt`"
    with tempfile.TemporaryDirectory() as tmp:
        arrays = {}
        for i, (mdp, demos) in enumerate(problems):
            visits = np.bincount(demos.states.ravel(), minlength=mdp.n_states) / demos.states.shape[0]
            arrays.update({f"P{i}": mdp.P, f"features{i}": mdp.features, f"p0_{i}": mdp.p0,
                           f"visits{i}": visits, f"horizon{i}": np.array(mdp.horizon)})
        np.savez(Path(tmp) / "in.npz", n=np.array(len(problems)), **arrays)
        env = {**os.environ, "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}
        proc = subprocess.run([bench_python, __file__, "--imitation-worker", str(Path(tmp) / "in.npz"),
                               str(Path(tmp) / "out.npz")], capture_output=True, text=True, env=env)
        if proc.returncode != 0:
            return "the imitation worker failed: " + proc.stderr.strip().splitlines()[-1]
        with np.load(Path(tmp) / "out.npz") as out:
            return [{"reward": out[f"reward{i}"], "seconds": float(out[f"seconds{i}"]),
                     "iterations": int(out[f"iterations{i}"])} for i in range(len(problems))]


def imitation_worker(path_in: str, path_out: str) -> None:
    """Runs under the bench venv: imitation's MCEIRL with a linear reward on the features."""
    import torch
    from imitation.algorithms.mce_irl import MCEIRL
    from imitation.rewards.reward_nets import BasicRewardNet
    from imitation.util.logger import configure
    from seals.base_envs import TabularModelPOMDP

    torch.set_num_threads(1)
    results = {}
    with np.load(path_in) as data:
        for i in range(int(data["n"])):
            P, features, visits = data[f"P{i}"], data[f"features{i}"], data[f"visits{i}"]
            horizon = int(data[f"horizon{i}"])
            # imitation's occupancy counts horizon + 1 states s_0..s_H: H = T - 1 gives our T visited states
            env = TabularModelPOMDP(transition_matrix=P, observation_matrix=features.astype(np.float32),
                                    reward_matrix=np.zeros(P.shape[0]), horizon=horizon - 1,
                                    initial_state_dist=data[f"p0_{i}"])
            net = BasicRewardNet(env.observation_space, env.action_space, use_action=False, hid_sizes=[])
            tol = 1e-4 * float(np.linalg.norm(features.T @ visits))  # the same stopping rule as maxent_irl
            irl = MCEIRL(visits, env, net, rng=np.random.default_rng(0), grad_l2_eps=tol, linf_eps=0.0,
                         log_interval=None, custom_logger=configure(format_strs=[]))
            iterations = []
            original = irl._train_step
            irl._train_step = lambda obs, _f=original: (iterations.append(1), _f(obs))[1]
            start = time.perf_counter()
            irl.train(max_iter=3000)
            results[f"seconds{i}"] = time.perf_counter() - start
            results[f"iterations{i}"] = len(iterations)
            with torch.no_grad():
                obs = torch.as_tensor(features, dtype=torch.float32)
                results[f"reward{i}"] = net(obs, None, None, None).double().numpy()
    np.savez(path_out, **results)


def route_benchmark(ns: dict) -> dict:
    """Fit on the training routes, predict and score the held-out ones (the notebook's full budget)."""
    from rlcourse.roads import load_network, load_routes, segment_overlap

    start = time.perf_counter()
    net, trips = load_network(), load_routes()
    feats = np.stack([net.route_features(r) for r in trips.routes])
    train, test = ~trips.test, trips.test
    w, _ = ns["fit_route_weights"](net, feats[train], trips.origins[train], trips.destinations[train], 60, n_iters=60)
    rows = np.flatnonzero(test)
    overlap = np.mean([segment_overlap(net.best_route(np.minimum(w, 0), trips.origins[i], trips.destinations[i]),
                                       trips.routes[i]) for i in rows])
    log_z = ns["route_log_partition"](w, net, trips.origins[test], trips.destinations[test], 60).numpy()
    seconds = time.perf_counter() - start
    shortest = np.mean([segment_overlap(net.shortest_route(trips.origins[i], trips.destinations[i]), trips.routes[i])
                        for i in rows])
    return {"seconds": seconds, "overlap": overlap, "shortest": shortest,
            "loglik": float((feats[test] @ w - log_z).mean())}


def notebook_sweep() -> dict:
    """Run the solution notebook at its full budget up to its sweep cell and return the sweep's arrays."""
    import nbformat

    from autograder.authoring.nbrun import run_notebook

    nb = nbformat.read(SOLUTION, as_version=4)
    last = next(i for i, c in enumerate(nb.cells) if c.get("id") == SWEEP_CELL)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sweep.json"
        nb.cells = nb.cells[:last + 1] + [nbformat.v4.new_code_cell(
            "import json\n"
            f"open({str(out)!r}, 'w').write(json.dumps({{'demo_counts': list(DEMO_COUNTS), 'n_seeds': N_SEEDS, "
            "'ratios': ratios.tolist(), 'correlations': correlations.tolist()}))")]
        nb.cells[-1]["id"] = "bench-sweep-dump"
        copy = Path(tmp) / SOLUTION.name
        nbformat.write(nb, copy)
        start = time.perf_counter()
        report = run_notebook(copy, {"FAST": False}, timeout=1200, cwd=SOLUTION.parent)
        if not report.ok:
            sys.exit(f"the notebook failed before its sweep: {report.error}")
        sweep = json.loads(out.read_text())
    sweep["seconds"] = round(time.perf_counter() - start, 1)
    ratios, corr = np.array(sweep["ratios"]), np.array(sweep["correlations"])
    print(f"### The notebook's data-efficiency sweep ({sweep['n_seeds']} seeds, mean ± sd; per seed in the results)\n")
    print("| demonstrations | return ratio | seeds above 1 | corr(learned, true reward) |")
    print("|---|---|---|---|")
    for j, n in enumerate(sweep["demo_counts"]):
        print(f"| {n} | {ratios[:, j].mean():.3f} ± {ratios[:, j].std():.3f} | {(ratios[:, j] > 1).sum()} of "
              f"{len(ratios)} | {corr[:, j].mean():.3f} ± {corr[:, j].std():.3f} |")
    return sweep


def record(**parts) -> None:
    """Merge ``parts`` into the results file, each stamped with the run's commit, date and load."""
    sys.path.insert(0, str(ROOT))
    from bench.run_record import meta

    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    stamp = meta()
    for key, value in parts.items():
        results[key] = {**value, "meta": stamp}
    results["meta"] = stamp
    RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {RESULTS.relative_to(ROOT)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--imitation-seeds", type=int, default=2,
                        help="how many of the seeds imitation also runs (about 2-3 minutes each here)")
    parser.add_argument("--bench-python", default=str(ROOT / ".venv-bench" / "bin" / "python"))
    parser.add_argument("--imitation-worker", nargs=2, metavar=("IN", "OUT"))
    parser.add_argument("--sweep", action="store_true", help="only the notebook's data-efficiency sweep")
    parser.add_argument("--record", action="store_true", help=f"write the results into {RESULTS.relative_to(ROOT)}")
    args = parser.parse_args()
    if args.imitation_worker:
        imitation_worker(*args.imitation_worker)
        return
    if args.sweep:
        sweep = notebook_sweep()
        if args.record:
            record(sweep=sweep)
        return
    import torch

    torch.set_num_threads(1)
    ns = load_solution()
    problems = [grid_problem(seed) for seed in range(args.seeds)]
    ours = []
    for mdp, demos in problems:
        start = time.perf_counter()
        w, history = ns["maxent_irl"](mdp.P, mdp.features, mdp.p0, demos.states, mdp.horizon, demos.actions)
        seconds = time.perf_counter() - start
        ours.append({**evaluate(ns, mdp, demos, mdp.features @ w), "seconds": seconds,
                     "iterations": len(history["grad_norm"])})
    theirs = run_imitation(problems[:args.imitation_seeds], args.bench_python)
    routes = route_benchmark(ns)

    def stats(rows, key, fmt):
        values = np.array([r[key] for r in rows])
        return f"{values.mean():{fmt}} ± {values.std():{fmt}}"

    print(f"### Recovery on the 20 x 20 terrain grid (T = 50, 200 demonstrations, {args.seeds} seeds, mean ± sd)\n")
    print("| method | feature-expectation gap (relative) | corr(learned, true reward) | return ratio | "
          "time per run (s) | iterations |")
    print("|---|---|---|---|---|---|")
    print(f"| course solution `maxent_irl` | {stats(ours, 'gap', '.1e')} | {stats(ours, 'corr', '.3f')} | "
          f"{stats(ours, 'ratio', '.3f')} | {stats(ours, 'seconds', '.2f')} | {stats(ours, 'iterations', '.0f')} |")
    if isinstance(theirs, str):
        print(f"| imitation 1.0.1 `MCEIRL` | not run: {theirs} | | | | |")
    else:
        rows = [{**evaluate(ns, mdp, demos, t["reward"]), **t} for (mdp, demos), t in zip(problems, theirs)]
        mine = ours[:len(rows)]
        print(f"| course solution, same {len(rows)} seeds | {stats(mine, 'gap', '.1e')} | {stats(mine, 'corr', '.3f')} | "
              f"{stats(mine, 'ratio', '.3f')} | {stats(mine, 'seconds', '.2f')} | {stats(mine, 'iterations', '.0f')} |")
        print(f"| imitation 1.0.1 `MCEIRL` (linear reward net, Adam), {len(rows)} seeds | {stats(rows, 'gap', '.1e')} | "
              f"{stats(rows, 'corr', '.3f')} | {stats(rows, 'ratio', '.3f')} | {stats(rows, 'seconds', '.2f')} | "
              f"{stats(rows, 'iterations', '.0f')} |")
    print("\n### Route prediction (256 intersections, 450 training and 150 held-out routes)\n")
    print("| fit + predict + score (s) | segments matched: MaxEnt | segments matched: shortest path | "
          "held-out log-likelihood per route |")
    print("|---|---|---|---|")
    print(f"| {routes['seconds']:.1f} | {routes['overlap']:.3f} | {routes['shortest']:.3f} | {routes['loglik']:.2f} |")
    print(f"\nmachine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    if args.record:
        keep = ("gap", "corr", "ratio", "seconds", "iterations")
        recovery = {"seeds": args.seeds, "course": [{k: float(r[k]) for k in keep} for r in ours],
                    "imitation": theirs if isinstance(theirs, str) else
                    [{k: float(r[k]) for k in keep} for r in rows]}
        record(recovery=recovery, routes={k: float(v) for k, v in routes.items()})


if __name__ == "__main__":
    main()
