"""Hidden tests of hw7b's `online_dpo_round`: the round is recomputed on the grader's side with the grader's own copies
of the tiny models, generator and annotator; the lent annotator keeps its own record of what it was asked."""
import math

import numpy as np
import torch
import torch.nn.functional as F

from autograder.suite import lend, stub
from conftest import as_float_tensor, same_rows, trusted_lm
from rlcourse.group_rl import completion_log_prob_sums
from rlcourse.lm import generate

HINT = ("tokens = generate(sampler or policy, prompts.repeat_interleave(2, dim=0), context - P, generator=generator); "
        "a = tokens[0::2], b = tokens[1::2]; annotator(a, b) once; chosen = a where > 0.5, b where < 0.5, ties dropped; "
        "loss = mean of -logsigmoid(beta * ((pi_c - ref_c) - (pi_r - ref_r))) with completion_log_prob_sums; "
        "zero_grad, backward, step.")


class _Annotator:
    """Scores a review by a hidden token table; prefers the higher score with a graded probability, and answers
    exactly 0.5 on the pairs whose scores are closest (about a third). Records every call."""

    def __init__(self, seed: int, no_preference: bool = False, one: bool = False) -> None:
        self.table = torch.as_tensor(np.random.default_rng(seed).normal(size=13))
        self.no_preference, self.one, self.calls = no_preference, one, []

    def answer(self, a, b):
        d = self.table[a.long()].sum(1) - self.table[b.long()].sum(1)
        p = torch.sigmoid(2.0 * d)
        if self.no_preference:
            return torch.full_like(p, 0.5)
        if self.one:                                   # a preference on the clearest pair only
            return torch.where(torch.arange(len(d)) == d.abs().argmax(), p, torch.full_like(p, 0.5))
        close = d.abs() <= torch.quantile(d.abs(), 0.34)
        return torch.where(close, torch.full_like(p, 0.5), p)

    def label(self, a, b):
        a, b = torch.as_tensor(a), torch.as_tensor(b)
        self.calls.append((a.clone(), b.clone()))
        return self.answer(a, b)


def _prompts(rng, n=6):
    return torch.as_tensor(np.c_[np.ones(n, dtype=np.int64), rng.integers(3, 13, size=(n, 1))])


def _trusted(prompts, beta, gen_seed, policy_seed, ref_seed, sampler_seed, lr, annotator):
    """What the round must do, done here: (a, b, chosen, rejected, loss, policy weights after)."""
    policy, ref = trusted_lm(policy_seed), trusted_lm(ref_seed)
    source = policy if sampler_seed is None else trusted_lm(sampler_seed)
    p = prompts.shape[1]
    tokens = generate(source, prompts.repeat_interleave(2, dim=0), source.cfg.context - p,
                      generator=torch.Generator().manual_seed(gen_seed))
    a, b = tokens[0::2], tokens[1::2]
    verdict = annotator.answer(a, b)
    keep, a_wins = verdict != 0.5, (verdict > 0.5)[:, None]
    chosen, rejected = torch.where(a_wins, a, b)[keep], torch.where(a_wins, b, a)[keep]
    before = {k: v.clone() for k, v in policy.state_dict().items()}
    if len(chosen) == 0:
        return a, b, chosen, rejected, float("nan"), before, before
    with torch.no_grad():
        rc, rr = completion_log_prob_sums(ref, chosen, p), completion_log_prob_sums(ref, rejected, p)
    loss = -F.logsigmoid(beta * ((completion_log_prob_sums(policy, chosen, p) - rc)
                                 - (completion_log_prob_sums(policy, rejected, p) - rr))).mean()
    policy.zero_grad(set_to_none=True)
    loss.backward()
    with torch.no_grad():                      # SGD's step, written out (no torch optimizer: see sandbox_helpers)
        for param in policy.parameters():
            param.add_(param.grad, alpha=-lr)
    return a, b, chosen, rejected, float(loss), before, policy.state_dict()


def _round(student, rng, sampler=False, no_preference=False, one=False):
    prompts = _prompts(rng)
    beta = float(rng.uniform(0.3, 2.0))
    gen_seed, policy_seed, ref_seed = (int(x) for x in rng.integers(0, 10_000, size=3))
    sampler_seed = int(rng.integers(0, 10_000)) if sampler else None
    models = _Annotator(int(rng.integers(0, 10_000)), no_preference, one)
    out, after, ref_after, sampler_after = student.helpers.run_round(
        lend(models, methods=["label"]), prompts, beta, gen_seed, policy_seed, ref_seed, sampler_seed=sampler_seed, lr=0.5)
    want = _trusted(prompts, beta, gen_seed, policy_seed, ref_seed, sampler_seed, 0.5, models)
    assert isinstance(out, dict) and {"loss", "chosen", "rejected"} <= set(out), \
        "online_dpo_round should return a dict with 'loss', 'chosen' and 'rejected'"
    return out, after, ref_after, sampler_after, models, want, (policy_seed, ref_seed, sampler_seed)


def _check_asked(models, want):
    a, b = want[0], want[1]
    assert len(models.calls) == 1, f"the annotator should be called once per round, it was called {len(models.calls)} times"
    got_a, got_b = models.calls[0]
    same_rows(got_a, a, "the first responses the annotator was asked about (a)")
    same_rows(got_b, b, "the second responses the annotator was asked about (b)")


def _moved_as_one_step(after, want, what="the policy"):
    before, expected = want[5], want[6]
    assert isinstance(after, dict) and set(after) == set(expected), f"{what}'s parameters are not those of the model given"
    for key in expected:
        got = after[key].double() - before[key].double()
        exp = expected[key].double() - before[key].double()
        if not torch.allclose(got, exp, rtol=1e-3, atol=1e-6):
            if exp.abs().max() == 0 and got.abs().max() > 0:
                raise AssertionError(f"{what}'s `{key}` moved, and one step on these pairs does not move it "
                                     "(stale gradients not zeroed?)")
            cos = float((got * exp).sum() / (got.norm() * exp.norm() + 1e-30))
            raise AssertionError(f"{what}'s `{key}` did not move as one DPO step on the labelled pairs moves it "
                                 f"(cosine between the two changes {cos:.2f})")


@stub("online_dpo_round", points=2, hint=HINT)
def test_asks_about_the_policys_own_pairs(student, rng):
    """Six prompts: the annotator is asked once, about the two samples of each prompt drawn from the policy"""
    out, *_, models, want, _ = _round(student, rng)
    _check_asked(models, want)


@stub("online_dpo_round", points=2, hint=HINT)
def test_orients_the_pairs_and_drops_ties(student, rng):
    """chosen and rejected follow the annotator's answers (> 0.5: a; < 0.5: b), pairs answered 0.5 left out"""
    out, *_, models, want, _ = _round(student, rng)
    _check_asked(models, want)
    same_rows(out["chosen"], want[2], "chosen")
    same_rows(out["rejected"], want[3], "rejected")


@stub("online_dpo_round", points=3, hint=HINT)
def test_one_dpo_step(student, rng):
    """Policy and reference differ: the loss and the policy's change are one DPO step (SGD); ref is untouched"""
    out, after, ref_after, _, models, want, seeds = _round(student, rng)
    _check_asked(models, want)
    loss = out["loss"]
    assert isinstance(loss, float) and math.isfinite(loss), f"'loss' should be a finite Python float, got {loss!r}"
    assert math.isclose(loss, want[4], rel_tol=1e-4, abs_tol=1e-6), \
        f"the loss is {loss:.4g}: not the mean over the kept pairs of -log sigmoid(beta * margin)"
    _moved_as_one_step(after, want)
    ref = trusted_lm(seeds[1]).state_dict()
    assert all(torch.equal(ref_after[k], ref[k]) for k in ref), "the reference model must not change"


@stub("online_dpo_round", points=2, hint="With a sampler, the pairs are drawn from it (sampler.cfg.context - P new "
                                         "tokens), and the policy, not the sampler, takes the step.")
def test_pairs_from_the_sampler(student, rng):
    """A sampler is given: the pairs come from it, the policy takes the step, the sampler is untouched"""
    out, after, _, sampler_after, models, want, seeds = _round(student, rng, sampler=True)
    _check_asked(models, want)
    same_rows(out["chosen"], want[2], "chosen")
    _moved_as_one_step(after, want)
    sampler = trusted_lm(seeds[2]).state_dict()
    assert sampler_after is not None and all(torch.equal(sampler_after[k], sampler[k]) for k in sampler), \
        "the sampler must not change"


@stub("online_dpo_round", points=1, hint="When every answer is 0.5 no pair is kept: no step at all, loss nan, and empty "
                                         "(0, T) chosen and rejected.")
def test_no_preference_no_step(student, rng):
    """Every answer is 0.5: no step (the policy keeps its weights), loss NaN, empty chosen and rejected"""
    out, after, _, _, models, want, seeds = _round(student, rng, no_preference=True)
    _check_asked(models, want)
    assert isinstance(out["loss"], float) and math.isnan(out["loss"]), "with no labelled pair the loss should be nan"
    for key in ("chosen", "rejected"):
        assert type(out[key]) is torch.Tensor and out[key].shape[0] == 0, f"{key} should be empty (0 rows)"
    before = trusted_lm(seeds[0]).state_dict()
    assert all(torch.equal(after[k], before[k]) for k in before), "with no labelled pair the policy must not take a step"


@stub("online_dpo_round", points=1, hint="A round with a single labelled pair still takes its step: only a round with no "
                                         "pair at all is skipped.")
def test_a_single_labelled_pair(student, rng):
    """Only one pair gets a preference: it is kept, and the policy takes one DPO step on it"""
    out, after, _, _, models, want, _ = _round(student, rng, one=True)
    _check_asked(models, want)
    same_rows(out["chosen"], want[2], "chosen")
    assert math.isclose(out["loss"], want[4], rel_tol=1e-4, abs_tol=1e-6), "the loss of the one labelled pair is wrong"
    _moved_as_one_step(after, want)
