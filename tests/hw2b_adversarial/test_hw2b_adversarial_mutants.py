"""hw2b's hidden suite against hand-written mutants of its reference solution: each is a common mistake in one stub.

Every mutant is the complete solution with one text replacement in one stub. Graded by the real grader (sandbox
and all), each must lose points on its own stub and keep full marks elsewhere. The table printed with ``-s`` is
the mutation report quoted in the report to README: killed (lost points) out of mutants, per stub.

    .venv/bin/pytest -q -s tests/hw2b_adversarial/test_hw2b_adversarial_mutants.py
"""
from __future__ import annotations

import pytest

from conftest import check_hand_mutants

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

ID = "hw2b_adversarial"
LOSS = "return F.softplus(-expert_logits).mean() + F.softplus(policy_logits).mean()"

# stub -> {mutant name: (text in the solution, replacement)}
MUTANTS = {
    "soft_policy": {
        "reward of the next step": ("q = reward[t] +", "q = reward[min(t + 1, horizon - 1)] +"),
        "reward of step 0 throughout": ("q = reward[t] +", "q = reward[0] +"),
        "hard maximum": ("v = q_max + np.log(np.exp(q - q_max).sum(axis=1, keepdims=True))", "v = q_max"),
        "no maximum subtracted": ("v = q_max + np.log(np.exp(q - q_max).sum(axis=1, keepdims=True))",
                                  "v = np.log(np.exp(q).sum(axis=1, keepdims=True))"),
        "mean over actions": ("np.exp(q - q_max).sum(axis=1, keepdims=True)", "np.exp(q - q_max).mean(axis=1, keepdims=True)"),
        "forward in time": ("for t in reversed(range(horizon)):", "for t in range(horizon):"),
        "V_T from the last reward": ("v_next = np.zeros(n_states)", "v_next = reward[-1].max(axis=1)"),
        "dynamics read backwards": ("csr_array(P.reshape(n_states * n_actions, n_states))",
                                    "csr_array(P.transpose(2, 1, 0).reshape(n_states * n_actions, n_states))"),
    },
    "state_distributions": {
        "policy of the next step": ("(d[t][:, None] * policy[t]).ravel()",
                                    "(d[t][:, None] * policy[min(t + 1, horizon - 1)]).ravel()"),
        "uniform start": ("d[0] = p0", "d[0] = 1.0 / n_states"),
        "one step short": ("for t in range(horizon - 1):", "for t in range(horizon - 2):"),
        "policy ignored": ("(d[t][:, None] * policy[t]).ravel()", "(d[t][:, None] * np.full_like(policy[t], 1.0 / n_actions)).ravel()"),
        "policy of step 0 throughout": ("(d[t][:, None] * policy[t]).ravel()", "(d[t][:, None] * policy[0]).ravel()"),
        "renormalised by hand": ("d[t + 1] = P_T @ (d[t][:, None] * policy[t]).ravel()",
                                 "d[t + 1] = P_T @ (d[t][:, None] * policy[t]).ravel()\n        d[t + 1] /= d[t + 1].max()"),
    },
    "discriminator_loss": {
        "log of a sigmoid": (LOSS, "return -torch.log(torch.sigmoid(expert_logits)).mean() "
                                   "- torch.log(1 - torch.sigmoid(policy_logits)).mean()"),
        "one mean over both sides": (LOSS, "return torch.cat([F.softplus(-expert_logits), F.softplus(policy_logits)]).mean()"),
        "average of the two sides": (LOSS, "return 0.5 * (F.softplus(-expert_logits).mean() + F.softplus(policy_logits).mean())"),
        "labels swapped": (LOSS, "return F.softplus(expert_logits).mean() + F.softplus(-policy_logits).mean()"),
        "expert side only": (LOSS, "return F.softplus(-expert_logits).mean()"),
        "policy side detached": (LOSS, "return F.softplus(-expert_logits).mean() + F.softplus(policy_logits.detach()).mean()"),
        "sums": (LOSS, "return F.softplus(-expert_logits).sum() + F.softplus(policy_logits).sum()"),
    },
    "airl_logits": {
        "done ignored": ("gamma * (1.0 - done) * h_next", "gamma * h_next"),
        "done drops h(s) instead": ("gamma * (1.0 - done) * h_next - h", "gamma * h_next - (1.0 - done) * h"),
        "log pi added": ("return f - log_pi", "return f + log_pi"),
        "log pi forgotten": ("return f - log_pi", "return f"),
        "gamma on h(s)": ("gamma * (1.0 - done) * h_next - h", "(1.0 - done) * h_next - gamma * h"),
        "shaping reversed": ("gamma * (1.0 - done) * h_next - h", "h - gamma * (1.0 - done) * h_next"),
        "log of pi taken again": ("return f - log_pi", "return f - torch.log(log_pi.exp() + 1e-3)"),
        "done inverted": ("(1.0 - done)", "done"),
    },
    "policy_reward": {
        "gail as log D": ('    if kind == "gail":\n        return F.softplus(logits)',
                          '    if kind == "gail":\n        return -F.softplus(-logits)'),
        "gail through log(1 - sigmoid)": ("return F.softplus(logits)", "return -torch.log(1 - torch.sigmoid(logits))"),
        "logd through log(sigmoid)": ("return -F.softplus(-logits)", "return torch.log(torch.sigmoid(logits))"),
        "logd as minus the gail reward": ("return -F.softplus(-logits)", "return -F.softplus(logits)"),
        "airl as the gail reward": ('    if kind == "airl":\n        return logits', '    if kind == "airl":\n        return F.softplus(logits)'),
        "unknown kinds fall through": ('    raise ValueError', '    return logits\n    raise ValueError'),
        "gail detached": ("return F.softplus(logits)", "return F.softplus(logits.detach())"),
        "kinds matched loosely": ('if kind == "gail":', 'if kind.lower() == "gail":'),
    },
}


def test_every_mutant_loses_points_on_its_own_stub_and_only_there(open_tmp):
    check_hand_mutants(ID, MUTANTS, open_tmp)
