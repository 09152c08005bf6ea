"""Make the item-comparison data set of hw3_preferences: pairwise comparisons with ties among a
few dozen items, drawn from hidden utilities through Bradley–Terry with Rao–Kupper ties.

    python datasets/scripts/make_items.py            # writes datasets/items/*.npz and records them

Model (see ``rlcourse.preferences``): for a pair (i, j) with utility difference d = u_i - u_j,
P(i wins) = sigmoid(d - eta), P(j wins) = sigmoid(-d - eta), P(tie) = the rest, eta = log(theta).
Pairs are drawn uniformly among distinct items. The hidden utilities ship in their own file,
centred to mean zero (utilities are identified only up to an additive constant).
"""
from __future__ import annotations

import argparse

import numpy as np

from rlcourse import data
from rlcourse.preferences import random_pairs, rao_kupper_probabilities, sample_labels

OUT = data.DATASETS / "items"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n-items", type=int, default=40)
    parser.add_argument("--n-comparisons", type=int, default=6000)
    parser.add_argument("--utility-std", type=float, default=1.0, help="utilities ~ N(0, std^2), then centred")
    parser.add_argument("--log-theta", type=float, default=0.3, help="Rao–Kupper tie parameter eta = log(theta)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    utilities = rng.normal(0.0, args.utility_std, size=args.n_items)
    utilities -= utilities.mean()
    pairs = random_pairs(np.arange(args.n_items), args.n_comparisons, rng)
    diff = utilities[pairs[:, 0]] - utilities[pairs[:, 1]]
    mu = sample_labels(diff, args.log_theta, rng)
    _, tie, _ = rao_kupper_probabilities(diff, args.log_theta)

    OUT.mkdir(parents=True, exist_ok=True)
    comp_path, util_path = OUT / "comparisons.npz", OUT / "true_utilities.npz"
    np.savez_compressed(comp_path, i=pairs[:, 0].astype(np.int16), j=pairs[:, 1].astype(np.int16), mu=mu)
    np.savez_compressed(util_path, utilities=utilities)
    info = {"n_items": args.n_items, "n_comparisons": args.n_comparisons, "utility_std": args.utility_std,
            "tie_model": "Rao-Kupper: P(i>j)=sigmoid(d-eta), P(j>i)=sigmoid(-d-eta), P(tie)=rest, d=u_i-u_j",
            "log_theta": args.log_theta, "theta": float(np.exp(args.log_theta)),
            "label_convention": "mu=1 first item wins, 0 second wins, 0.5 tie",
            "tie_fraction": round(float((mu == 0.5).mean()), 4),
            "expected_tie_fraction": round(float(tie.mean()), 4),
            "pair_sampling": "uniform over distinct items, with repetition",
            "utilities_file": "items/true_utilities.npz"}
    data.record(comp_path, __file__, argv, seed=args.seed, info=info)
    data.record(util_path, __file__, argv, seed=args.seed,
                info={"n_items": args.n_items, "centred": True, "comparisons_file": "items/comparisons.npz"})
    print(f"{args.n_comparisons} comparisons among {args.n_items} items, {info['tie_fraction']:.1%} ties -> {OUT}")


if __name__ == "__main__":
    main()
