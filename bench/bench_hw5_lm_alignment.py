"""Benchmark of hw5_lm_alignment: gold reward and KL of SFT, PPO, DPO and best-of-n over seeds, the
reward-KL frontier at matched KL, wall times, and interoperability with Hugging Face GPT-2 and TRL.
Prints the Markdown tables that the README shows.

    python bench/bench_hw5_lm_alignment.py                    # 3 seeds + interop (about 45 min on one core)
    python bench/bench_hw5_lm_alignment.py --seeds 1 --skip-interop
    python bench/bench_hw5_lm_alignment.py --only-interop     # GPT-2 / TRL checks only (about a minute)
    python bench/bench_hw5_lm_alignment.py --time-notebook    # also time the notebook, FAST and full
    python bench/bench_hw5_lm_alignment.py --skip-interop --record   # and write bench/results/hw5_lm_alignment.json

With ``--record``, each finished seed is kept in ``bench/results/hw5_lm_alignment.partial.json`` (a run that
stops resumes there, skipping the seeds it has) and the results file is written when every seed is done: the
budgets, every method's figures per seed, and the matched-KL frontier the tables print.

Every number comes from the reference solutions in ``solutions/hw5_lm_alignment`` (its setup and stub
cells, executed here) on the shipped SFT model and preference set, with the notebook's full budgets.
The interoperability part runs in the benchmark-only environment ``.venv-bench-lm`` (pins in
``bench/requirements-hw5.txt``: transformers and trl), as a subprocess of this script.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from bench.run_record import meta  # noqa: E402

RESULTS = REPO / "bench" / "results" / "hw5_lm_alignment.json"
PARTIAL = REPO / "bench" / "results" / "hw5_lm_alignment.partial.json"
NOTEBOOK = REPO / "solutions" / "hw5_lm_alignment" / "hw5_lm_alignment.ipynb"
BENCH_VENV = REPO / ".venv-bench-lm" / "bin" / "python"
# The notebook's full budgets (its parameters cell with FAST = False).
BUDGET = dict(RM_STEPS=120, N_EVAL=128, BON_NS=(4, 16, 64), PPO_BETAS=(0.01, 0.05, 0.2), PPO_ITERS=30,
              PPO_BATCH=64, DPO_BETAS=(0.05, 0.1, 0.5), DPO_STEPS=90)
STUBS = ("token_log_probs", "sequence_log_prob", "reward_model_loss", "kl_penalised_rewards", "ppo_token_loss",
         "dpo_loss", "best_of_n")


def notebook_cells(kinds: tuple[str, ...]) -> list:
    """Code cells of the solution notebook that are setup cells ("setup") or stubs ("stub")."""
    import nbformat

    out = []
    for cell in nbformat.read(NOTEBOOK, as_version=4).cells:
        meta = cell.metadata
        is_setup = "setup" in meta.get("tags", [])
        is_stub = bool(meta.get("nbgrader", {}).get("solution")) and cell.cell_type == "code"
        if cell.cell_type == "code" and (("setup" in kinds and is_setup) or ("stub" in kinds and is_stub)):
            out.append(cell)
    return out


def solution_namespace() -> dict:
    """The solution notebook's setup and stub cells, executed in a fresh namespace."""
    ns: dict = {"__name__": "__bench__"}
    for cell in notebook_cells(("setup", "stub")):
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(cell.source, f"<{cell.metadata.get('nbgrader', {}).get('grade_id')}>", "exec"), ns)
    return ns


def run_seed(ns: dict, seed: int) -> dict[str, dict]:
    """Every method's gold reward, proxy reward, KL and wall time for one seed, all on the same evaluation prompts."""
    import torch

    from rlcourse import lm_training as L
    from rlcourse import reviews as R
    from rlcourse.lm import completion_mask, generate, load_sft

    ns["seed_everything"](seed)
    sft, prefs = load_sft(), R.load_preferences()
    p, train = prefs["prompt_len"], torch.as_tensor(~prefs["test"])
    chosen, rejected = torch.as_tensor(prefs["chosen"]), torch.as_tensor(prefs["rejected"])
    eval_prompts = torch.as_tensor(prefs["eval_prompts"])[: BUDGET["N_EVAL"]]
    out: dict[str, dict] = {}
    t0 = time.perf_counter()
    rm = L.fit_reward_model(sft, chosen[train], rejected[train], ns["reward_model_loss"], BUDGET["RM_STEPS"], seed=seed)
    rm_time = time.perf_counter() - t0
    proxy = lambda s: ns["proxy_reward"](rm, s)  # noqa: E731
    sequence_log_prob = ns["sequence_log_prob"]

    def evaluate(policy):
        return L.evaluate(policy, sft, proxy, eval_prompts, seed,
                          log_prob_sums=lambda model, x, q: sequence_log_prob(model(x), x, completion_mask(x, q)))

    out["SFT"] = {**evaluate(sft), "seconds": 0.0}
    for n in BUDGET["BON_NS"]:
        t0 = time.perf_counter()
        gen = torch.Generator().manual_seed(seed * 1000 + n)
        best = ns["best_of_n"](lambda x: generate(sft, x, R.MAX_LEN - p, generator=gen), proxy, eval_prompts, n)
        out[f"best-of-{n}"] = {"gold": float(R.gold_reward(best.numpy()).mean()), "proxy": float(proxy(best).mean()),
                               "kl": float(np.log(n) - (n - 1) / n), "seconds": time.perf_counter() - t0 + rm_time}
    for beta in BUDGET["PPO_BETAS"]:
        t0 = time.perf_counter()
        policy, log = L.ppo_train(sft, proxy, chosen[train, :p], ns["token_log_probs"], ns["kl_penalised_rewards"],
                                  ns["ppo_token_loss"], beta=beta, iters=BUDGET["PPO_ITERS"], batch=BUDGET["PPO_BATCH"],
                                  seed=seed)
        seconds = time.perf_counter() - t0 + rm_time
        out[f"PPO beta={beta}"] = {**evaluate(policy), "seconds": seconds,
                                   "peak_gold_batch": float(log["gold"].max()), "last_gold_batch": float(log["gold"][-1])}
    for beta in BUDGET["DPO_BETAS"]:
        t0 = time.perf_counter()
        policy, _ = L.dpo_train(sft, chosen[train], rejected[train], p, sequence_log_prob, ns["dpo_loss"], beta=beta,
                                steps=BUDGET["DPO_STEPS"], seed=seed)
        seconds = time.perf_counter() - t0
        out[f"DPO beta={beta}"] = {**evaluate(policy), "seconds": seconds}
    for row in out.values():
        row.pop("tokens", None)
    return out


def mean_sd(values) -> str:
    v = np.asarray(values, dtype=float)
    return f"{v.mean():+.3f} ± {v.std():.3f}"


def frontier(runs: list[dict[str, dict]]) -> list[dict]:
    """Each trained policy (means over seeds) against best-of-n's gold reward interpolated at the same KL, with
    best-of-n's KL at its formula log n - (n - 1)/n; ``None`` where the policy's KL is beyond the largest n."""
    methods = list(runs[0])
    ns_ = sorted(int(m.split("-")[-1]) for m in methods if m.startswith("best-of"))
    bon_kl = np.array([0.0] + [np.log(n) - (n - 1) / n for n in ns_])
    bon_gold = np.array([np.mean([r["SFT"]["gold"] for r in runs])]
                        + [np.mean([r[f"best-of-{n}"]["gold"] for r in runs]) for n in ns_])
    rows = []
    for m in methods:
        if m.startswith(("PPO", "DPO")):
            kl, gold = float(np.mean([r[m]["kl"] for r in runs])), float(np.mean([r[m]["gold"] for r in runs]))
            ref = float(np.interp(kl, bon_kl, bon_gold)) if kl <= bon_kl[-1] else None
            rows.append({"policy": m, "kl": kl, "gold": gold, "best_of_n_gold_at_kl": ref,
                         "higher": None if ref is None else (m.split()[0] if gold > ref else "best-of-n"),
                         "largest_n": ns_[-1], "largest_n_kl": float(bon_kl[-1])})
    return rows


def print_tables(runs: list[dict[str, dict]]) -> None:
    from rlcourse import data

    methods = list(runs[0])
    print(f"\n### Gold reward and KL from the SFT model ({len(runs)} seed(s); mean ± sd over seeds; "
          f"{BUDGET['N_EVAL']} evaluation prompts for every method)\n")
    print("| method | gold reward | proxy reward | KL (nats) | wall time (s) |")
    print("|---|---:|---:|---:|---:|")
    for m in methods:
        col = lambda k: [r[m][k] for r in runs]  # noqa: E731
        kl = "≤ {:.2f} (bound)".format(col("kl")[0]) if m.startswith("best-of") else mean_sd(col("kl")).replace("+", "")
        print(f"| {m} | {mean_sd(col('gold'))} | {mean_sd(col('proxy'))} | {kl} | {np.mean(col('seconds')):.0f} |")
    print("\nWall times include training the reward model for best-of-n and PPO; best-of-n's KL is "
          "log n - (n - 1)/n, an upper bound for a discrete policy (equal only for a reward without atoms).")

    print("\n### The frontier at matched KL (means over seeds)\n")
    print("| policy | KL (nats) | gold reward | best-of-n at the same KL | higher gold |")
    print("|---|---:|---:|---:|---|")
    for row in frontier(runs):
        m, kl, gold, ref = row["policy"], row["kl"], row["gold"], row["best_of_n_gold_at_kl"]
        if ref is None:
            print(f"| {m} | {kl:.2f} | {gold:+.3f} | beyond best-of-{row['largest_n']} (KL {row['largest_n_kl']:.2f}) "
                  "| n/a |")
        else:
            print(f"| {m} | {kl:.2f} | {gold:+.3f} | {ref:+.3f} | {row['higher']} |")
    info = data.info("lm/sft.pt")["info"]
    print(f"\nSFT model: {info['params']:,} parameters, held-out perplexity {info['valid_perplexity']}, pretraining "
          f"{info['train_minutes']} min wall on this machine ({info['steps']} steps of {info['batch']} reviews).")


def _read_partial() -> dict:
    """The finished seeds of an interrupted ``--record`` run of the same budgets (empty if none or other budgets)."""
    try:
        state = json.loads(PARTIAL.read_text())
    except (OSError, ValueError):
        return {}
    return state.get("seeds", {}) if state.get("budget") == _budget_record() else {}


def _budget_record() -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in BUDGET.items()}


def _save(path: Path, data: dict) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)


def record(runs: dict[str, dict[str, dict]]) -> None:
    """The results file: budgets, every method per seed, the frontier; the partial file is then removed."""
    ordered = [runs[k] for k in sorted(runs, key=int)]
    _save(RESULTS, {"command": "python bench/bench_hw5_lm_alignment.py --skip-interop --record",
                    "budget": _budget_record(), "evaluation_prompts": BUDGET["N_EVAL"],
                    "best_of_n_kl": "log n - (n - 1)/n: an upper bound for a discrete policy, not measured",
                    "seeds": runs, "frontier": frontier(ordered), "meta": meta()})
    PARTIAL.unlink(missing_ok=True)
    print(f"recorded {RESULTS}", file=sys.stderr)


# ------------------------------------------------------------------------------------------------
# Interoperability (runs inside .venv-bench-lm, where transformers and trl are installed).
def interop_worker() -> None:
    import types
    from collections import defaultdict

    import torch
    import torch.nn.functional as F
    import transformers
    import trl
    from transformers import GPT2Config, GPT2ForSequenceClassification, GPT2LMHeadModel
    from trl.trainer.dpo_trainer import DPOTrainer
    from trl.trainer.utils import selective_log_softmax

    torch.manual_seed(0)
    ns: dict = {"torch": torch, "F": F, "np": np}
    for name, source in json.loads(sys.stdin.read()).items():    # the stub cells, sent by the parent
        exec(compile(source, name, "exec"), ns)
    cfg = GPT2Config(vocab_size=64, n_positions=32, n_embd=32, n_layer=2, n_head=2, pad_token_id=0, eos_token_id=2)
    lm, ref = GPT2LMHeadModel(cfg).eval(), GPT2LMHeadModel(cfg).eval()   # eval: no dropout, same logits twice
    b, t, p = 6, 16, 4
    tokens = torch.randint(3, 64, (2 * b, t))
    lengths = torch.randint(p + 1, t + 1, (2 * b,))
    attention = (torch.arange(t)[None] < lengths[:, None]).long()
    tokens = tokens * attention                                         # right padding with id 0
    completion = attention.clone()
    completion[:, :p] = 0
    rows = []

    logits = lm(input_ids=tokens, attention_mask=attention).logits
    direct = torch.gather(logits[:, :-1].log_softmax(-1), 2, tokens[:, 1:, None]).squeeze(-1) * completion[:, 1:]
    ours = ns["token_log_probs"](logits, tokens, completion)
    rows.append(("token_log_probs on GPT-2 logits vs a direct gather", float((ours[:, 1:] - direct).abs().max())))
    seq = ns["sequence_log_prob"](logits, tokens, completion)
    seq.sum().backward()
    grads = sum(int(p_.grad is not None and p_.grad.abs().sum() > 0) for p_ in lm.parameters())
    rows.append(("sequence_log_prob vs the summed gather (gradients reach "
                 f"{grads}/{len(list(lm.parameters()))} GPT-2 tensors)", float((seq - direct.sum(1)).abs().max())))

    # DPO loss: ours against TRL's DPOTrainer._compute_loss (loss_type "sigmoid") on the same batch.
    beta = 0.1
    with torch.no_grad():
        ref_logits = ref(input_ids=tokens, attention_mask=attention).logits
        ref_seq = ns["sequence_log_prob"](ref_logits, tokens, completion)
        logits = lm(input_ids=tokens, attention_mask=attention).logits
        pol_seq = ns["sequence_log_prob"](logits, tokens, completion)
    ours = float(ns["dpo_loss"](pol_seq[:b], pol_seq[b:], ref_seq[:b], ref_seq[b:], beta))

    def trl_forward(input_ids, attention_mask, labels, use_cache=False, fused_lm_head=True):
        """GPT-2 forward returning what TRL's fused head returns, log-probs by TRL's selective_log_softmax."""
        lg = lm(input_ids=input_ids, attention_mask=attention_mask).logits[:, :-1]
        lab = labels[:, 1:]
        lp = selective_log_softmax(lg, lab.clamp(min=0)) * (lab != -100)
        zeros = torch.zeros_like(lp)
        return types.SimpleNamespace(log_probs=lp, entropy=zeros, mean_logits=zeros, is_top1=zeros.bool())

    ident = lambda x: x  # noqa: E731
    trainer = types.SimpleNamespace(
        model=types.SimpleNamespace(training=True), accelerator=types.SimpleNamespace(device="cpu", gather_for_metrics=ident, gather=ident),
        aux_loss_enabled=False, ld_alpha=None, precompute_ref_logps=True, f_divergence_type="reverse_kl",
        loss_types=["sigmoid"], loss_weights=[1.0], beta=beta, label_smoothing=0.0, use_weighting=False,
        _metrics={"train": defaultdict(list), "eval": defaultdict(list)}, _total_train_tokens=0, _tp_size=1)
    inputs = {"input_ids": tokens, "attention_mask": attention, "completion_mask": completion,
              "ref_chosen_logps": ref_seq[:b], "ref_rejected_logps": ref_seq[b:]}
    with torch.no_grad():
        theirs = DPOTrainer._compute_loss(trainer, trl_forward, inputs, False)
    theirs = float(theirs[0] if isinstance(theirs, tuple) else theirs)
    rows.append((f"dpo_loss vs TRL DPOTrainer._compute_loss (sigmoid, beta={beta}); ours {ours:.6f}, TRL {theirs:.6f}",
                 abs(ours - theirs)))

    # The RLHF stubs and best-of-n on GPT-2: a generate() sampler and a sequence-classification reward model.
    rm = GPT2ForSequenceClassification(GPT2Config(**{**cfg.to_dict(), "num_labels": 1})).eval()
    prompts = torch.randint(3, 64, (3, p))
    gen = lambda x: lm.generate(x, attention_mask=torch.ones_like(x), do_sample=True, max_new_tokens=6,  # noqa: E731
                                min_new_tokens=6, pad_token_id=0)
    score = lambda s: rm(input_ids=s).logits.squeeze(-1).detach()  # noqa: E731
    best = ns["best_of_n"](gen, score, prompts, 4)
    ok = best.shape == (3, p + 6) and bool((best[:, :p] == prompts).all())
    rows.append(("best_of_n with GPT-2 generate() and a GPT-2 reward model: shape and prompts kept", 0.0 if ok else 1.0))
    mask = torch.zeros_like(best, dtype=torch.float)
    mask[:, p:] = 1
    lp = ns["token_log_probs"](lm(input_ids=best).logits, best, mask)
    with torch.no_grad():
        lp_ref = ns["token_log_probs"](ref(input_ids=best).logits, best, mask)
    rewards = ns["kl_penalised_rewards"](score(best), lp.detach(), lp_ref, mask, 0.1)
    loss = ns["ppo_token_loss"](lp, lp.detach(), rewards, torch.zeros_like(rewards), rewards, mask)
    loss.backward()
    rows.append(("kl_penalised_rewards + ppo_token_loss on GPT-2: finite loss with gradients",
                 0.0 if torch.isfinite(loss) else 1.0))
    print(json.dumps({"versions": {"torch": torch.__version__, "transformers": transformers.__version__,
                                   "trl": trl.__version__}, "rows": rows}))


def bench_interop() -> None:
    if not BENCH_VENV.exists():
        print(f"\n(interop skipped: create {BENCH_VENV.parent.parent} with `python3 -m venv .venv-bench-lm && "
              ".venv-bench-lm/bin/pip install -r bench/requirements-hw5.txt`)")
        return
    stubs = {c.metadata["nbgrader"]["grade_id"]: c.source for c in notebook_cells(("stub",))}
    proc = subprocess.run([str(BENCH_VENV), __file__, "--interop-worker"], input=json.dumps(stubs),
                          capture_output=True, text=True, cwd=REPO)
    if proc.returncode != 0:
        raise RuntimeError(f"interop worker failed:\n{proc.stderr[-3000:]}")
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    v = result["versions"]
    print(f"\n### Interoperability (torch {v['torch']}, transformers {v['transformers']}, trl {v['trl']}; "
          "randomly initialised GPT-2 from a config, no download)\n")
    print("| check | largest absolute difference | within 1e-5 |")
    print("|---|---:|---|")
    for name, diff in result["rows"]:
        print(f"| {name} | {diff:.1e} | {'yes' if diff < 1e-5 else 'NO'} |")


def time_notebook() -> None:
    print("\n### Notebook run times (python -m autograder run, this machine)\n")
    print("| mode | wall time (s) |")
    print("|---|---:|")
    for label, params in (("FAST = True", ["-p", "FAST=True"]), ("full budget", [])):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "autograder", "run", str(NOTEBOOK), *params, "--timeout", "3600"],
                       check=True, capture_output=True, cwd=REPO)
        print(f"| {label} | {time.perf_counter() - t0:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--skip-interop", action="store_true")
    parser.add_argument("--only-interop", action="store_true")
    parser.add_argument("--time-notebook", action="store_true")
    parser.add_argument("--record", action="store_true", help="write bench/results/hw5_lm_alignment.json (resumable)")
    parser.add_argument("--interop-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.interop_worker:
        interop_worker()
        return
    if not args.only_interop:
        import torch

        torch.set_num_threads(1)
        ns = solution_namespace()
        done = _read_partial() if args.record else {}
        for seed in range(args.seeds):
            if str(seed) in done:
                print(f"seed {seed}: kept from {PARTIAL.name}", file=sys.stderr, flush=True)
                continue
            t0 = time.perf_counter()
            done[str(seed)] = run_seed(ns, seed)
            print(f"seed {seed}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
            if args.record:
                _save(PARTIAL, {"budget": _budget_record(), "seeds": done})
        runs = {k: done[k] for k in map(str, range(args.seeds))}
        print_tables(list(runs.values()))
        if args.record:
            record(runs)
    if not args.skip_interop:
        bench_interop()
    if args.time_notebook:
        time_notebook()


if __name__ == "__main__":
    main()
