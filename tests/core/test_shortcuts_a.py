"""Shortcuts through hw0-hw3's hidden suites, and implementations their docstrings allow (a red-team audit).

Each case grades the release notebook with a few stubs written as a lazy or cheating student would (every other stub
left as released, so it raises) and checks the score of each: "zero" for a shortcut that skips the stub's work,
"full" for a correct variant the docstring allows. Before the fixes these cases scored:

- hw2 ``maxent_irl``, one gradient at w = 0 scaled up (no ascent): 2/8, the return test (any weights near the true
  direction earn the expert's return); now that test also asks for the fit's feature expectations.
- hw2 ``deep_maxent_irl``, the expert's visit counts (or their log) as the reward, no network: 2/5, the learning test;
  now it also asks for the reward the documented training reaches (correlation with the reference's).
- hw3 ``fit_bradley_terry`` answered by the MM fit or by scipy's BFGS on the loss (no gradient descent): 3/3; now both
  tests also ask for two steps of gradient descent of a given size from zero.
- hw3 ``select_queries`` with ``np.argsort(var)[::-1]`` (ties the other way round, which the docstring leaves open):
  lost 2 to 4 points on about two draws in three (random candidate pools repeat pairs); now judged by the variances
  of the pairs chosen.
- hw2 ``maxent_irl`` with the sample variance (ddof = 1) in its step scale: 7/8, the documented-steps test; the
  docstring's "variance over the demonstrations" allows either, and both are accepted now.
- hw2 ``deep_maxent_irl`` with its layers built in float64 (``nn.Linear(..., dtype=torch.float64)``, which draws other
  initial weights under the same seed than float32 layers): 3/5, refused by the two tests that compare with the
  reference's initial network; the docstring leaves the dtype open, and either network is accepted now.
- hw1 ``train_bc`` correct beside a wrong ``bc_loss`` (a sum for the mean): 6/8, and 0/8 beside a missing one (the
  reference cannot stand in for a function of a network, so the student's own bc_loss ran); the library's density
  stands in for it now, in train_bc's and dagger's tests.
- hw3 ``train_reward_model`` and ``select_queries`` correct beside a missing ``segment_return`` and
  ``preference_loss``: 0/6 and 0/4 (the same reason); the docstrings' one-liners stand in for those two now.
- hw2 ``fit_route_weights`` correct beside a missing ``route_log_partition``: 0/3 (called with weights that need
  gradients); the reference's log-partition, lent by the grader as values and vector-Jacobian products, stands in now.
- hw1 ``dagger`` correct beside a missing ``relabel_with_expert``: 0/11 (it is called with an expert object); the
  grader's labels, lent, stand in for it now (and the notebook's own runs when it is asked to label with anything
  but the race expert, so labelling with the learner still loses points).
- hw2b: a hard backup (max for log-sum-exp) in ``soft_policy``, the policy ignored in ``state_distributions`` (P
  averaged over actions), and max(0, -l) for softplus(-l) in ``discriminator_loss``: 1/5, 1/4 and 1/6, each from the
  one test where the shortcut and the formula agree (rewards spread over hundreds, a one-action cycle, logits of
  +-1000); each of those tests now also checks a case where they differ.
- hw3 ``bt_gradient`` as central finite differences of ``bt_loss`` (no derivative worked out): 2/3, from the test
  that compared with finite differences at 1e-4; both tests now compare with the closed form at 1e-11.
- hw2 ``state_visitation_frequency`` by Monte Carlo with the released ``sample_trajectories`` (no forward pass):
  1/5, from the Monte-Carlo test, which now also asks for T = 2 exactly; and a correct forward pass beside a missing
  ``soft_value_iteration``: 4/5 (the gradient test ran the student's backward pass; it runs the reference's now).
- hw3 ``fit_bradley_terry_mm`` answered by scipy's BFGS on the loss (no MM iteration): 4/4; its docstring now says
  the iteration starts from equal strengths and updates every item at once, and its three tests ask for two MM
  iterations from there.
- hw0 ``discounted_returns`` returning float32 ("a float array"): 4/5, refused at rtol 1e-8; now float32 is compared
  at float32's precision.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest

from autograder.authoring.samples import solution_sources
from autograder.core import course
from conftest import graded_stubs

pytestmark = pytest.mark.slow  # a few gradings: make test-fast leaves it out

MADE_UP = '{"grad_norm": np.array([1.0, 0.0]), "log_likelihood": np.array([-1.0, 0.0])}'

HW2_SHORTCUTS = {
    "maxent_irl": f'''
def maxent_irl(P, features, p0, trajectories, horizon, actions=None, lr=1.0, n_iters=500, tol=1e-4):
    """No ascent: the gradient at w = 0, scaled up (any weights near the true direction earn the expert's return)."""
    features = np.asarray(features, dtype=float)
    mu = features[np.asarray(trajectories)].sum(axis=1).mean(axis=0)
    g = mu - features.T @ state_visitation_frequency(P, soft_value_iteration(P, np.zeros(len(features)), horizon),
                                                     p0, horizon)
    return 30.0 * g / np.linalg.norm(g), {MADE_UP}
''',
    "state_visitation_frequency": '''
def state_visitation_frequency(P, policy, p0, horizon):
    """No forward pass: Monte Carlo with the released sampler."""
    states = sample_trajectories(P, policy[:horizon], np.asarray(p0), 200000, np.random.default_rng(0)).states
    return np.bincount(states.ravel(), minlength=P.shape[0]) / len(states)
''',
    "deep_maxent_irl": '''
def deep_maxent_irl(P, features, p0, trajectories, horizon, actions=None, hidden=32, lr=0.01, n_iters=200,
                    weight_decay=1e-4, seed=0):
    """No network: the log of the expert's visit counts as the reward, and a made-up history."""
    states = np.asarray(trajectories)
    visits = np.bincount(states.ravel(), minlength=np.asarray(P).shape[0]) / states.shape[0]
    return np.log(visits + 1e-2), {"grad_norm": np.linspace(1, 0, n_iters), "log_likelihood": np.linspace(-9, -1, n_iters)}
''',
}

HW2_VISITS_EINSUM = '''
def state_visitation_frequency(P, policy, p0, horizon):
    d = np.array(p0, dtype=float); total = np.zeros_like(d)
    for t in range(horizon):
        total = total + d
        d = np.einsum("s,sa,sab->b", d, policy[t], P)
    return total
'''
HW3_GD_BY_MM = '''
def fit_bradley_terry(n_items, i, j, mu, lr=None, n_steps=5000, tol=1e-9):
    """No gradient descent: the MM fit, which reaches the same maximum."""
    return fit_bradley_terry_mm(n_items, i, j, mu)
'''
HW3_GD_BY_SCIPY = '''
def fit_bradley_terry(n_items, i, j, mu, lr=None, n_steps=5000, tol=1e-9):
    """No gradient descent: scipy's BFGS on the loss."""
    from scipy.optimize import minimize
    res = minimize(lambda u: bt_loss(u, i, j, mu), np.zeros(n_items), jac=lambda u: bt_gradient(u, i, j, mu),
                   method="BFGS", options={"gtol": 1e-12, "maxiter": 10000})
    return res.x - res.x.mean()
'''
HW3_GRADIENT_BY_DIFFERENCES = '''
def bt_gradient(utilities, i, j, mu):
    """No derivation: central finite differences of bt_loss."""
    u, eps = np.asarray(utilities, dtype=float), 1e-6
    return np.array([(bt_loss(u + eps * e, i, j, mu) - bt_loss(u - eps * e, i, j, mu)) / (2 * eps) for e in np.eye(len(u))])
'''
HW3_GRADIENT_BY_AUTOGRAD = '''
def bt_gradient(utilities, i, j, mu):
    """Allowed: autograd through the loss written in torch (exact to rounding)."""
    u = torch.tensor(np.asarray(utilities, dtype=float), requires_grad=True)
    d = u[torch.as_tensor(i)] - u[torch.as_tensor(j)]
    m = torch.as_tensor(np.asarray(mu, dtype=float))
    (-(m * torch.nn.functional.logsigmoid(d) + (1 - m) * torch.nn.functional.logsigmoid(-d)).mean()).backward()
    return u.grad.numpy()
'''
HW3_SELECT_REVERSED = '''
def select_queries(ensemble, obs, act, candidates, k):
    """Allowed: equal variances in the other order (np.argsort ascending, reversed)."""
    candidates = np.asarray(candidates)
    with torch.no_grad():
        R = ensemble(torch.as_tensor(obs), torch.as_tensor(act)).sum(-1)
        p = torch.sigmoid(R[:, candidates[:, 0]] - R[:, candidates[:, 1]])
        var = p.var(dim=0).numpy()
    return np.argsort(var)[::-1][:k].astype(np.int64)
'''
HW3_SELECT_TOPK = '''
def select_queries(ensemble, obs, act, candidates, k):
    """Allowed: float64, the population variance, and torch.topk (whose order of equal values is its own)."""
    candidates = np.asarray(candidates)
    with torch.no_grad():
        R = ensemble(torch.as_tensor(obs), torch.as_tensor(act)).sum(-1).double()
        var = torch.sigmoid(R[:, candidates[:, 0]] - R[:, candidates[:, 1]]).var(dim=0, unbiased=False)
    return torch.topk(var, k).indices.numpy().astype(np.int64)
'''
HW3_RATINGS_LOOP = '''
def ratings_to_comparisons(annotator, segment, rating, window=5):
    """Allowed: a loop over ratings in session order (the pairs in another order than the reference's)."""
    pairs, mu = [], []
    for m in range(len(annotator)):
        later = [q for q in range(m + 1, len(annotator)) if annotator[q] == annotator[m]][:window]
        for q in later:
            if segment[q] != segment[m]:
                pairs.append((segment[m], segment[q]))
                mu.append(1.0 if rating[m] > rating[q] else 0.5 if rating[m] == rating[q] else 0.0)
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(mu, dtype=float)
'''
HW2_DEEP_ALLOWED = '''
def deep_maxent_irl(P, features, p0, trajectories, horizon, actions=None, hidden=32, lr=0.01, n_iters=200,
                    weight_decay=1e-4, seed=0):
    """Allowed: layers built in float64 (other initial weights than float32 layers), loops, reward.backward(-grad)."""
    states = np.asarray(trajectories)
    n_states = np.asarray(P).shape[0]
    d_expert = np.zeros(n_states)
    for row in states:
        for s in row:
            d_expert[s] += 1
    d_expert /= len(states)
    torch.manual_seed(seed)
    layer = lambda n_in, n_out: torch.nn.Linear(n_in, n_out, dtype=torch.float64)
    net = torch.nn.Sequential(layer(features.shape[1], hidden), torch.nn.ReLU(), layer(hidden, hidden), torch.nn.ReLU(),
                              layer(hidden, 1))
    x = torch.tensor(features, dtype=torch.float64)
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    grad_norm, log_likelihood = [], []
    for _ in range(n_iters):
        r = net(x)[:, 0]
        pi = soft_value_iteration(P, r.detach().numpy(), horizon)
        g = d_expert - state_visitation_frequency(P, pi, p0, horizon)
        grad_norm.append(float(np.sqrt((g ** 2).sum())))
        if actions is not None:
            log_likelihood.append(float(np.mean([sum(np.log(pi[t, s, a]) for t, (s, a) in enumerate(zip(srow, arow)))
                                                 for srow, arow in zip(states, actions)])))
        opt.zero_grad()
        r.backward(-torch.tensor(g))
        opt.step()
    with torch.no_grad():
        return net(x)[:, 0].numpy(), {"grad_norm": np.array(grad_norm), "log_likelihood": np.array(log_likelihood)}
'''
HW0_FLOAT32 = '''
def discounted_returns(rewards, gamma):
    """Allowed: float32 throughout ("a float array")."""
    r = np.asarray(rewards, dtype=np.float32)
    out, running = np.zeros_like(r), np.zeros(r.shape[0], dtype=np.float32)
    for t in reversed(range(r.shape[1])):
        running = r[:, t] + np.float32(gamma) * running
        out[:, t] = running
    return out
'''

HW2B_HALF_WORK = {
    'soft_policy': '''
def soft_policy(P, reward, horizon):
    """Hard value iteration, Boltzmann policy."""
    S, A = P.shape[:2]; pi = np.zeros((horizon, S, A)); v = np.zeros(S)
    for t in range(horizon - 1, -1, -1):
        q = reward[t] + P @ v
        z = q - q.max(1, keepdims=True); e = np.exp(z); pi[t] = e / e.sum(1, keepdims=True)
        v = q.max(1)
    return pi
''',
    'state_distributions': '''
def state_distributions(P, policy, p0):
    T = policy.shape[0]; d = [np.asarray(p0, float)]; M = P.mean(axis=1)
    for t in range(T - 1):
        d.append(d[-1] @ M)
    return np.array(d)
''',
    'discriminator_loss': '''
def discriminator_loss(expert_logits, policy_logits):
    return torch.relu(-expert_logits).mean() + torch.relu(policy_logits).mean()
''',
}
HW2B_ALLOWED = {
    'soft_policy': '''
def soft_policy(P, reward, horizon):
    from scipy.special import logsumexp
    S, A = P.shape[:2]
    pi = np.zeros((horizon, S, A)); v = np.zeros(S)
    for t in range(horizon - 1, -1, -1):
        q = reward[t] + np.einsum("sab,b->sa", P, v)
        v = logsumexp(q, axis=1)
        pi[t] = np.exp(q - v[:, None])
    return pi
''',
    'state_distributions': '''
def state_distributions(P, policy, p0):
    T = policy.shape[0]
    d = [np.asarray(p0, dtype=float)]
    for t in range(T - 1):
        d.append(np.einsum("s,sa,sab->b", d[-1], policy[t], P))
    return np.array(d)
''',
    'discriminator_loss': '''
def discriminator_loss(expert_logits, policy_logits):
    bce = torch.nn.functional.binary_cross_entropy_with_logits
    return bce(expert_logits, torch.ones_like(expert_logits)) + bce(policy_logits, torch.zeros_like(policy_logits))
''',
    'airl_logits': '''
def airl_logits(g, h, h_next, log_pi, gamma, done):
    return g - h - log_pi + gamma * h_next * (1 - done)
''',
    'policy_reward': '''
def policy_reward(logits, kind):
    table = {"gail": lambda l: -F.logsigmoid(-l), "logd": F.logsigmoid, "airl": lambda l: l.clone()}
    if kind not in table:
        raise ValueError(kind)
    return table[kind](logits)
''',
}

HW3_MM_BY_SCIPY = '''
def fit_bradley_terry_mm(n_items, i, j, mu, n_iters=5000, tol=1e-10):
    """No MM: scipy's BFGS on the mean loss, to a stationary point."""
    from scipy.optimize import minimize
    from scipy.special import expit, log_expit
    i, j, mu = np.asarray(i), np.asarray(j), np.asarray(mu, dtype=float)
    def f(u):
        d = u[i] - u[j]
        return -np.mean(mu * log_expit(d) + (1 - mu) * log_expit(-d))
    def g(u):
        gg = (expit(u[i] - u[j]) - mu) / len(i)
        return np.bincount(i, gg, minlength=n_items) - np.bincount(j, gg, minlength=n_items)
    res = minimize(f, np.zeros(n_items), jac=g, method="BFGS", options={"gtol": 1e-13, "maxiter": 10000})
    return res.x - res.x.mean()
'''

SOLVED = {a: solution_sources(a) for a in ("hw1_imitation", "hw2_maxent_irl", "hw3_preferences")}
MEAN = "return neg_log_density.sum(dim=-1).mean()"
assert MEAN in SOLVED["hw1_imitation"]["bc_loss"], "the reference bc_loss's last line has moved"
HW1_BC_LOSS_SUMMED = SOLVED["hw1_imitation"]["bc_loss"].replace(MEAN, "return neg_log_density.sum()")
FIT_HEAD = "def fit_route_weights("
assert SOLVED["hw2_maxent_irl"]["fit_route_weights"].startswith(FIT_HEAD), "the reference fit_route_weights has moved"
# A shortcut: fit_route_weights keeps the reference log-partition it is lent, and route_log_partition (tested after
# it) answers with it; the lent stand-in refuses calls once its fit has returned.
HW2_KEEP_THE_STAND_IN = {
    "fit_route_weights": "_KEPT = []\n\n" + SOLVED["hw2_maxent_irl"]["fit_route_weights"].replace(
        '    """Maximum-likelihood', '    _KEPT.append(route_log_partition)\n    """Maximum-likelihood', 1),
    "route_log_partition": ("def route_log_partition(weights, net, origins, destinations, horizon):\n"
                            "    return _KEPT[-1](weights, net, origins, destinations, horizon)\n"),
}
assert "_KEPT.append" in HW2_KEEP_THE_STAND_IN["fit_route_weights"]
POPULATION = "features[states].sum(axis=1).var(axis=0)"
assert POPULATION in SOLVED["hw2_maxent_irl"]["maxent_irl"], "the reference maxent_irl's step scale has moved"
# Allowed: "the variance over the demonstrations" read as the sample variance (ddof = 1)
HW2_SAMPLE_VARIANCE = SOLVED["hw2_maxent_irl"]["maxent_irl"].replace(POPULATION, POPULATION[:-1] + ", ddof=1)")

# (assignment, the stubs written, the score each must get: "zero" or "full")
CASES = [
    ("hw0_setup", {"discounted_returns": HW0_FLOAT32}, {"discounted_returns": "full"}),
    # a correct train_bc and dagger beside a wrong bc_loss (a sum for the mean) and a missing relabel_with_expert:
    # the mistakes cost bc_loss and relabel_with_expert alone
    ("hw1_imitation", {"train_bc": SOLVED["hw1_imitation"]["train_bc"], "bc_loss": HW1_BC_LOSS_SUMMED,
                       "dagger": SOLVED["hw1_imitation"]["dagger"]},
     {"train_bc": "full", "bc_loss": "zero", "dagger": "full"}),
    ("hw2b_adversarial", HW2B_HALF_WORK, {k: "zero" for k in HW2B_HALF_WORK}),
    ("hw2b_adversarial", HW2B_ALLOWED, {k: "full" for k in HW2B_ALLOWED}),
    ("hw2_maxent_irl", HW2_SHORTCUTS, {k: "zero" for k in HW2_SHORTCUTS}),
    ("hw2_maxent_irl", HW2_KEEP_THE_STAND_IN, {"route_log_partition": "zero", "fit_route_weights": "full"}),
    # and a correct fit_route_weights beside a missing route_log_partition
    # and a correct state_visitation_frequency beside a missing soft_value_iteration
    ("hw2_maxent_irl", {"deep_maxent_irl": HW2_DEEP_ALLOWED, "maxent_irl": HW2_SAMPLE_VARIANCE,
                        "fit_route_weights": SOLVED["hw2_maxent_irl"]["fit_route_weights"],
                        "state_visitation_frequency": HW2_VISITS_EINSUM},
     {"deep_maxent_irl": "full", "maxent_irl": "full", "fit_route_weights": "full",
      "state_visitation_frequency": "full"}),
    ("hw3_preferences", {"fit_bradley_terry": HW3_GD_BY_MM,
                         "fit_bradley_terry_mm": SOLVED["hw3_preferences"]["fit_bradley_terry_mm"],
                         "select_queries": HW3_SELECT_REVERSED, "ratings_to_comparisons": HW3_RATINGS_LOOP,
                         "bt_gradient": HW3_GRADIENT_BY_AUTOGRAD},
     {"fit_bradley_terry": "zero", "fit_bradley_terry_mm": "full", "select_queries": "full",
      "ratings_to_comparisons": "full", "bt_gradient": "full"}),
    ("hw3_preferences", {"fit_bradley_terry": HW3_GD_BY_SCIPY, "bt_loss": SOLVED["hw3_preferences"]["bt_loss"],
                         "select_queries": HW3_SELECT_TOPK, "bt_gradient": HW3_GRADIENT_BY_DIFFERENCES,
                         "fit_bradley_terry_mm": HW3_MM_BY_SCIPY},
     {"fit_bradley_terry": "zero", "select_queries": "full", "bt_gradient": "zero", "fit_bradley_terry_mm": "zero"}),
    # correct stubs beside missing ones they call with networks (which the grader's reference cannot take)
    ("hw3_preferences", {"train_reward_model": SOLVED["hw3_preferences"]["train_reward_model"],
                         "select_queries": SOLVED["hw3_preferences"]["select_queries"]},
     {"train_reward_model": "full", "select_queries": "full"}),
]


@pytest.mark.parametrize("case", range(len(CASES)), ids=[f"{a}-{'-'.join(w)}" for a, _, w in CASES])
def test_shortcuts_earn_nothing_and_allowed_variants_everything(case, open_tmp):
    assignment, stubs, want = CASES[case]
    scores = graded_stubs(assignment, stubs, open_tmp / f"{assignment}_{case}.ipynb")
    for name, outcome in want.items():
        stub = scores[name]
        failed = [f"{t.name}: {t.message}" for t in stub.tests if not t.passed]
        if outcome == "zero":
            assert stub.max_score > 0 and stub.score == 0, f"{assignment} {name}: the shortcut earned {stub.score}"
        else:
            assert stub.score == stub.max_score, f"{assignment} {name}: an allowed variant lost points: {failed}"


def test_select_queries_accepts_either_order_of_equal_variances():
    """hw3's selection check: a repeated candidate (equal variances) may come in either order, a wrong pick may not."""
    sys.path.insert(0, str(course.suite_dir("hw3_preferences")))
    try:
        from test_select_queries import _check_selection
    finally:
        sys.path.pop(0)
    var = np.array([0.1, 0.3, 0.3, 0.05, 0.2])           # candidates 1 and 2 are the same pair
    for got in ([1, 2, 4], [2, 1, 4]):
        _check_selection(np.array(got), var, 3, "the selection")
    for wrong in ([1, 4, 2], [1, 2, 0], [1, 1, 4]):
        with pytest.raises(AssertionError):
            _check_selection(np.array(wrong), var, 3, "the selection")


def _suite_module(assignment: str, name: str):
    """The suite file ``name`` of ``assignment``, imported with its own folder first on the path (and its own
    ``conftest``, put back afterwards)."""
    import importlib

    folder = str(course.suite_dir(assignment))
    saved = {k: sys.modules.pop(k) for k in ("conftest", name) if k in sys.modules}
    sys.path.insert(0, folder)
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(folder)
        for k in ("conftest", name):
            sys.modules.pop(k, None)
        sys.modules.update(saved)


class _CorrectModeCoverage:
    """A student namespace whose mode_coverage is right, raising ValueError for an expert that never passed."""

    @staticmethod
    def mode_coverage(sides, expert_sides):
        sides, expert_sides = np.asarray(sides), np.asarray(expert_sides)
        q_left, q_right = np.mean(expert_sides == 1), np.mean(expert_sides == -1)
        if q_left + q_right == 0:
            raise ValueError("the expert never passed")
        p_left, p_right = np.mean(sides == 1), np.mean(sides == -1)
        return {"left": float(p_left), "right": float(p_right), "not_passed": float(np.mean(sides == 0)),
                "coverage": float((min(p_left, q_left) + min(p_right, q_right)) / (q_left + q_right))}


def test_mode_coverage_random_labels_never_draw_an_expert_that_never_passed():
    """hw1b: seed 1575 of the test's generator draws, in its first round, an expert whose episodes all failed to pass
    (about 1 draw in 2,000), where a correct stub must raise; the test hands over a passing episode instead."""
    suite = _suite_module("hw1b_multimodal", "test_mode_coverage")
    rng = np.random.default_rng(1575)                 # the premise: the first round's expert, as drawn, never passes
    suite._labels(rng, int(rng.integers(20, 60)), rng.dirichlet(np.ones(3)))
    drawn = suite._labels(rng, int(rng.integers(10, 40)), rng.dirichlet(np.ones(3)) * 0.8 + np.array([0.1, 0.1, 0.0]))
    assert not (drawn != 0).any(), "seed 1575 no longer draws an expert that never passed: pick another seed"
    seen = []

    class Recording(_CorrectModeCoverage):
        @staticmethod
        def mode_coverage(sides, expert_sides):
            seen.append(np.asarray(expert_sides).copy())
            return _CorrectModeCoverage.mode_coverage(sides, expert_sides)

    suite.test_fractions_and_coverage_on_random_labels(Recording(), np.random.default_rng(1575))
    assert len(seen) == 3 and all((e != 0).any() for e in seen), "every expert handed over passes at least once"
