"""hw7b's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). They build the tiny language models, the
optimiser and the generator a round needs (objects that cannot cross the channel), call the submission, and
return raw data (its answer, the weights as the round left them) that the tests judge on the grader's side.
"""
import torch

from rlcourse.lm import LMConfig, TinyLM

TINY = dict(vocab_size=13, context=8, n_layer=1, n_head=2, d_model=16)


def tiny_lm(seed: int) -> TinyLM:
    """A freshly initialised tiny TinyLM, its weights drawn under ``seed`` (the grader builds the same one)."""
    torch.manual_seed(seed)
    return TinyLM(LMConfig(**TINY))


class PlainSGD:
    """Plain gradient descent with the part of ``torch.optim.SGD``'s interface a round uses (``param_groups``,
    ``zero_grad(set_to_none=True)``, ``step()``) and the same update, ``p -= lr * p.grad``. Not torch's own class:
    the first torch optimizer a process builds imports ``torch._dynamo``, about 2 s of CPU (5 s of wall time at a
    load of 5), which a grading would otherwise pay once here and once on the grader's side."""

    def __init__(self, params, lr: float) -> None:
        self.param_groups = [{"params": list(params), "lr": lr}]

    def zero_grad(self, set_to_none: bool = True) -> None:
        for p in self.param_groups[0]["params"]:
            if set_to_none:
                p.grad = None
            elif p.grad is not None:
                p.grad.zero_()

    @torch.no_grad()
    def step(self, closure=None):
        loss = None if closure is None else closure()
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is not None:
                    p.add_(p.grad, alpha=-group["lr"])
        return loss


def run_round(models, prompts, beta: float, gen_seed: int, policy_seed: int, ref_seed: int, sampler_seed=None,
              lr: float = 0.5, stale: float = 0.3):
    """The submission's ``online_dpo_round`` on fresh tiny models, plain SGD at ``lr`` over the policy (its gradients
    first set to ``stale``, as left by an earlier computation) and the lent ``models.label`` as annotator. Returns
    (its answer, the policy's, the reference's and the sampler's weights after the round)."""
    policy, ref = tiny_lm(policy_seed), tiny_lm(ref_seed)
    sampler = None if sampler_seed is None else tiny_lm(sampler_seed)
    opt = PlainSGD(policy.parameters(), lr=lr)
    for p in policy.parameters():
        p.grad = torch.full_like(p, stale)
    out = notebook["online_dpo_round"](policy, ref, prompts, models.label, opt, beta,  # noqa: F821 - set by the worker
                                       torch.Generator().manual_seed(gen_seed), sampler=sampler)
    return (out, module_state(policy), module_state(ref),  # noqa: F821 - sandbox_common
            None if sampler is None else module_state(sampler))  # noqa: F821


def run_rule_critic(rulebook, names, a, b, weights=None):
    """The submission's ``rule_critic`` with the lent rulebook's methods ``names`` as its rules."""
    rules = [getattr(rulebook, name) for name in names]
    if weights is None:
        return notebook["rule_critic"](rules, a, b)  # noqa: F821
    return notebook["rule_critic"](rules, a, b, weights=weights)  # noqa: F821


def run_position_swap(judge, a, b):
    """The submission's ``position_swap`` with the lent ``judge.ask`` as its judge."""
    return notebook["position_swap"](judge.ask, a, b)  # noqa: F821
