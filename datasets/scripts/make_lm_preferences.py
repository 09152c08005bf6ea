"""The preference set of ``hw5_lm_alignment``: pairs of SFT completions labelled by a simulated annotator.

    python datasets/scripts/make_lm_preferences.py      # about 2 minutes on one core

For each prompt (the first ``PROMPT_LEN`` tokens of a fresh review from the grammar: ``<bos>``
and four words), two completions are sampled from the shipped SFT model (``datasets/lm/sft.pt``,
temperature 1). A simulated annotator prefers completion ``a`` with the Bradley–Terry
probability ``sigmoid((gold(a) - gold(b)) / TEMPERATURE)`` on the gold reward of the whole
review (``rlcourse.reviews.gold_reward``). The held-out split and a separate set of evaluation
prompts (for measuring policies) come from other seeds. Writes ``datasets/lm/preferences.npz``:

- ``chosen``, ``rejected``: ``(N, 32)`` int16 token ids (prompt + completion + padding)
- ``gold_chosen``, ``gold_rejected``: ``(N,)`` gold rewards; ``test``: ``(N,)`` bool, the held-out split
- ``eval_prompts``: ``(M, PROMPT_LEN)`` int16 prompts for evaluating policies
- ``prompt_len``, ``temperature``: scalars
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from rlcourse import data, reviews
from rlcourse.lm import generate, load_lm
from rlcourse.seeding import seed_everything

PROMPT_LEN = 5
TEMPERATURE = 0.25


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train", type=int, default=3000)
    p.add_argument("--test", type=int, default=500)
    p.add_argument("--eval-prompts", type=int, default=256)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    seed_everything(args.seed)
    sft = load_lm(data.verify("lm/sft.pt"))
    n = args.train + args.test
    prompts = torch.as_tensor(reviews.sample_corpus(n, seed=args.seed + 100)[0][:, :PROMPT_LEN])
    gen = torch.Generator().manual_seed(args.seed)
    def sample() -> np.ndarray:
        return torch.cat([generate(sft, chunk, reviews.MAX_LEN - PROMPT_LEN, generator=gen)
                          for chunk in prompts.split(250)]).numpy()

    a, b = sample(), sample()
    ga, gb = reviews.gold_reward(a), reviews.gold_reward(b)
    rng = np.random.default_rng(args.seed)
    a_wins = rng.random(n) < 1.0 / (1.0 + np.exp(-(ga - gb) / TEMPERATURE))
    chosen, rejected = np.where(a_wins[:, None], a, b), np.where(a_wins[:, None], b, a)
    g_chosen, g_rejected = np.where(a_wins, ga, gb), np.where(a_wins, gb, ga)
    test = np.arange(n) >= args.train
    differ = g_chosen != g_rejected
    agreement = float(np.mean(g_chosen[differ] > g_rejected[differ]))
    eval_prompts = reviews.sample_corpus(args.eval_prompts, seed=args.seed + 200)[0][:, :PROMPT_LEN]
    out = data.DATASETS / "lm" / "preferences.npz"
    np.savez_compressed(out, chosen=chosen.astype(np.int16), rejected=rejected.astype(np.int16),
                        gold_chosen=g_chosen, gold_rejected=g_rejected, test=test,
                        eval_prompts=eval_prompts.astype(np.int16), prompt_len=PROMPT_LEN, temperature=TEMPERATURE)
    info = {"pairs_train": args.train, "pairs_test": args.test, "eval_prompts": args.eval_prompts,
            "annotator_temperature": TEMPERATURE, "label_agreement_with_gold": round(agreement, 4),
            "tied_gold_pairs": int((~differ).sum()), "sft_gold_mean": round(float(np.r_[ga, gb].mean()), 4)}
    data.record(out, __file__, argv, seed=args.seed, info=info)
    print(info)


if __name__ == "__main__":
    main()
