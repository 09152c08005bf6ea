"""Hidden tests of hw1b's `chunked_rollout`: the environments stay in the grader (lent), and every check is
against what the grader's own copy of the environment received and returned."""
import numpy as np

from autograder.suite import check_array, lend, stub
from conftest import raised
from rlcourse import multimodal as mm

HINT = ("Call env.reset() once; at steps t = 0, k, 2k, ... call plan once on all n observations; at step t run "
        "action t - k * (t // k) of the latest chunk; stop when every episode has ended; mask is True up to and "
        "including the step that ended an episode; pad with zeros.")


class Recording:
    """A trusted environment that logs every call the stub makes to it."""

    def __init__(self, env) -> None:
        self.env, self.resets, self.obs, self.actions, self.after = env, 0, [], [], []

    def reset(self):
        self.resets += 1
        self.obs, self.actions, self.after = [], [], []
        first = self.env.reset()
        self.obs.append(np.array(first, dtype=np.float32))
        return first

    def step(self, actions):
        self.actions.append(np.array(actions, dtype=np.float64).reshape(len(self.obs[0]), -1))
        out = self.env.step(actions)
        self.after.append(tuple(np.array(x) for x in out[1:]))
        self.obs.append(np.array(out[0], dtype=np.float32))
        return out


class LinearPlanner:
    """chunk[i, j, :] = tanh(obs[i] @ weights[j] + bias[j]): a deterministic planner, lent to the stub, that keeps the
    grader's record of its calls (``rows``: the batch size of every call).

    weights (H, obs_dim, act_dim), bias (H, act_dim).
    """

    def __init__(self, weights, bias) -> None:
        self.weights, self.bias = np.asarray(weights, dtype=np.float64), np.asarray(bias, dtype=np.float64)
        self.rows = []

    def plan(self, obs):
        obs = np.asarray(obs, dtype=np.float64)
        self.rows.append(len(obs))
        return np.tanh(np.einsum("nd,hda->nha", obs, self.weights) + self.bias).astype(np.float32)


def _lent(planner):
    return lend(planner, methods=["plan"])


class Scripted:
    """n episodes that end after lengths[i] steps (terminated where flags[i], else truncated), whatever the
    actions; observations are a fixed random state per episode plus the step count."""

    def __init__(self, lengths, flags, base) -> None:
        self.lengths, self.flags, self.base = np.asarray(lengths), np.asarray(flags, dtype=bool), np.asarray(base)
        self.n_envs = len(self.lengths)

    def reset(self):
        self.t = 0
        return self.base.astype(np.float32)

    def step(self, actions):
        self.t += 1
        obs = (self.base + 0.1 * min(self.t, 10**6) * np.sign(self.base)).astype(np.float32)
        ended = self.t >= self.lengths
        still = self.t <= self.lengths
        rewards = np.where(still, 1.0 + 0.01 * self.t, 0.0)
        return obs, rewards, ended & self.flags, ended & ~self.flags


def _planner(rng, horizon, obs_dim, act_dim=1, scale=1.0):
    return scale * rng.normal(size=(horizon, obs_dim, act_dim)), 0.3 * rng.normal(size=(horizon, act_dim))


def _expected(rec, weights, bias, execute):
    """What a correct run sends: from the logged observations and the planner's closed form."""
    T = len(rec.actions)
    want = []
    for t in range(T):
        t0 = execute * (t // execute)
        chunk = np.tanh(np.einsum("nd,hda->nha", rec.obs[t0].astype(np.float64), weights) + bias)
        want.append(chunk[:, t - t0])
    return np.stack(want)          # (T, n, act_dim)


def _run(student, env, weights, bias, execute):
    rec, planner = Recording(env), LinearPlanner(weights, bias)
    episodes = student.helpers.run_chunked(lend(rec, methods=["reset", "step"], attrs=[]), _lent(planner), execute)
    assert isinstance(episodes, dict), "chunked_rollout did not run"
    rows = list(planner.rows)
    for name in ("obs", "actions", "rewards", "mask", "lengths", "terminated"):
        assert isinstance(episodes.get(name), np.ndarray), \
            f"the returned Episodes' {name} should be a numpy array, got {type(episodes.get(name)).__name__}"
    return rec, episodes, rows


def _truth(rec):
    """Mask, lengths and terminated from the trusted log."""
    n = len(rec.obs[0])
    ended = np.zeros(n, dtype=bool)
    mask, terminated = [], np.zeros(n, dtype=bool)
    for term, trunc in ((a[1], a[2]) for a in rec.after):
        mask.append(~ended)
        terminated |= ~ended & term.astype(bool)
        ended = ended | term.astype(bool) | trunc.astype(bool)
    return np.stack(mask, axis=1), terminated


@stub("chunked_rollout", points=2, hint=HINT)
def test_runs_each_action_of_the_latest_chunk(student, rng):
    """On the obstacle track (lent): the actions sent at every step are the right entries of the right chunks"""
    n, execute, horizon = 6, int(rng.integers(2, 4)), 5
    weights, bias = _planner(rng, horizon, mm.OBS_DIM, scale=0.5)
    rec, episodes, rows = _run(student, mm.ObstacleTracks(n, int(rng.integers(0, 10**6))), weights, bias, execute)
    assert rec.resets == 1, f"call env.reset() exactly once, it was called {rec.resets} times"
    sent = np.stack(rec.actions)                                       # (T, n, 1)
    want = _expected(rec, weights, bias, execute)
    mask, _ = _truth(rec)
    live = mask.T[..., None]                                           # compare on real steps only
    check_array(np.where(live, sent, 0.0), np.where(live, want, 0.0), rtol=1e-5, atol=1e-5,
                name=f"the actions sent to env.step (execute={execute}), step by step")
    calls = -(-len(rec.actions) // execute)
    assert rows == [n] * calls, (f"plan should be called once every {execute} steps (at steps 0, {execute}, ...) on all "
                                 f"{n} observations; for the {len(rec.actions)} steps your run took, it was called "
                                 f"{len(rows)} times with {sorted(set(rows))} rows")


@stub("chunked_rollout", points=2, hint=HINT)
def test_records_the_episodes_exactly(student, rng):
    """The returned obs, actions, rewards, mask, lengths and terminated match the grader's log, zero-padded"""
    n, execute = 5, 2
    weights, bias = _planner(rng, 3, mm.OBS_DIM, scale=2.0)            # hard steering: crashes at different steps
    rec, ep, _ = _run(student, mm.ObstacleTracks(n, int(rng.integers(0, 10**6))), weights, bias, execute)
    mask, terminated = _truth(rec)
    T = len(rec.actions)
    assert ep["mask"].shape == (n, T), f"mask should be (n, T) = {(n, T)}, with T the longest episode; got {ep['mask'].shape}"
    check_array(ep["mask"].astype(bool), mask, name="the mask (True up to and including the step that ends an episode)")
    check_array(ep["lengths"], mask.sum(axis=1), name="the lengths")
    check_array(ep["terminated"].astype(bool), terminated, name="terminated")
    obs = np.stack(rec.obs[:T], axis=1) * mask[..., None]
    check_array(ep["obs"], obs.astype(np.float32), rtol=1e-5, atol=1e-6, name="obs (the observation each action was chosen from)")
    check_array(ep["actions"], (np.stack(rec.actions, axis=1) * mask[..., None]).astype(np.float32), rtol=1e-5, atol=1e-6,
                name="actions")
    rewards = np.stack([a[0] for a in rec.after], axis=1) * mask
    check_array(ep["rewards"], rewards.astype(np.float32), rtol=1e-5, atol=1e-6, name="rewards (zero after an episode ends)")
    assert ep["obs"].dtype == np.float32 and ep["actions"].dtype == np.float32, "obs and actions should be float32"


@stub("chunked_rollout", points=2, hint="An episode may end in the middle of a chunk: it stops there (mask False "
      "afterwards) while the others go on executing the same chunk; stop stepping when every episode has ended. "
      "A chunk of exactly `execute` actions is valid.")
def test_episodes_that_end_inside_a_chunk(student, rng):
    """Scripted episodes of hidden lengths ending inside chunks of k actions: lengths, flags, zero-padded rewards, obs and actions, no extra steps"""
    n, execute = 4, 4
    lengths = rng.choice(np.arange(2, 15), size=n, replace=False)
    lengths[0] = execute * int(rng.integers(1, 3)) + int(rng.integers(1, execute))   # inside a chunk, not at its end
    flags = rng.random(n) < 0.5
    base = rng.normal(size=(n, 3))
    weights, bias = _planner(rng, execute, 3)                          # chunks of exactly `execute` actions
    rec, ep, rows = _run(student, Scripted(lengths, flags, base), weights, bias, execute)
    T = int(lengths.max())
    assert len(rec.actions) == T, ("env.step should be called until the longest episode has ended and then no more "
                                   f"(it was called {len(rec.actions)} times, "
                                   f"{'too few' if len(rec.actions) < T else 'too many'})")
    check_array(ep["lengths"], lengths, name="the lengths")
    check_array(ep["terminated"].astype(bool), flags, name="terminated (True only for episodes ended by terminated)")
    mask = np.arange(T)[None, :] < lengths[:, None]
    check_array(ep["mask"].astype(bool), mask, name="the mask")
    rewards = np.stack([a[0] for a in rec.after], axis=1) * mask          # the lengths differ: padding is certain
    check_array(ep["rewards"], rewards.astype(np.float32), rtol=1e-5, atol=1e-6, name="rewards (zero after an episode ends)")
    sent = (np.stack(rec.actions, axis=1) * mask[..., None]).astype(np.float32)
    check_array(ep["actions"], sent, rtol=1e-5, atol=1e-6, name="actions (the ones sent, zero after an episode ends)")
    seen = (np.stack(rec.obs[:T], axis=1) * mask[..., None]).astype(np.float32)
    check_array(ep["obs"], seen, rtol=1e-5, atol=1e-6, name="obs (the ones each action was chosen from, zero after an "
                "episode ends)")
    want = _expected(rec, weights, bias, execute)
    check_array(np.stack(rec.actions)[:, 0], want[:, 0], rtol=1e-5, atol=1e-5,
                name="the actions of the longest-running episodes after another one ended")
    assert rows == [n] * (-(-T // execute)), \
        f"plan should be called on all {n} episodes once every {execute} steps; it was called with {rows} rows"


@stub("chunked_rollout", points=1, hint="With execute = 1 a chunked policy is an ordinary policy: plan at every step and run chunk[:, 0].")
def test_execute_one_is_an_ordinary_policy(student, rng):
    """execute = 1 with chunks of 4: every step plans and runs the first action"""
    weights, bias = _planner(rng, 4, mm.OBS_DIM, scale=0.3)
    rec, ep, rows = _run(student, mm.ObstacleTracks(3, int(rng.integers(0, 10**6))), weights, bias, 1)
    want = _expected(rec, weights, bias, 1)
    mask, _ = _truth(rec)
    check_array(np.where(mask.T[..., None], np.stack(rec.actions), 0), np.where(mask.T[..., None], want, 0), rtol=1e-5,
                atol=1e-5, name="the actions")
    assert len(rows) == len(rec.actions), f"plan should be called at every step ({len(rec.actions)}), got {len(rows)} calls"


@stub("chunked_rollout", points=1, hint="Raise ValueError when execute < 1 or a chunk is shorter than execute (or has the wrong number of rows).")
def test_refuses_chunks_shorter_than_execute(student, rng):
    """A chunk of H < execute actions, and execute = 0, raise ValueError; a chunk of H = execute actions runs"""
    for horizon, execute in ((2, 3), (3, 0)):
        weights, bias = _planner(rng, horizon, 3)
        env = Scripted(np.array([5, 6]), np.array([True, False]), rng.normal(size=(2, 3)))
        outcome = raised(student.helpers.run_chunked, lend(env, ["reset", "step"]),
                         _lent(LinearPlanner(weights, bias)), execute)
        assert outcome == "ValueError", (f"chunks of {horizon} actions with execute={execute} should raise ValueError, "
                                         f"got {outcome}")
    weights, bias = _planner(rng, 3, 3)
    rec, ep, _ = _run(student, Scripted(np.array([5, 6]), np.array([True, False]), rng.normal(size=(2, 3))), weights,
                      bias, 3)
    check_array(ep["lengths"], np.array([5, 6]), name="the lengths with chunks of exactly execute = 3 actions (valid)")
    want = _expected(rec, weights, bias, 3)
    check_array(np.stack(rec.actions)[:, 1], want[:, 1], rtol=1e-5, atol=1e-5,
                name="the actions with chunks of exactly execute = 3 actions (valid)")
