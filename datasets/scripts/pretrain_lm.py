"""Pretrain the tiny review model of ``hw5_lm_alignment`` on the grammar's corpus (the "SFT" model).

    python datasets/scripts/pretrain_lm.py                 # about 2 minutes on an idle core; resumes
    python datasets/scripts/pretrain_lm.py --steps 200 --out /tmp/lm   # a quick smoke run

Samples a corpus from ``rlcourse.reviews`` (seeded), trains ``rlcourse.lm.TinyLM`` by next-token
cross-entropy with AdamW and a cosine schedule, checkpoints every ``--ckpt-every`` steps (a
killed run resumes from the checkpoint), then writes ``datasets/lm/sft.pt`` with its measured
held-out perplexity and the gold reward of its samples, and records it in the MANIFEST.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import data, reviews
from rlcourse.checkpoint import atomic_save
from rlcourse.lm import LMConfig, TinyLM, generate, save_lm
from rlcourse.seeding import seed_everything

REPO = Path(__file__).resolve().parents[2]
PROMPT_LEN = 5


def lm_loss(model: TinyLM, batch: torch.Tensor) -> torch.Tensor:
    """Mean next-token cross-entropy over real tokens (targets that are not padding)."""
    logits = model(batch[:, :-1])
    return F.cross_entropy(logits.reshape(-1, logits.shape[-1]), batch[:, 1:].reshape(-1),
                           ignore_index=reviews.PAD_ID)


@torch.no_grad()
def evaluate(model: TinyLM, valid: torch.Tensor, seed: int) -> dict[str, float]:
    """Held-out perplexity per token, and the gold reward of completions of held-out prompts."""
    model.eval()
    nll = float(np.mean([lm_loss(model, b).item() for b in valid.split(512)]))
    gen = torch.Generator().manual_seed(seed)
    samples = generate(model, valid[:512, :PROMPT_LEN], reviews.MAX_LEN - PROMPT_LEN, generator=gen)
    terms = reviews.gold_terms(samples.numpy())
    data_gold = reviews.gold_reward(valid[:512].numpy())
    model.train()
    return {"valid_perplexity": math.exp(nll), "sample_gold": float(terms.gold.mean()),
            "corpus_gold": float(data_gold.mean()), "sample_ungrammatical": float(terms.ungrammatical.mean()),
            "sample_unfinished": float(terms.unfinished.mean())}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reviews", type=int, default=50_000, help="training reviews sampled from the grammar")
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ckpt-every", type=int, default=250)
    p.add_argument("--out", type=Path, default=REPO / "datasets" / "lm")
    p.add_argument("--threads", type=int, default=1, help="torch threads (1 is fastest on a busy 2-core machine)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    ckpt_path = args.out / "pretrain_ckpt.tmp"

    seed_everything(args.seed)
    t0 = time.time()
    train_np, _ = reviews.sample_corpus(args.reviews, seed=args.seed)
    valid_np, _ = reviews.sample_corpus(2000, seed=args.seed + 10_000)
    train, valid = torch.as_tensor(train_np), torch.as_tensor(valid_np)
    print(f"corpus: {len(train)} reviews, {int((train != 0).sum())} tokens ({time.time() - t0:.0f} s)", flush=True)

    model = TinyLM(LMConfig(vocab_size=len(reviews.VOCAB), context=reviews.MAX_LEN))
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.01, betas=(0.9, 0.98))
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: min(1.0, (s + 1) / 100) * 0.5 * (1 + math.cos(math.pi * min(s, args.steps) / args.steps)))
    step, elapsed = 0, 0.0
    if ckpt_path.exists():
        ck = torch.load(ckpt_path, weights_only=True)
        model.load_state_dict(ck["model"]); opt.load_state_dict(ck["opt"]); sched.load_state_dict(ck["sched"])
        step, elapsed = int(ck["step"]), float(ck["elapsed"])
        print(f"resumed at step {step}", flush=True)
    gen = torch.Generator().manual_seed(args.seed * 7919 + step)
    model.train()
    t_start, tokens_seen = time.time(), 0
    while step < args.steps:
        batch = train[torch.randint(len(train), (args.batch,), generator=gen)]
        loss = lm_loss(model, batch)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step(); sched.step()
        step += 1
        tokens_seen += int((batch != 0).sum())
        if step % 100 == 0:
            rate = tokens_seen / (time.time() - t_start)
            print(f"step {step} loss {loss.item():.3f} ({rate:,.0f} tokens/s)", flush=True)
        if step % args.ckpt_every == 0 or step == args.steps:
            atomic_save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                         "step": step, "elapsed": elapsed + time.time() - t_start}, ckpt_path)
    elapsed += time.time() - t_start
    metrics = evaluate(model, valid, seed=args.seed)
    print({k: round(v, 4) for k, v in metrics.items()}, f"train time {elapsed / 60:.1f} min", flush=True)
    out = args.out / "sft.pt"
    save_lm(model.eval(), out, **{k: round(v, 4) for k, v in metrics.items()}, train_minutes=round(elapsed / 60, 2),
            steps=args.steps, seed=args.seed)
    if args.out.resolve() == (REPO / "datasets" / "lm").resolve():
        data.record(out, __file__, argv, seed=args.seed,
                    info={"params": model.n_params(), **{k: round(v, 4) for k, v in metrics.items()},
                          "train_minutes": round(elapsed / 60, 2), "steps": args.steps, "batch": args.batch})
    ckpt_path.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
