"""Throughput of grading a whole class: every assignment, a realistic mix, ``batch --jobs 2``.

    python bench/bench_class_throughput.py [--n 20] [--jobs 2] [--ids hw0_setup ...] [--record]
    python bench/bench_class_throughput.py --overhead   # one warm grading of an untouched hw0 notebook

For each assignment, a class of N copies of its sample submissions in the issue's mix (per 20: 10
complete, 6 partial, 2 untouched, 1 raising an exception, 1 looping forever) is graded by
``python -m autograder batch ID FOLDER --out DIR --jobs J`` in a fresh process, timed from start to
gradebook. A class of 200 is extrapolated from it: the batch's start-up (building each worker's
grader, measured as the time to grade a class of one untouched notebook) is paid once, and the rest
grows with the number of submissions:

    T(200) = T(start) + (T(N) - T(start)) * 200 / N

Prints a Markdown table; ``--record`` writes ``bench/results/class_throughput.json``.

``--per-test`` also records, for every hidden test of each assignment, where its time goes: graded once
against the complete sample in this process (a fresh grader, so the reference's answers are computed
once, as for a batch's first submission), its wall time, the worker's CPU (its main thread), the
grader's CPU (its main thread) and its channel messages; and graded against the reference alone (the
solution's own namespace as the student, in this process, no sandbox, a fresh reference cache, the same
hidden inputs), its wall and CPU time: the floor a grading is measured against. It grades the looping
sample once too (what a stub that never returns costs), with its per-test limits and without them (every
test at ``test_seconds``, as before they existed), in the same grader. CPU times are the figures to read on a loaded
machine; every assignment's record carries the load it was measured at.

    python bench/bench_class_throughput.py --n 4 --ids hw0_setup hw3_preferences --per-test --record

``--cache-price`` measures what drawing hidden inputs per submission costs: a batch of N identical complete
submissions (the reference's answers computed once and cached) against N whose stub code differs by a
comment (computed for each).

    python bench/bench_class_throughput.py --cache-price --n 6 --jobs 1 --ids hw3_preferences hw5_lm_alignment --record
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402
MIX = {"complete": 10, "partial": 6, "untouched": 2, "broken_exception": 1, "infinite_loop": 1}


def make_class(folder: Path, assignment: str, n: int, kinds: dict[str, int] | None = None) -> None:
    """N submissions in the mix (scaled from 20), named student000..."""
    samples = REPO / "autograder" / "samples" / assignment
    kinds = kinds or {k: max(1, round(v * n / 20)) if v else 0 for k, v in MIX.items()}
    folder.mkdir(parents=True)
    i = 0
    for kind, count in kinds.items():
        for _ in range(count):
            shutil.copy(samples / f"{kind}.ipynb", folder / f"student{i:03d}.ipynb")
            i += 1


def distinct_copies(folder: Path, assignment: str, n: int) -> None:
    """N copies of the complete sample whose stub cells differ by a comment: each meets its own hidden inputs
    (``input_key`` hashes the stub code), as a real class's submissions do, so the reference cache only helps
    within one submission."""
    import nbformat

    folder.mkdir(parents=True)
    notebook = nbformat.read(REPO / "autograder" / "samples" / assignment / "complete.ipynb", as_version=4)
    stubs = [c for c in notebook.cells if c.cell_type == "code" and c.get("metadata", {}).get("nbgrader", {}).get("solution")]
    for i in range(n):
        for cell in stubs:
            cell.source = cell.source.rstrip("\n").rsplit("\n# submission ", 1)[0] + f"\n# submission {i}"
        nbformat.write(notebook, folder / f"student{i:03d}.ipynb")


def cache_price(assignment: str, n: int, jobs: int) -> dict:
    """Wall and CPU seconds of a batch of N identical complete submissions (one draw of the hidden inputs: the
    reference's answers computed once, then cached) and of N distinct ones (N draws: computed N times)."""
    with tempfile.TemporaryDirectory() as tmp:
        make_class(Path(tmp) / "same", assignment, n, {"complete": n})
        distinct_copies(Path(tmp) / "distinct", assignment, n)
        same = timed_batch(assignment, Path(tmp) / "same", Path(tmp) / "same_out", jobs)
        load_same = os.getloadavg()[0]
        distinct = timed_batch(assignment, Path(tmp) / "distinct", Path(tmp) / "distinct_out", jobs)
    return {"n": n, "jobs": jobs, "identical": {"wall": round(same[0], 2), "cpu": round(same[1], 2), "load": load_same},
            "distinct": {"wall": round(distinct[0], 2), "cpu": round(distinct[1], 2), "load": os.getloadavg()[0]},
            "meta": meta()}


def timed_batch(assignment: str, folder: Path, out: Path, jobs: int) -> tuple[float, float]:
    """Wall seconds and CPU seconds (this batch's processes) of one ``batch`` run (``assignment`` may be
    several, comma-separated)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", assignment, str(folder), "--out", str(out),
                           "--jobs", str(jobs)], capture_output=True, text=True, cwd=REPO)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"batch {assignment} failed:\n{done.stderr[-3000:]}")
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def sandbox_cpu(out: Path) -> float:
    """CPU seconds of the sandbox workers of a batch, summed from its results (``sandbox_cpu``): the part of a class's
    cost that the batch's own process accounts miss (the workers are not its waited-for children)."""
    return sum(json.loads(path.read_text()).get("sandbox_cpu", 0.0) for path in out.rglob("result.json"))


def overhead(assignment: str = "hw0_setup", sample: str = "untouched", repeats: int = 3) -> float:
    """Median seconds to grade one sample with one warm Grader: what every submission pays besides its tests."""
    from autograder.core.grader import Grader

    grader = Grader(assignment)
    path = REPO / "autograder" / "samples" / assignment / f"{sample}.ipynb"
    grader.grade(path)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        grader.grade(path)
        times.append(time.perf_counter() - start)
    grader.close()
    return sorted(times)[repeats // 2]


EARLIER_META = {"commit": "not recorded (the rows were committed in 0a6f337, 2026-12-02)", "date": "not recorded",
                "load": "per row (its load column)", "machine": "2-core CPU"}
"""Provenance of a whole-class run recorded before this file carried a ``meta`` object."""


def startup(ids: list[str], jobs: int) -> dict:
    """What the batch's start-up costs graded one assignment at a time against all in one batch: a class of
    one untouched notebook per assignment (so start-up is nearly all of it), wall and CPU of every process
    the batches ran (``RUSAGE_CHILDREN``: the CLI, its pool, the zygotes and workers)."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for assignment in ids:
            make_class(root / "in" / assignment, assignment, 1, {"untouched": 1})
        separate = {a: timed_batch(a, root / "in" / a, root / "separate" / a, jobs) for a in ids}
        wall, cpu = timed_batch(",".join(ids), root / "in", root / "together", jobs)
    return {"meta": meta(), "assignments": ids, "jobs": jobs,
            "one_batch_per_assignment": {"wall": round(sum(w for w, _ in separate.values()), 2),
                                         "cpu": round(sum(c for _, c in separate.values()), 2),
                                         "per_assignment": {a: {"wall": round(w, 2), "cpu": round(c, 2)}
                                                            for a, (w, c) in separate.items()}},
            "one_batch_for_all": {"wall": round(wall, 2), "cpu": round(cpu, 2)}}


def _rounded(stats: dict[str, float]) -> dict[str, float]:
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in stats.items()}


def per_test(assignment: str) -> dict:
    """Per hidden test: the complete sample graded in a sandbox, and the reference alone (see the docstring)."""
    from autograder.core import course
    from autograder.core.grader import Grader, SuitePlugin, build_reference, input_key
    from autograder.core.intake import read_code_cells
    from autograder.core.notebook import find_stubs
    from autograder.core.session import LocalTransport, Namespace, ReferenceCache

    samples = course.samples_dir(assignment)
    load_before = list(os.getloadavg())
    grader = Grader(assignment)
    try:
        cpu, wall = time.process_time(), time.perf_counter()
        result = grader.grade(samples / "complete.ipynb")
        complete_wall, complete_cpu = time.perf_counter() - wall, time.process_time() - cpu
        complete = grader.last_test_stats
        wall = time.perf_counter()
        looping = grader.grade(samples / "infinite_loop.ipynb")
        looping_wall = time.perf_counter() - wall
        timeouts = {node: round(s["span"], 2) for node, s in grader.last_test_stats.items()
                    if "span" in s and s["span"] >= 0.8 * s.get("limit", 1e9)}
        own_limits, grader.test_limits = grader.test_limits, {}  # the same, with test_seconds for every test
        wall = time.perf_counter()
        grader.grade(samples / "infinite_loop.ipynb")
        looping_without_wall = time.perf_counter() - wall
        grader.test_limits = own_limits
        stubs = {name: m for name, m in find_stubs(read_code_cells(samples / "complete.ipynb")[0], grader.expected)[0].items()
                 if not m.problem}
        alone = build_reference(assignment)
        plugin = SuitePlugin(Namespace(LocalTransport(alone, grader.helpers), "student"),
                             Namespace(LocalTransport(grader.reference_ns, grader.helpers, ReferenceCache()), "reference"),
                             {}, None, grader.dependencies, input_key(grader.version, stubs))
        cpu, wall = time.process_time(), time.perf_counter()
        grader._run_suite(plugin)
        alone_wall, alone_cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        grader.close()
    tests = {}
    for node in sorted(set(complete) | set(plugin.test_stats)):
        c, r = complete.get(node, {}), plugin.test_stats.get(node, {})
        tests[node] = _rounded({"wall": c.get("span", c.get("seconds")), "worker_cpu": c.get("worker_cpu"),
                                "grader_cpu": c.get("grader_cpu"), "messages": c.get("messages"), "limit": c.get("limit"),
                                "reference_alone_wall": r.get("seconds"), "reference_alone_cpu": r.get("grader_cpu")})
    sum_of = lambda side, key: round(sum((t.get(key if side == "complete" else f"reference_alone_{key}") or 0)  # noqa: E731
                                         for t in tests.values()), 3)
    return {"meta": {**meta(), "load_before": load_before},
            "complete": {"score": result.score, "max_score": result.max_score, "wall": round(complete_wall, 3),
                         "grading_process_cpu": round(complete_cpu, 3), "tests_wall": sum_of("complete", "wall"),
                         "tests_worker_cpu": sum_of("complete", "worker_cpu"),
                         "tests_grader_cpu": sum_of("complete", "grader_cpu"),
                         "tests_messages": sum_of("complete", "messages")},
            "reference_alone": {"passed": sum(o.passed for o in plugin.outcomes), "tests": len(plugin.outcomes),
                                "wall": round(alone_wall, 3), "cpu": round(alone_cpu, 3),
                                "tests_cpu": sum_of("reference_alone", "cpu")},
            "infinite_loop": {"score": looping.score, "max_score": looping.max_score, "wall": round(looping_wall, 3),
                              "wall_without_per_test_limits": round(looping_without_wall, 3),
                              "tests_near_their_limit": timeouts},
            "tests": tests}


def add_reference_ratio(rows: list[dict], per_test_records: dict) -> None:
    """Beside each row, its CPU per submission (the batch's processes and its sandbox workers, the mix of 20 as
    graded) and its ratio to the reference's own CPU on the suite (``per_test``'s reference alone: the solution
    graded as the student in one process, no sandbox), where a per-test record of that assignment is at hand."""
    for r in rows:
        ref = (per_test_records.get(r["assignment"]) or {}).get("reference_alone", {}).get("cpu")
        if ref and r.get("n"):
            total = r["cpu"] + r.get("sandbox_cpu", 0.0)
            r["cpu_per_submission"] = round(total / r["n"], 3)
            r["reference_suite_cpu"] = ref
            r["cpu_to_reference"] = round(total / r["n"] / ref, 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--record", action="store_true")
    parser.add_argument("--overhead", action="store_true",
                        help="only time grading hw0's untouched sample with a warm grader (median of 3)")
    parser.add_argument("--startup", action="store_true",
                        help="only compare the start-up of one batch per assignment with one batch for them all")
    parser.add_argument("--per-test-only", action="store_true",
                        help="only the per-test records (no class), merged into the results file")
    parser.add_argument("--per-test", action="store_true",
                        help="also record where each hidden test's time goes (complete sample and reference alone)")
    parser.add_argument("--cache-price", action="store_true",
                        help="only compare a batch of N identical complete submissions with N distinct ones")
    parser.add_argument("--no-reference-cache", action="store_true",
                        help="recompute the reference's answers for every submission (as if hidden inputs varied)")
    args = parser.parse_args()
    from autograder.core import course

    if args.no_reference_cache:
        os.environ["AUTOGRADER_REFERENCE_CACHE_BYTES"] = "0"
    if args.overhead:
        print(f"grading hw0's untouched sample, warm grader: {overhead():.2f} s (median of 3, load "
              f"{os.getloadavg()[0]:.1f})")
        return

    ids = args.ids or [i for i in course.assignment_ids() if course.suite_dir(i).is_dir()]
    if args.cache_price:
        out = REPO / "bench" / "results" / "class_throughput.json"
        for assignment in ids:
            found = cache_price(assignment, args.n, args.jobs)
            print(f"{assignment}: {args.n} identical complete submissions {found['identical']['wall']:.0f} s wall "
                  f"({found['identical']['cpu']:.0f} s CPU), {args.n} distinct {found['distinct']['wall']:.0f} s "
                  f"({found['distinct']['cpu']:.0f} s CPU)", flush=True)
            if args.record:
                data = json.loads(out.read_text()) if out.exists() else {}
                data.setdefault("meta", EARLIER_META)
                data.setdefault("reference_cache_price", {})[assignment] = found
                out.write_text(json.dumps(data, indent=1) + "\n")
        return
    if args.startup:
        found = startup(ids, args.jobs)
        print(f"start-up of {len(ids)} assignments: one batch each {found['one_batch_per_assignment']['wall']:.0f} s wall, "
              f"{found['one_batch_per_assignment']['cpu']:.0f} s CPU; one batch for all "
              f"{found['one_batch_for_all']['wall']:.0f} s wall, {found['one_batch_for_all']['cpu']:.0f} s CPU "
              f"(load {os.getloadavg()[0]:.1f})")
        if args.record:
            out = REPO / "bench" / "results" / "class_throughput.json"
            data = json.loads(out.read_text()) if out.exists() else {}
            data.setdefault("meta", EARLIER_META)
            data["startup_once"] = found
            out.write_text(json.dumps(data, indent=1) + "\n")
            print(f"wrote {out}")
        return
    rows = []
    if args.per_test_only:
        details = {a: per_test(a) for a in ids}
        for a, d in details.items():
            print(f"{a}: looping sample {d['infinite_loop']['wall']:.1f} s with per-test limits, "
                  f"{d['infinite_loop']['wall_without_per_test_limits']:.1f} s without", flush=True)
        if args.record:
            out = REPO / "bench" / "results" / "class_throughput.json"
            data = json.loads(out.read_text()) if out.exists() else {}
            data.setdefault("meta", EARLIER_META)
            data["per_test"] = {**data.get("per_test", {}), **details}
            out.write_text(json.dumps(data, indent=1) + "\n")
            print(f"wrote {out}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        for assignment in ids:
            root = Path(tmp) / assignment
            make_class(root / "one", assignment, 1, {"untouched": 1})
            start_wall, _ = timed_batch(assignment, root / "one", root / "one_out", args.jobs)
            make_class(root / "class", assignment, args.n)
            wall, cpu = timed_batch(assignment, root / "class", root / "out", args.jobs)
            n = len(list((root / "class").iterdir()))
            rows.append({"assignment": assignment, "n": n, "wall": wall, "cpu": cpu,
                         "sandbox_cpu": round(sandbox_cpu(root / "out"), 3), "start": start_wall,
                         "extrapolated_200": start_wall + (wall - start_wall) * 200 / n,
                         "load": os.getloadavg()[0]})
            print(f"{assignment}: {n} in {wall:.0f} s (start-up {start_wall:.0f} s, CPU {cpu:.0f} s and "
                  f"{rows[-1]['sandbox_cpu']:.0f} s in the sandbox)", flush=True)
    total, total_200 = sum(r["wall"] for r in rows), sum(r["extrapolated_200"] for r in rows)
    print(f"\n| assignment | class | wall | CPU | start-up (a class of 1) | 200 students (extrapolated) |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['assignment']} | {r['n']} | {r['wall']:.0f} s | {r['cpu']:.0f} s | {r['start']:.0f} s | "
              f"{r['extrapolated_200'] / 60:.1f} min |")
    print(f"| all | {sum(r['n'] for r in rows)} | {total:.0f} s | {sum(r['cpu'] for r in rows):.0f} s | | "
          f"{total_200 / 60:.1f} min |")
    details = {}
    if args.per_test:
        for assignment in ids:
            details[assignment] = per_test(assignment)
            d = details[assignment]
            print(f"{assignment}: complete {d['complete']['wall']:.1f} s wall, {d['complete']['tests_grader_cpu']:.1f} s "
                  f"grader CPU + {d['complete']['tests_worker_cpu']:.1f} s worker CPU in tests, "
                  f"{d['complete']['tests_messages']:.0f} messages; reference alone {d['reference_alone']['cpu']:.1f} s "
                  f"CPU; looping sample {d['infinite_loop']['wall']:.1f} s", flush=True)
    add_reference_ratio(rows, details or (json.loads((REPO / "bench" / "results" / "class_throughput.json").read_text())
                                          .get("per_test", {}) if (REPO / "bench" / "results" / "class_throughput.json").exists() else {}))
    for r in rows:
        if "cpu_to_reference" in r:
            print(f"{r['assignment']}: {r['cpu_per_submission']:.2f} s CPU a submission, {r['cpu_to_reference']:.1f} x the "
                  f"reference's own suite CPU ({r['reference_suite_cpu']:.2f} s)")
    if args.record:
        name = "class_throughput_no_cache.json" if args.no_reference_cache else "class_throughput.json"
        out = REPO / "bench" / "results" / name
        earlier = json.loads(out.read_text()) if out.exists() else {}
        run = {"args": vars(args), "mix_per_20": MIX, "rows": rows, "total_wall": total,
               "extrapolated_200_total": total_200, "meta": meta()}
        earlier_ids = {r["assignment"] for r in earlier.get("rows", [])}
        smaller = bool(earlier.get("rows")) and (args.n < earlier.get("args", {}).get("n", 0) or not earlier_ids <= set(ids))
        if smaller:  # a small class does not replace the last whole-class measurement: it goes beside it
            data = dict(earlier)
            data.setdefault("meta", EARLIER_META)
            data["small_class_run"] = run
        else:
            data = run
        if details:
            data["per_test"] = {**(earlier.get("per_test", {}) if smaller else {}), **details}
        elif "per_test" in earlier:
            data["per_test"] = earlier["per_test"]
        out.write_text(json.dumps(data, indent=1) + "\n")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
