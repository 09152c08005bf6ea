"""Make hw7_verifier_rl's base model: a tiny transformer pretrained on a "web" of three-digit additions.

    python datasets/scripts/make_hw7_models.py --seed 0          # about four minutes on one busy core

The web (``rlcourse.verifier_rl.web_documents``) holds documents of one or two equations ``aaa+bbb=sum``,
two joined by ``;``, each document closed by ``<eos>``; one answer in ten has a digit altered. The model
(``rlcourse.verifier_rl.config()``) minimises the next-token cross-entropy of every real token of the
documents (AdamW, ``--steps`` batches of ``--batch`` fresh documents, a cosine learning-rate decay over
``--horizon`` steps, stopped early: the run is an early checkpoint of a longer one). It is
never shown the assignment's format, prompt then answer then ``<eos>``: after an answer the web continues
with ``;`` as often as it stops, so the base model fails the format about half the time (zero-shot).

Writes ``datasets/hw7/base.pt`` with, in its metadata, the training settings and what the script measured
on 500 held-out problems: the fraction of sampled answers (temperature 1) that are well-formed and correct,
and of greedy ones. The checker here is the script's own (the students write theirs in the notebook).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import data
from rlcourse import verifier_rl as V
from rlcourse.lm import TinyLM, save_lm


def _check(tokens: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """(well-formed, correct) of each row: an instructor's copy of the rule, independent of any student's."""
    ok, right = [], []
    for row in tokens.tolist():
        p = row[1:V.PROMPT_LEN - 1]
        a = int("".join(str(t - V.DIGIT0) for t in p[:3]))
        b = int("".join(str(t - V.DIGIT0) for t in p[4:7]))
        out = row[V.PROMPT_LEN:]
        if V.EOS not in out:
            ok.append(False); right.append(False); continue
        ans = out[:out.index(V.EOS)]
        good = 1 <= len(ans) <= 4 and all(V.DIGIT0 <= t <= V.DIGIT0 + 9 for t in ans) \
            and (len(ans) == 1 or ans[0] != V.DIGIT0)
        ok.append(good)
        right.append(good and int("".join(str(t - V.DIGIT0) for t in ans)) == a + b)
    return np.array(ok), np.array(right)


def pretrain(steps: int, batch: int, lr: float, seed: int, horizon: int | None = None,
             log_every: int = 500) -> tuple[TinyLM, list]:
    """The base model after ``steps`` AdamW steps on fresh web documents, and a log of (step, loss, seconds).

    The learning rate warms up over 100 steps, then follows a cosine from ``lr`` to ``lr / 10`` over ``horizon``
    steps (``steps`` when not given): stopping before the horizon keeps the rate high, as an early checkpoint
    of a longer run would."""
    horizon = horizon or steps
    torch.manual_seed(seed)
    model = TinyLM(V.config()).train()
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=0.01, betas=(0.9, 0.98))
    log, t0, running = [], time.perf_counter(), None
    for step in range(steps):
        for group in opt.param_groups:    # warm-up of 100 steps, then cosine decay to a tenth
            group["lr"] = lr * min(1.0, (step + 1) / 100) * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(step / horizon, 1.0))))
        x = V.web_documents(batch, seed=seed * 1_000_003 + step)
        logits = model(x[:, :-1])
        target = x[:, 1:]
        loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), target.reshape(-1), ignore_index=V.PAD)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        running = loss.item() if running is None else 0.98 * running + 0.02 * loss.item()
        if (step + 1) % log_every == 0:
            log.append((step + 1, round(running, 4), round(time.perf_counter() - t0, 1)))
            print(f"step {step + 1}: loss {running:.4f}  {time.perf_counter() - t0:.0f} s", flush=True)
    return model.eval(), log


def measure(model: TinyLM, n: int = 500, seed: int = 12345) -> dict:
    """Well-formed and correct fractions on ``n`` held-out problems: one sample each at temperature 1, and greedy."""
    a, b = V.problems(n, seed)
    x = V.prompts(a, b)
    sampled = V.sample(model, x, 1, seed=seed)
    greedy = V.sample(model, x, 1, seed=seed, temperature=1e-6)
    fs, cs = _check(sampled)
    fg, cg = _check(greedy)
    return dict(format_sampled=round(float(fs.mean()), 4), correct_sampled=round(float(cs.mean()), 4),
                format_greedy=round(float(fg.mean()), 4), correct_greedy=round(float(cg.mean()), 4))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--horizon", type=int, default=8000, help="length of the cosine learning-rate decay")
    parser.add_argument("--batch", type=int, default=128)
    parser.add_argument("--lr", type=float, default=2e-3)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    model, log = pretrain(args.steps, args.batch, args.lr, args.seed, horizon=args.horizon)
    seconds = time.perf_counter() - t0
    info = dict(steps=args.steps, horizon=args.horizon, batch=args.batch, lr=args.lr, seed=args.seed, typo=0.1, two_equations=0.5,
                train_seconds=round(seconds, 1), final_loss=log[-1][1] if log else float("nan"),
                params=model.n_params(), **measure(model))
    out = data.DATASETS / V.BASE_FILE
    save_lm(model, out, **info)
    data.record(out, __file__, argv, seed=args.seed, info=info)
    print(info)


if __name__ == "__main__":
    main()
