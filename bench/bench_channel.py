"""What one message between the grader and a sandbox worker costs: a lent object's round trip and a plain call.

    python bench/bench_channel.py --label LABEL [--record] [--repeats 5] [--n 4000]
    python bench/bench_channel.py --summarise NAME [--pairs 1,2,3]

hw3's RUCB tests lend an environment to the student's ``rucb`` (``autograder.suite.lend``): every
``env.duel(c, d)`` in the worker is a callback message to the grader, which runs the method and answers.
A complete hw3 submission makes about 5,000 of them (its five RUCB tests; ``messages`` in
``bench/results/class_throughput.json``, two a round trip). This bench measures, in a real sandbox worker
(spawned by the grader's own zygote, isolated as in grading):

* **lent round trip**: student code in the worker calls ``env.duel(a, b)`` ``n`` times on a lent object
  whose method returns 1.0 at once, with the arguments as Python ints (the reference's ``rucb``) and as
  numpy ints (a student's ``np.argmax``), inside one grader request with a deadline, as in a test;
* **pipe floor**: the same ping-pong with no protocol at all (a bare Python echo process, one ``os.read``
  and one ``os.write`` a side): what the kernel and the interpreter cost per round trip on this machine at
  this load, under any protocol; left to the scheduler (which on an idle machine puts the two on different
  CPUs) and with both pinned to one CPU (as the grader pins a worker while its callbacks come quickly,
  ``autograder.core.pairing``);
* **plain call**: the grader calls a worker function ``ident(x)`` ``n`` times, one request each, with
  ``x`` a Python int and an 8-element float64 array.

For each it records, per round trip, the CPU time of the grader's main thread (``time.thread_time``), the
worker's CPU time (its ``/proc/PID/schedstat``), wall time, and the worker's run delay (time runnable but
waiting for a CPU: the machine's load). The worker's own loop (the same ``duels`` on a local object) is
measured too and subtracted, so "overhead" is what the channel adds. CPU times are the figure to read
on a loaded machine; wall time there is mostly waiting for a CPU.

It also times each piece of a round trip in this process alone (encoding, framing, deadline
bookkeeping, a read of ``/proc/PID/schedstat``, a ``poll``, the pipe's write and read), and counts how
many of each the grader's side does per lent round trip (by wrapping the functions while a short run
goes), so the split of the grader's share can be read off.

The settings are fixed here, before any run: ``N`` round trips per repeat, ``REPEATS`` repeats, the
two argument kinds, the two plain-call values, ``PIECE_ITERATIONS`` iterations per piece.
``--record`` merges this run under ``--label`` into ``bench/results/channel.json`` with its ``meta``.

Before and after a change, alternate the two (the earlier commit's grader from
``git archive COMMIT autograder rlcourse ... | tar -x -C DIR``, this script copied into ``DIR/bench``, run with
``PYTHONPATH=DIR BENCH_COMMIT=COMMIT`` and ``--out`` this file) as ``before-i`` and ``after-i``, so that each pair
meets about the same load; then ``--summarise NAME --pairs i,j,...`` writes their side-by-side summary under
``paired_summaries`` in the results file.
"""
from __future__ import annotations

import argparse
import json
import os
import select
import signal
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench import run_record  # noqa: E402

import numpy as np  # noqa: E402

N = 4000
REPEATS = 5
PIECE_ITERATIONS = 20_000
KEYS = ("grader_cpu", "grader_process_cpu", "worker_cpu", "wall", "worker_run_delay")
"""Per round trip: the grader's main thread's CPU (the channel's work), its whole process's (with the output drain
and the tree guard threads), the worker's CPU, wall time, and the worker's wait for a CPU."""
TARGET_US = 50.0
"""The issue's aim: at most this much worker-to-grader overhead (both sides' CPU) per lent round trip."""

WORKER_CELL = '''
import numpy as np

def duels(env, n, as_numpy):
    a, b = (np.int64(0), np.int64(1)) if as_numpy else (0, 1)
    total = 0.0
    for _ in range(n):
        total += env.duel(a, b)
    return total

class Local:
    def duel(self, a, b):
        return 1.0

def local_duels(n, as_numpy):
    return duels(Local(), n, as_numpy)

def ident(x):
    return x
'''


class Env:
    """The lent object: a duel that answers at once, so what is timed is the channel."""

    n_arms = 2

    def duel(self, a, b) -> float:
        return 1.0


def schedstat(pid: int) -> tuple[int, int]:
    """(CPU ns, run-delay ns) of ``pid``'s main thread."""
    with open(f"/proc/{pid}/schedstat") as f:
        run, wait, _ = f.read().split()
    return int(run), int(wait)


def meta() -> dict:
    """The run's record; ``uncommitted_files`` counts the grader's own files changed since the commit."""
    return run_record.meta(["autograder/sandbox", "autograder/core"])

def start_session():
    from autograder.core import course
    from autograder.core.session import Cell, Session
    from autograder.core.supervisor import Zygote
    from autograder.sandbox.config import Limits, SpawnConfig

    zygote = Zygote(["numpy"])
    limits = Limits(call_seconds=600.0, test_seconds=600.0, submission_seconds=3600.0)
    session = Session(zygote, [Cell("bench", WORKER_CELL, stub="duels")], SpawnConfig(course.sandbox_view(()), limits))
    session.start()
    assert session.status["bench"].ok, session.status["bench"].message
    return zygote, session


def measure(session, run) -> dict:
    """One timed run: grader main-thread CPU, worker CPU, worker run delay and wall, in ns."""
    pid = session.worker.pid
    w0, d0 = schedstat(pid)
    g0, p0, t0 = time.thread_time_ns(), time.process_time_ns(), time.perf_counter_ns()
    run()
    g1, p1, t1 = time.thread_time_ns(), time.process_time_ns(), time.perf_counter_ns()
    w1, d1 = schedstat(pid)
    return {"grader_cpu": g1 - g0, "grader_process_cpu": p1 - p0, "worker_cpu": w1 - w0,
            "worker_run_delay": d1 - d0, "wall": t1 - t0}


def per_op(samples: list[dict], n: int, key: str) -> list[float]:
    return [s[key] / n / 1000 for s in samples]


def summary(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "per_repeat": values}


def busy_lent(seconds: float) -> None:
    """Another grader at work beside the measured one (``--alongside``): a session of its own whose worker calls a
    lent object back as fast as it can for ``seconds``; prints ``ready`` once its worker has started."""
    from autograder.core.session import Lend, Namespace

    zygote, session = start_session()
    student = Namespace(session, "student")
    print("ready", flush=True)
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            student.duels(Lend(Env(), ("duel",), ("n_arms",)), 2000, False, timeout=600)
    except KeyboardInterrupt:  # the measured grader is done
        pass
    finally:
        session.close()
        zygote.close()


def start_alongside(k: int, seconds: float) -> list[subprocess.Popen]:
    """``k`` other graders making lent round trips (:func:`busy_lent`) while this one is measured, started and
    ready before it returns."""
    others = [subprocess.Popen([sys.executable, __file__, "--busy-lent", str(seconds)], stdout=subprocess.PIPE, text=True)
              for _ in range(k)]
    for other in others:
        if other.stdout.readline().strip() != "ready":
            raise RuntimeError("a grader alongside did not start")
    return others


def end_to_end(n: int, repeats: int) -> dict:
    from autograder.core.session import Lend, Namespace

    zygote, session = start_session()
    student = Namespace(session, "student")
    out = {}
    try:
        student.duels(Lend(Env(), ("duel",), ("n_arms",)), 200, False, timeout=600)  # warm both sides
        for as_numpy in (False, True):
            kind = "numpy_int_args" if as_numpy else "python_int_args"
            lent, local = [], []
            pinnings = getattr(getattr(session, "pair", None), "pinnings", None)  # an earlier grader has no pairing
            for _ in range(repeats):
                session.begin_test()
                lent.append(measure(session, lambda: student.duels(Lend(Env(), ("duel",), ("n_arms",)), n, as_numpy,
                                                                   timeout=600)))
                local.append(measure(session, lambda: student.local_duels(n, as_numpy, timeout=600)))
                session.end_test()
            loop = statistics.median(per_op(local, n, "worker_cpu"))
            row = {key: summary(per_op(lent, n, key)) for key in KEYS}
            if pinnings is not None:
                row["pinnings"] = session.pair.pinnings - pinnings
            row["worker_own_loop_cpu"] = summary(per_op(local, n, "worker_cpu"))
            overhead = [g + w - loop for g, w in zip(per_op(lent, n, "grader_cpu"), per_op(lent, n, "worker_cpu"))]
            row["overhead_cpu_both_sides"] = summary(overhead)
            out[f"lent_round_trip_{kind}"] = row
        for name, value in (("plain_call_int", 3), ("plain_call_array8", np.arange(8.0))):
            samples = []
            calls = max(1, n // 4)
            for _ in range(repeats):
                session.begin_test()

                def run():
                    for _ in range(calls):
                        student.ident(value)
                samples.append(measure(session, run))
                session.end_test()
            row = {key: summary(per_op(samples, calls, key)) for key in KEYS}
            row["overhead_cpu_both_sides"] = summary([g + w for g, w in zip(per_op(samples, calls, "grader_cpu"),
                                                                          per_op(samples, calls, "worker_cpu"))])
            row["calls_per_repeat"] = calls
            out[name] = row
        out["grader_side_counts_per_lent_round_trip"] = count_grader_side(session, student)
    finally:
        session.close()
        zygote.close()
    return out


ECHO = """
import os, sys
r, w = int(sys.argv[1]), int(sys.argv[2])
while True:
    data = os.read(r, 64)
    if not data:
        break
    os.write(w, data)
"""


def pipe_floor(n: int, repeats: int, one_cpu: bool = False) -> dict:
    """The floor under any protocol: a 32-byte ping-pong over two pipes with a bare Python echo process (one
    blocking read and one write a side, no encoding, no deadline), CPU per round trip on both sides; with
    ``one_cpu``, this thread and the echo process pinned to one CPU."""
    to_r, to_w = os.pipe()
    from_r, from_w = os.pipe()
    child = subprocess.Popen([sys.executable, "-c", ECHO, str(to_r), str(from_w)], pass_fds=(to_r, from_w))
    os.close(to_r), os.close(from_w)
    samples = []
    mask = os.sched_getaffinity(0)
    if one_cpu:
        os.sched_setaffinity(child.pid, {min(mask)})
        os.sched_setaffinity(0, {min(mask)})
    try:
        message = b"x" * 32
        for _ in range(repeats + 1):
            c0, d0 = schedstat(child.pid)
            g0, t0 = time.thread_time_ns(), time.perf_counter_ns()
            for _ in range(n):
                os.write(to_w, message)
                os.read(from_r, 64)
            g1, t1 = time.thread_time_ns(), time.perf_counter_ns()
            c1, d1 = schedstat(child.pid)
            samples.append({"grader_cpu": g1 - g0, "worker_cpu": c1 - c0, "worker_run_delay": d1 - d0, "wall": t1 - t0})
    finally:
        os.sched_setaffinity(0, mask)
        os.close(to_w)
        child.wait()
        os.close(from_r)
    samples = samples[1:]  # the first warms both sides
    row = {key: summary(per_op(samples, n, key)) for key in ("grader_cpu", "worker_cpu", "wall", "worker_run_delay")}
    row["overhead_cpu_both_sides"] = summary([g + w for g, w in zip(per_op(samples, n, "grader_cpu"),
                                                                  per_op(samples, n, "worker_cpu"))])
    return row


def count_grader_side(session, student, n: int = 500) -> dict:
    """How many times the grader's side calls each piece per lent round trip (functions wrapped for a short run)."""
    import autograder.sandbox.wire as wire
    from autograder.core import session as session_module
    from autograder.core import supervisor
    from autograder.core.session import Lend

    counts: dict[str, int] = {}
    patched = []

    def wrap(owner, name, label):
        original = getattr(owner, name)

        def counted(*args, **kwargs):
            counts[label] = counts.get(label, 0) + 1
            return original(*args, **kwargs)
        setattr(owner, name, counted)
        patched.append((owner, name, original))

    for owner, name, label in ((wire, "_wait", "poll waits"), (supervisor.WorkerProcess, "cpu_wait", "/proc schedstat reads"),
                               (wire, "seconds_left", "deadline checks"), (wire.os, "write", "os.write"),
                               (wire.os, "readv", "os.readv"), (wire.json, "dumps", "json.dumps"),
                               (wire.json, "loads", "json.loads"), (wire, "_decode_header", "header decodes"),
                               (wire.FrameReader, "ready", "idle checks (pinned)"),
                               (session_module, "encode", "encode (session)"),
                               (session_module, "decode", "decode (session)")):
        if hasattr(owner, name):  # an earlier commit's grader may lack a piece
            wrap(owner, name, label)
    try:
        session.begin_test()
        student.duels(Lend(Env(), ("duel",), ()), n, False, timeout=600)
        session.end_test()
    finally:
        for owner, name, original in reversed(patched):
            setattr(owner, name, original)
    return {k: v / n for k, v in sorted(counts.items())}


def pieces(iterations: int) -> dict:
    """Microseconds of CPU (this thread) per call of each piece of a round trip, in this process alone."""
    from autograder.sandbox import wire
    from autograder.sandbox.wire import FrameReader, decode, encode, send_message

    def timed(fn, k=iterations) -> float:
        fn()
        start = time.thread_time_ns()
        for _ in range(k):
            fn()
        return (time.thread_time_ns() - start) / k / 1000

    out = {}
    args_py, args_np = [[0, 1], {}], [[np.int64(0), np.int64(1)], {}]
    out["encode duel args (python ints)"] = timed(lambda: encode(args_py))
    out["encode duel args (numpy ints)"] = timed(lambda: encode(args_np))
    tree_py, blobs_py = encode(args_py)
    tree_np, blobs_np = encode(args_np)
    out["decode duel args (python ints)"] = timed(lambda: decode(tree_py, blobs_py, None))
    out["decode duel args (numpy ints)"] = timed(lambda: decode(tree_np, [bytearray(b) for b in blobs_np], None))
    out["encode answer 1.0"] = timed(lambda: encode(1.0))
    header = {"callback": {"lent": 1, "method": "duel"}, "args": tree_py}
    out["json.dumps callback header"] = timed(lambda: json.dumps(dict(header, nblobs=0), allow_nan=False).encode())
    if hasattr(wire, "_JSON"):
        out["header with the wire's kept JSON encoder"] = timed(lambda: wire._JSON.encode(dict(header, nblobs=0)).encode())
    raw = json.dumps(dict(header, nblobs=0)).encode()
    out["json.loads callback header"] = timed(lambda: json.loads(raw.decode()))
    if hasattr(wire, "_decode_header"):
        out["the wire's header decoder"] = timed(lambda: wire._decode_header(raw.decode()))
    out["frame pack (struct + join)"] = timed(lambda: b"".join([struct.pack(">I", len(raw)), raw]))
    r, w = os.pipe()
    try:
        poller = select.poll()
        poller.register(r, select.POLLIN)
        os.write(w, b"x")

        def new_poll():
            p = select.poll()
            p.register(r, select.POLLIN)
            p.poll(0)
        out["select.poll() + register + poll (ready fd)"] = timed(new_poll)
        out["poll on a kept poller (ready fd)"] = timed(lambda: poller.poll(0))
        os.read(r, 1)
        buf = bytearray(len(raw) + 4)
        view = memoryview(buf)

        def write_read():
            os.write(w, struct.pack(">I", len(raw)) + raw)
            os.readv(r, [view])
        out["pipe os.write + os.readv (one small frame)"] = timed(write_read)
        reader = FrameReader(r)
        frame = struct.pack(">I", len(raw)) + raw

        def send_read(deadline):
            os.write(w, frame)
            reader.read_message(deadline=deadline)
        out["send + FrameReader.read_message, no deadline"] = timed(lambda: send_read(None))
        far = time.monotonic() + 3600
        out["send + FrameReader.read_message, monotonic deadline"] = timed(lambda: send_read(far))
        out["send_message (header only, blocking fd)"] = timed(lambda: (send_message(w, header), os.readv(r, [view])))
    finally:
        os.close(r), os.close(w)
    me = os.getpid()

    def read_schedstat():
        with open(f"/proc/{me}/schedstat") as f:
            return int(f.read().split()[1])
    out["read /proc/PID/schedstat"] = timed(read_schedstat)
    out["time.monotonic()"] = timed(time.monotonic)
    out["wire.seconds_left(float deadline)"] = timed(lambda: wire.seconds_left(far))
    return out


def summarise(path: Path, only: list[str] | None = None) -> dict:
    """The paired runs (``before-i`` / ``after-i``; those with ``i`` in ``only`` where given) of ``path`` side by
    side: per case, the median CPU overhead per round trip (both sides) of each run, with the load average
    (1 min) it started at."""
    data = json.loads(path.read_text())
    runs = data.get("runs", {})
    pairs = sorted({label.split("-", 1)[1] for label in runs if label.startswith("before-")}
                   & {label.split("-", 1)[1] for label in runs if label.startswith("after-")})
    pairs = [p for p in pairs if only is None or p in only]
    cases = [c for c in runs[f"before-{pairs[0]}"]["end_to_end_us"] if "overhead_cpu_both_sides" in
             runs[f"before-{pairs[0]}"]["end_to_end_us"][c]] if pairs else []
    out = {}
    for case in cases:
        row = {}
        for side in ("before", "after"):
            values = [runs[f"{side}-{p}"]["end_to_end_us"][case]["overhead_cpu_both_sides"]["median"] for p in pairs]
            row[f"{side}_us"] = {"per_pair": [round(v, 1) for v in values], "median": round(statistics.median(values), 1)}
        row["ratio_after_to_before"] = round(row["after_us"]["median"] / row["before_us"]["median"], 3)
        out[case] = row
    loads = {f"{side}-{p}": round(runs[f"{side}-{p}"]["meta"]["load"][0], 2) for p in pairs for side in ("before", "after")}
    def floor_median(key: str) -> float | None:  # a floor over the "after" runs that recorded it
        values = [runs[f"after-{p}"][key]["overhead_cpu_both_sides"]["median"] for p in pairs if key in runs[f"after-{p}"]]
        return round(statistics.median(values), 2) if values else None

    commits = {side: sorted({runs[f"{side}-{p}"]["meta"].get("commit") for p in pairs}) for side in ("before", "after")}
    return {"pairs": len(pairs), "commits": commits, "cases": out, "load_at_start": loads,
            "pipe_floor_us_median": floor_median("pipe_floor_us"),
            "pipe_floor_one_cpu_us_median": floor_median("pipe_floor_one_cpu_us"),
            "target_us": TARGET_US,
            "lent_round_trip_within_target": {case: row["after_us"]["median"] <= TARGET_US for case, row in out.items()
                                              if case.startswith("lent_round_trip")}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--label", help="where this run goes in the results file (before-1, after-1, ...)")
    parser.add_argument("--summarise", metavar="NAME",
                        help="only write, under this name, the paired summary of the runs in --out (before-i against "
                             "after-i, for the i in --pairs)")
    parser.add_argument("--pairs", help="comma-separated: which pairs --summarise takes (default all)")
    parser.add_argument("--n", type=int, default=N)
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--record", action="store_true")
    parser.add_argument("--alongside", type=int, default=0, metavar="K",
                        help="measure while K other graders (each a grader and its worker) make lent round trips, as "
                             "a batch's other jobs would")
    parser.add_argument("--busy-lent", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "results" / "channel.json",
                        help="the results file --record merges into")
    args = parser.parse_args()
    if args.summarise:
        data = json.loads(args.out.read_text())
        summary_ = summarise(args.out, args.pairs.split(",") if args.pairs else None)
        data.setdefault("paired_summaries", {})[args.summarise] = summary_
        args.out.write_text(json.dumps(data, indent=1) + "\n")
        print(json.dumps(summary_, indent=1))
        return
    if args.busy_lent is not None:
        busy_lent(args.busy_lent)
        return
    if not args.label:
        parser.error("--label is needed to run")
    run_meta = meta()
    others = start_alongside(args.alongside, 600.0) if args.alongside else []
    try:
        result = {"meta": run_meta, "settings": {"n": args.n, "repeats": args.repeats,
                                                  "piece_iterations": PIECE_ITERATIONS, "alongside": args.alongside},
                  "pipe_floor_us": pipe_floor(args.n, args.repeats),
                  "pipe_floor_one_cpu_us": pipe_floor(args.n, args.repeats, one_cpu=True),
                  "end_to_end_us": end_to_end(args.n, args.repeats),
                  "pieces_us_cpu": pieces(PIECE_ITERATIONS)}
    finally:
        for other in others:  # an interrupt lets each close its session and zygote
            other.send_signal(signal.SIGINT)
        for other in others:
            try:
                other.wait(timeout=30)
            except subprocess.TimeoutExpired:
                other.kill()
    result["meta"]["load_at_end"] = list(os.getloadavg())
    for name, row in result["end_to_end_us"].items():
        if "overhead_cpu_both_sides" in row:
            print(f"{name}: overhead {row['overhead_cpu_both_sides']['median']:.1f} µs CPU per round trip "
                  f"(grader {row['grader_cpu']['median']:.1f}, worker {row['worker_cpu']['median']:.1f}), "
                  f"wall {row['wall']['median']:.1f} µs, worker run delay {row['worker_run_delay']['median']:.1f} µs")
    for key, what in (("pipe_floor_us", "pipe ping-pong floor"), ("pipe_floor_one_cpu_us", "on one CPU")):
        floor = result[key]
        print(f"{what}: {floor['overhead_cpu_both_sides']['median']:.1f} µs CPU per round trip "
              f"(parent {floor['grader_cpu']['median']:.1f}, echo {floor['worker_cpu']['median']:.1f}), "
              f"wall {floor['wall']['median']:.1f} µs")
    print("grader side per lent round trip:", result["end_to_end_us"]["grader_side_counts_per_lent_round_trip"])
    for name, us in result["pieces_us_cpu"].items():
        print(f"  {name}: {us:.2f} µs")
    print(f"load {run_meta['load']} -> {run_meta['load_at_end']}")
    if args.record:
        path = args.out
        data = json.loads(path.read_text()) if path.exists() else {}
        data.setdefault("description", "Per-message overhead of the grader-sandbox channel (bench/bench_channel.py): "
                                       "CPU microseconds per round trip on both sides, worker's own loop subtracted; "
                                       "wall and run delay show the machine's load.")
        data["target_us"] = TARGET_US
        data["command"] = f"python bench/bench_channel.py --label LABEL --record"
        data.setdefault("runs", {})[args.label] = result
        data["meta"] = run_meta
        path.write_text(json.dumps(data, indent=1) + "\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
