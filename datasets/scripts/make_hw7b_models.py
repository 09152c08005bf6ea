"""Make hw7b_ai_feedback's shipped models: the learned judge with planted biases, and PPO's policies along one run.

    python datasets/scripts/make_hw7b_models.py --seed 0        # a few minutes on one core

hw5's students write the Bradley-Terry loss and PPO's loss, and hw7b's release is readable while hw5 is
graded, so both fits live here, in instructor tooling the student release leaves out.

- ``datasets/hw7b/judge.pt``: the judge ``P(x beats y | x shown first) = sigmoid(s(x) - s(y) + c)``, a
  scalar-head copy of the SFT model ``s`` and a position offset ``c``, fitted jointly (AdamW, ``--judge-steps``
  batches of 64) by the logistic loss to labels of a *biased labeller* on the first ``--pairs`` training pairs
  of ``datasets/lm/preferences.npz``, each shown in a random order: the labeller prefers the review shown
  first with probability ``sigmoid((gold(x) - gold(y)) / 0.25 + LENGTH_BIAS * (len(x) - len(y)) +
  POSITION_BIAS)``: hw5's simulated person plus two planted biases, fixed before any run. The metadata
  holds the planted biases, the fitted offset ``position``, ``shift`` and ``scale`` (mean and sd of the raw
  scores on the pairs), the judge's length slope on those reviews, and its agreement on the held-out pairs
  with the labeller and with the gold reward, in each order.
- ``datasets/hw7b/ppo_iterNN.pt``: hw5's PPO (the reference solution's functions, hw5's given
  ``rlcourse.lm_training.ppo_train``) on hw6's shipped reward model, KL coefficient ``--ppo-beta``, batches of
  64, saved after 6, 12, ..., 30 iterations (five runs of growing length: each is a prefix of the next,
  the random draws coming in the same order), in half precision.

Seed 0 with the defaults is seed 0 of ``bench/bench_hw7b_ai_feedback.py``, which imports :func:`fit_judge`
and :func:`ppo_curve` from here for its other seeds.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from rlcourse import ai_feedback as A
from rlcourse import data
from rlcourse import group_rl as G
from rlcourse import lm_training as L
from rlcourse import reviews as R
from rlcourse.checkpoint import save_model
from rlcourse.lm import ScalarHeadLM, TinyLM, load_sft, save_lm

REPO = Path(__file__).resolve().parents[2]
LENGTH_BIAS = 0.25
"""Planted: logits the biased labeller adds per token of length the first review has over the second."""
POSITION_BIAS = 1.0
"""Planted: logits the biased labeller adds for the review shown first."""
PPO_ITERS = (6, 12, 18, 24, 30)
POSITION_LR = 0.02
"""Adam's step size for the judge's position offset (one scalar; the network's is ``lr``)."""


def biased_labels(first: torch.Tensor, second: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
    """The biased labeller's verdicts (1.0: the first wins), drawn with its probability (module docstring)."""
    d = ((A.gold(first) - A.gold(second)).numpy() / A.PERSON_TEMPERATURE
         + LENGTH_BIAS * (A.review_length(first) - A.review_length(second)).numpy() + POSITION_BIAS)
    return (rng.random(len(d)) < 1.0 / (1.0 + np.exp(-d))).astype(np.float32)


def judge_pairs(n_pairs: int, seed: int, test: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pairs of the preference file (training or held-out split), each in a random order, and biased labels."""
    prefs = R.load_preferences()
    idx = np.flatnonzero(prefs["test"] if test else ~prefs["test"])[:n_pairs]
    rng = np.random.default_rng(seed + (500 if test else 0))
    c, r = torch.as_tensor(prefs["chosen"][idx]), torch.as_tensor(prefs["rejected"][idx])
    swap = torch.as_tensor(rng.random(len(idx)) < 0.5)
    first, second = torch.where(swap[:, None], r, c), torch.where(swap[:, None], c, r)
    return first, second, torch.as_tensor(biased_labels(first, second, rng))


def fit_judge(sft: TinyLM, n_pairs: int, steps: int, seed: int, batch: int = 64, lr: float = 3e-4) -> A.Judge:
    """The judge fitted to the biased labeller's verdicts on ``n_pairs`` training pairs (see the module docstring),
    with its measured properties in ``judge.metadata``."""
    import copy

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    first, second, label = judge_pairs(n_pairs, seed)
    rm = ScalarHeadLM(copy.deepcopy(sft)).train()
    position = torch.zeros((), requires_grad=True)
    # the offset is one number: Adam moves a parameter by about lr a step, so it gets a step size of its own
    opt = torch.optim.AdamW([{"params": list(rm.parameters())},
                             {"params": [position], "lr": POSITION_LR, "weight_decay": 0.0}], lr=lr, weight_decay=0.01)
    t0 = time.perf_counter()
    for _ in range(steps):
        i = torch.randint(len(first), (batch,), generator=gen)
        logits = rm.score(first[i]) - rm.score(second[i]) + position
        loss = F.binary_cross_entropy_with_logits(logits, label[i])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    rm.eval()
    with torch.no_grad():
        raw = torch.cat([rm.score(x) for x in torch.cat([first, second]).split(512)]).double()
    judge = A.Judge(rm, float(position.detach()), float(raw.mean()), float(raw.std()))
    both = torch.cat([first, second])
    slope = float(np.polyfit(A.review_length(both).numpy(), judge.raw(both).numpy(), 1)[0])
    tf, ts, tl = judge_pairs(500, seed, test=True)
    p_fs, p_sf = judge(tf, ts), judge(ts, tf)
    g = A.gold(tf) - A.gold(ts)
    differ = g != 0
    judge.metadata = dict(
        planted_length_bias=LENGTH_BIAS, planted_position_bias=POSITION_BIAS, position=judge.position,
        shift=judge.shift, scale=judge.scale, length_slope_on_pairs=round(slope, 4), steps=steps, batch=batch, lr=lr, position_lr=POSITION_LR,
        seed=seed, pairs=n_pairs, fit_seconds=round(time.perf_counter() - t0, 1),
        test_agreement_with_labeller=round(float(((p_fs > 0.5).float() == tl).float().mean()), 4),
        test_agreement_with_gold_first_order=round(float(((p_fs > 0.5) == (g > 0))[differ].float().mean()), 4),
        test_agreement_with_gold_swapped_order=round(float(((p_sf < 0.5) == (g > 0))[differ].float().mean()), 4),
        test_inconsistent_fraction=round(float(((p_fs > 0.5) == (p_sf > 0.5)).float().mean()), 4))
    return judge


def solution_namespace(path: Path) -> dict:
    """A solution notebook's setup and stub cells, executed in a fresh namespace (hw5's PPO functions)."""
    import nbformat

    ns: dict = {"__name__": "__script__"}
    for cell in nbformat.read(path, as_version=4).cells:
        meta = cell.metadata
        if cell.cell_type == "code" and ("setup" in meta.get("tags", []) or meta.get("nbgrader", {}).get("solution")):
            with contextlib.redirect_stdout(io.StringIO()):
                exec(compile(cell.source, f"<{meta.get('nbgrader', {}).get('grade_id')}>", "exec"), ns)
    return ns


def ppo_curve(sft: TinyLM, seed: int, beta: float, iters: tuple[int, ...] = PPO_ITERS, batch: int = 64,
              n_pairs: int = 3000) -> dict[int, tuple[TinyLM, float]]:
    """hw5's PPO on hw6's shipped reward model: ``{iterations: (policy, seconds)}``, one run per length."""
    hw5 = solution_namespace(REPO / "solutions" / "hw5_lm_alignment" / "hw5_lm_alignment.ipynb")
    rm = G.load_reward_model()
    prefs = R.load_preferences()
    p = prefs["prompt_len"]
    tr = np.flatnonzero(~prefs["test"])[:n_pairs]
    prompts = torch.as_tensor(prefs["chosen"][tr, :p])
    out = {}
    for n in iters:
        t0 = time.perf_counter()
        policy, _ = L.ppo_train(sft, lambda s: G.proxy_score(rm, s), prompts, hw5["token_log_probs"],
                                hw5["kl_penalised_rewards"], hw5["ppo_token_loss"], beta=beta, iters=n, batch=batch,
                                seed=seed)
        out[n] = (policy, time.perf_counter() - t0)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pairs", type=int, default=3000)
    parser.add_argument("--judge-steps", type=int, default=150)
    parser.add_argument("--ppo-beta", type=float, default=0.05, help="PPO's KL coefficient (hw5's middle value)")
    parser.add_argument("--skip-ppo", action="store_true")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    sft = load_sft()
    judge = fit_judge(sft, args.pairs, args.judge_steps, args.seed)
    out = data.DATASETS / A.JUDGE_FILE
    save_model(judge.model, out, asdict(sft.cfg), **judge.metadata)
    data.record(out, __file__, argv, seed=args.seed, info=judge.metadata)
    print(f"judge: {judge.metadata} -> {out}")
    if args.skip_ppo:
        return
    for n, (policy, seconds) in ppo_curve(sft, args.seed, args.ppo_beta).items():
        info = dict(iteration=n, kl_coef=args.ppo_beta, batch=64, seed=args.seed, reward="hw6/reward_model.pt",
                    train_seconds=round(seconds, 1), precision="float16")
        out = data.DATASETS / f"hw7b/ppo_iter{n:02d}.pt"
        half = TinyLM(sft.cfg)
        half.load_state_dict(policy.state_dict())
        half.half()
        save_lm(half, out, **info)
        data.record(out, __file__, argv, seed=args.seed, info=info)
        print(f"PPO after {n} iterations ({seconds:.0f} s) -> {out}")


if __name__ == "__main__":
    main()
