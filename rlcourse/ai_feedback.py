"""Given tools of ``hw7b_ai_feedback``: annotators that are not people, a learned judge with planted biases,
and the loop that runs the students' preference round offline, iteratively or online.

hw7b reuses hw5's language, gold reward and SFT model (:mod:`rlcourse.reviews`, :mod:`rlcourse.lm`). What
its students write (one round of online DPO, the rule-list critic, the judge's position swap) lives in the
notebook; this module holds what the notebook gives them. None of it is one of hw5's or hw6's stubs: there
is no log-sigmoid here and no policy-gradient loss (the round that computes DPO's loss is passed in, as
:mod:`rlcourse.lm_training` takes its losses), and the judge is fitted by the instructors' script
``datasets/scripts/make_hw7b_models.py`` and shipped as weights.

An **annotator** is a function ``annotator(a, b) -> (N,)`` of two batches of reviews ``(N, T)`` (prompt,
completion, padding), the probability that ``a`` is the better one; a verdict of exactly 0.5 is "no
preference". The annotators here:

- :class:`SimulatedPerson`: hw5's simulated annotator, who prefers ``a`` with probability
  ``sigmoid((gold(a) - gold(b)) / 0.25)`` and answers with the verdict drawn (1.0 or 0.0);
- :data:`CONSTITUTION`: a written list of rules, each with the function that scores a review on it,
  for the students' ``rule_critic``;
- :class:`Judge`: a learned judge ``P(x beats y | x shown first) = sigmoid(s(x) - s(y) + c)``: a scalar
  head ``s`` on the SFT body and a position offset ``c``, fitted to labels from a labeller with two
  planted biases (longer reviews, and the review shown first, are preferred beyond their quality).
  :meth:`Judge.length_controlled` removes the length slope a practitioner can measure without any gold
  reward (the judge's score regressed on length over SFT samples).

:func:`preference_rounds` runs the students' round for a number of rounds from the SFT model with pairs
drawn from the SFT model (offline), from a snapshot of the policy refreshed every few rounds (iterative),
or from the policy itself (online), and evaluates the policy along the way (:func:`evaluate`).
:func:`gold_at_kl` reads a run's gold reward at a given KL from its evaluation points (matched KL).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np
import torch

from rlcourse import reviews as R
from rlcourse.checkpoint import load_model
from rlcourse.group_rl import completion_log_prob_sums
from rlcourse.lm import LMConfig, ScalarHeadLM, TinyLM, generate, load_lm

JUDGE_FILE = "hw7b/judge.pt"
PPO_FILES = tuple(f"hw7b/ppo_iter{i:02d}.pt" for i in (6, 12, 18, 24, 30))
PERSON_TEMPERATURE = 0.25
"""The simulated person's temperature (hw5's preference file was labelled with it)."""

Annotator = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def review_length(tokens: torch.Tensor) -> torch.Tensor:
    """Length of each review in tokens ``(N,)`` float: every non-padding token, ``<bos>`` and ``<eos>`` included."""
    return (torch.as_tensor(tokens) != R.PAD_ID).sum(1).float()


def gold(tokens: torch.Tensor) -> torch.Tensor:
    """The gold reward of each review, ``(N,)`` float64 (a program: :func:`rlcourse.reviews.gold_reward`)."""
    return torch.as_tensor(R.gold_reward(torch.as_tensor(tokens).numpy()), dtype=torch.float64)


class SimulatedPerson:
    """hw5's simulated annotator: ``a`` wins with probability ``sigmoid((gold(a) - gold(b)) / temperature)``.

    Calling it returns the drawn verdicts ``(N,)`` float64, 1.0 where ``a`` won and 0.0 where ``b`` did, from
    its own random generator (seeded once), and counts the labels it has given in ``labels``.
    """

    def __init__(self, seed: int, temperature: float = PERSON_TEMPERATURE):
        self.rng, self.temperature, self.labels = np.random.default_rng(seed), temperature, 0

    def __call__(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        d = (gold(a) - gold(b)).numpy() / self.temperature
        self.labels += len(d)
        return torch.as_tensor((self.rng.random(len(d)) < 1.0 / (1.0 + np.exp(-d))).astype(np.float64))


# --------------------------------------------------------------------------- the constitution
def _finished(tokens: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(1.0 - R.gold_terms(tokens.numpy()).unfinished)


def _grammatical(tokens: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(-R.gold_terms(tokens.numpy()).ungrammatical)


def _no_repeats(tokens: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(-R.gold_terms(tokens.numpy()).repeats)


def _positive(tokens: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(R.gold_terms(tokens.numpy()).sentiment)


CONSTITUTION: tuple[tuple[str, Callable[[torch.Tensor], torch.Tensor]], ...] = (
    ("Finish the review: end it with <eos>.", _finished),
    ("Write only word pairs the language allows.", _grammatical),
    ("Do not repeat a word that carries sentiment.", _no_repeats),
    ("Speak well of the item: the more praise, the better.", _positive),
)
"""The rule list: ``(rule as written, score of a batch of reviews (N, T) -> (N,) float64, higher = follows it
better)``. Each score is one term of the gold reward, but the list says nothing of how the terms trade off,
and praise is not saturated as in the gold reward's ``tanh``: a critic that votes rule by rule is close to
the gold reward on most pairs and differs from it where the rules disagree."""


# --------------------------------------------------------------------------- the learned judge
@dataclass
class Judge:
    """A learned pairwise judge: ``P(x beats y | x shown first) = sigmoid(s(x) - s(y) + position)``.

    ``model`` is a scalar-head copy of the SFT model (``s`` its raw score at the last token), ``position`` the
    fitted position offset (in logits), ``length_slope`` a slope subtracted per token of length (0 for the
    judge as fitted; see :meth:`length_controlled`), ``shift`` and ``scale`` standardise :meth:`score`.
    """

    model: ScalarHeadLM
    position: float
    shift: float
    scale: float
    length_slope: float = 0.0
    metadata: Optional[dict] = None

    @torch.no_grad()
    def raw(self, tokens: torch.Tensor) -> torch.Tensor:
        """``s(y) - length_slope * length(y)`` of each review, ``(N,)`` float64."""
        tokens = torch.as_tensor(tokens)
        s = torch.cat([self.model.score(x) for x in tokens.split(1024)]).double()
        return s - self.length_slope * review_length(tokens).double()

    def score(self, tokens: torch.Tensor) -> torch.Tensor:
        """The judge's standardised score of each review ``(N,)`` (mean 0 and sd 1 on SFT pairs, as fitted)."""
        return (self.raw(tokens) - self.shift) / self.scale

    def __call__(self, first: torch.Tensor, second: torch.Tensor) -> torch.Tensor:
        """``(N,)`` float64: the probability that ``first`` (shown first) beats ``second``."""
        return torch.sigmoid(self.raw(first) - self.raw(second) + self.position)

    def length_controlled(self, samples: torch.Tensor) -> "Judge":
        """The same judge with the least-squares slope of its score on review length over ``samples`` removed.

        The slope is read from the judge's own scores of reviews (SFT samples, say): no gold reward is
        needed. It removes whatever goes with length in those reviews, bias and merit alike.
        """
        s, n = self.raw(samples).numpy(), review_length(samples).double().numpy()
        slope = float(np.polyfit(n, s, 1)[0])
        return Judge(self.model, self.position, self.shift, self.scale, self.length_slope + slope, self.metadata)


def load_judge() -> Judge:
    """The shipped judge (``datasets/hw7b/judge.pt``), checksum-verified; ``.metadata`` says how it was made
    (the planted biases of its labeller, the fitted position offset, held-out agreement)."""
    from rlcourse import data

    rm = load_model(data.verify(JUDGE_FILE), lambda **config: ScalarHeadLM(TinyLM(LMConfig(**config))))
    m = rm.metadata
    return Judge(rm, float(m["position"]), float(m["shift"]), float(m["scale"]), 0.0, dict(m))


def load_ppo_curve() -> dict[int, TinyLM]:
    """PPO's policy at iterations 6, 12, ..., 30 (``datasets/hw7b/ppo_iter*.pt``, stored in half precision):
    hw5's PPO on hw6's reward model, made by ``datasets/scripts/make_hw7b_models.py`` (seed 0 of the bench)."""
    from rlcourse import data

    out = {}
    for name in PPO_FILES:
        model = load_lm(data.verify(name))
        out[int(model.metadata["iteration"])] = model
    return out


# --------------------------------------------------------------------------- evaluation and the loop
@torch.no_grad()
def evaluate(policy: TinyLM, ref: TinyLM, prompts: torch.Tensor, seed: int,
             judge: Optional[Judge] = None) -> dict:
    """One completion of each prompt at temperature 1: mean ``gold`` reward, ``kl`` from ``ref`` (the sampled
    estimate, mean of ``log pi - log pi_ref``; ``kl_se`` its standard error), mean review ``length`` and, with
    a judge, its mean standardised ``judge`` score. ``tokens`` holds the samples."""
    p = prompts.shape[1]
    tokens = generate(policy, prompts, R.MAX_LEN - p, generator=torch.Generator().manual_seed(seed))
    kl = completion_log_prob_sums(policy, tokens, p) - completion_log_prob_sums(ref, tokens, p)
    out = {"gold": float(gold(tokens).mean()), "kl": float(kl.mean()),
           "kl_se": float(kl.std() / np.sqrt(len(kl))) if len(kl) > 1 else float("nan"),
           "length": float(review_length(tokens).mean()), "tokens": tokens}
    if judge is not None:
        out["judge"] = float(judge.score(tokens).mean())
    return out


def preference_rounds(sft: TinyLM, round_fn: Callable, annotator: Annotator, prompts: torch.Tensor, *, rounds: int,
                      batch: int, beta: float, seed: int, sync_every: Optional[int] = 1, lr: float = 2e-4,
                      eval_prompts: Optional[torch.Tensor] = None, eval_every: int = 0,
                      judge: Optional[Judge] = None) -> tuple[TinyLM, dict]:
    """``rounds`` calls of the students' ``round_fn`` from a copy of ``sft`` (also the frozen reference).

    Each round draws ``batch`` prompts and calls ``round_fn(policy, sft, x, annotator, opt, beta, generator,
    sampler=...)`` (AdamW at ``lr``; one generator seeded ``seed`` for every draw). Where the pairs come from:

    - ``sync_every=None``: offline, every pair sampled from ``sft`` (the distribution an offline data set is
      drawn from; each round's pairs are fresh, so every method sees as many labels);
    - ``sync_every=k``: iterative, from a frozen snapshot of the policy, refreshed every ``k`` rounds;
    - ``sync_every=1``: online, from the policy itself (``sampler=None``).

    With ``eval_prompts`` and ``eval_every``, the policy is evaluated (:func:`evaluate`, seed ``seed``) before
    the first round and every ``eval_every`` rounds. Returns the policy (eval mode) and a log: per round
    ``loss`` and ``pairs`` (labelled pairs used) and the evaluation points ``evals`` (dicts with ``round``,
    ``gold``, ``kl``, ``kl_se``, ``length``, ``judge`` with a judge, and ``seconds`` so far).
    """
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    policy = copy.deepcopy(sft).train()
    opt = torch.optim.AdamW(policy.parameters(), lr=lr, weight_decay=0.0)
    log: dict = {"loss": [], "pairs": [], "evals": []}
    t0 = time.perf_counter()

    def checkpoint(r: int) -> None:
        if eval_prompts is not None and eval_every:
            e = evaluate(policy, sft, eval_prompts, seed, judge)
            e.pop("tokens")
            log["evals"].append({"round": r, **e, "seconds": time.perf_counter() - t0})

    checkpoint(0)
    snapshot = sft
    for r in range(rounds):
        if sync_every is not None and sync_every > 1 and r % sync_every == 0:
            snapshot = copy.deepcopy(policy).eval()
        sampler = sft if sync_every is None else (None if sync_every == 1 else snapshot)
        x = prompts[torch.randint(len(prompts), (batch,), generator=gen)]
        out = round_fn(policy, sft, x, annotator, opt, beta, gen, sampler=sampler)
        log["loss"].append(float(out["loss"]))
        log["pairs"].append(int(len(out["chosen"])))
        if eval_every and (r + 1) % eval_every == 0:
            checkpoint(r + 1)
    return policy.eval(), log


def gold_at_kl(evals: Sequence[dict], kl: float) -> float:
    """The gold reward where a run's evaluation points first reach ``kl``, linear between the two points that
    bracket it; NaN when the run never gets that far. ``evals`` are in training order (``gold``, ``kl``)."""
    pts = [(e["kl"], e["gold"]) for e in evals]
    for (k0, g0), (k1, g1) in zip(pts, pts[1:]):
        if k0 < kl <= k1:
            return float(g0 + (g1 - g0) * (kl - k0) / (k1 - k0))
    return float("nan")


def agreement_with_gold(annotator: Annotator, a: torch.Tensor, b: torch.Tensor) -> dict:
    """How often ``annotator``'s verdicts on pairs ``(a, b)`` side with the gold reward: ``agreement`` over the
    pairs whose gold rewards differ and where the annotator chose (verdict not 0.5), and ``decided``, the
    fraction of those pairs on which it chose."""
    p = torch.as_tensor(annotator(a, b), dtype=torch.float64)
    ga, gb = gold(a), gold(b)
    differ = ga != gb
    decided = differ & (p != 0.5)
    right = ((p > 0.5) == (ga > gb)) & decided
    return {"agreement": float(right.sum() / decided.sum().clamp(min=1)),
            "decided": float(decided.sum() / differ.sum().clamp(min=1))}
