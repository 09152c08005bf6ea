"""Hidden tests of hw3's rucb (dueling bandits).

Most tests check the contract step by step instead of learning to a result: the grader keeps its own record of
every duel asked of a lent environment and of the outcome it answered, rebuilds the win counts W and the bounds U
from that record, and checks that each duel (c_t, d_t) is one RUCB may play at step t (c_t a candidate, the
remembered arm kept and forgotten as the notebook says, d_t a maximiser of U[:, c_t]). A few hundred duels then
separate right from wrong exactly, where statistics over tens of thousands of duels did before; one test still
learns, on a planted instance.
"""
import numpy as np
from scipy.special import expit

from autograder.suite import lend, stub
from rlcourse.preferences import DuelingBandit

HINT = ("U = W/N + sqrt(alpha ln t / N) (1 where N = 0, 1/2 on the diagonal); candidates c with U[c, j] >= 1/2 for all j; "
        "challenger d = argmax_j U[j, c]; duel (c, d) through env.duel and update W.")
ALPHA = 0.51          # sandbox_helpers.run_rucb's default, the notebook's
SLACK = 1e-9          # rounding allowed in a bound that decides a choice


class _Recorder:
    """An environment as lent to the stub, with the grader's own record of every duel asked of it and of the
    outcome it answered: the tests judge this record, never the duels the stub says it played."""

    def __init__(self, env) -> None:
        self.env, self.n_arms, self.duels, self.outcomes = env, env.n_arms, [], []

    def duel(self, c, d) -> float:
        outcome = float(self.env.duel(c, d))
        self.duels.append((int(c), int(d)))
        self.outcomes.append(outcome)
        return outcome


def _played(student, env, horizon, seed):
    """The recorder of the duels the stub asked of ``env``, after checking it returned exactly them."""
    recorder = _Recorder(env)
    returned = student.helpers.run_rucb(lend(recorder, methods=["duel"], attrs=["n_arms"]), horizon, seed, timeout=60)
    n = len(recorder.duels)
    assert n == horizon, f"rucb should duel exactly once per step through env.duel ({horizon} steps), it dueled {n} times"
    played = np.array(recorder.duels, dtype=np.int64).reshape(-1, 2)
    assert isinstance(returned, np.ndarray) and returned.shape == (horizon, 2), \
        f"rucb should return an array of shape ({horizon}, 2), got {type(returned).__name__} {np.shape(returned)}"
    assert returned.dtype.kind in "iu", f"the duels should be integer arm indices, got dtype {returned.dtype}"
    assert np.array_equal(returned, played), \
        "the returned duels are not the ones played through env.duel: row t should be the (c, d) of the t-th env.duel(c, d)"
    assert played.min() >= 0 and played.max() < env.n_arms, "arm indices out of range"
    return recorder


def _replay(recorder):
    """Step through the grader's record with the notebook's rules: the first duel RUCB may not play (a message,
    or None), and per step whether a remembered arm b was in a candidate set of two or more and whether c was b."""
    k = recorder.n_arms
    W = np.zeros((k, k))
    remembered, offers = None, []
    for t, ((c, d), won) in enumerate(zip(recorder.duels, recorder.outcomes), start=1):
        N = W + W.T
        with np.errstate(divide="ignore", invalid="ignore"):
            U = np.where(N > 0, W / N + np.sqrt(ALPHA * np.log(t) / N), 1.0)
        np.fill_diagonal(U, 0.5)
        C = np.flatnonzero((U >= 0.5 - SLACK).all(axis=1))
        if remembered is not None and remembered not in C:
            remembered = None
        if C.size and c not in C:
            why = (f"arm {c} cannot be the Condorcet winner by then (U[{c}, j] < 1/2 for some j), so it is not a "
                   "candidate" if remembered != c else f"arm {c} was remembered but had left the candidate set")
            return f"at step t = {t} the candidate c = {c} is not in C: {why}", offers
        if C.size == 1:
            remembered = int(C[0])
        elif C.size > 1 and remembered is not None:
            offers.append(c == remembered)
        if U[d, c] < U[:, c].max() - SLACK:
            return (f"at step t = {t} the challenger d = {d} of c = {c} is not a maximiser of U[j, {c}] over j (the arm "
                    "most likely to beat c optimistically)"), offers
        if won == 1.0:
            W[c, d] += 1
        else:
            W[d, c] += 1
    return None, offers


def _check_rules(recorder, where):
    wrong, offers = _replay(recorder)
    assert wrong is None, f"on {where}, {wrong}"
    return offers


def _bt_instance(rng, k, gap=0.3):
    u = np.sort(rng.normal(size=k))[::-1].copy()
    u[0] += gap                                          # a clear best arm
    perm = rng.permutation(k)
    u = u[perm]
    return expit(u[:, None] - u[None, :]), int(np.argmax(u))


def _cyclic_instance(win=0.7):
    """Arm 0 beats everyone with probability ``win``; arms 1..4 form a cycle (no strong stochastic transitivity)."""
    P = np.full((5, 5), 0.5)
    for j in range(1, 5):
        P[0, j], P[j, 0] = win, 1 - win
    for a, b in ((1, 2), (2, 3), (3, 4), (4, 1)):
        P[a, b], P[b, a] = 0.9, 0.1
    for a, b in ((1, 3), (2, 4)):
        P[a, b], P[b, a] = 0.5 + 1e-3, 0.5 - 1e-3
    return P


def _run(student, P, horizon, seed):
    return np.array(_played(student, DuelingBandit(P, seed), horizon, seed).duels, dtype=np.int64)


class _StrictOrder:
    """A bandit without noise: of two arms, the one ranked higher always wins (ranks are a hidden permutation)."""

    def __init__(self, rank: np.ndarray) -> None:
        self.rank, self.n_arms = rank, len(rank)

    def duel(self, c: int, d: int) -> float:
        return 1.0 if self.rank[c] <= self.rank[d] else 0.0


class _LeaderFalls:
    """Arm 1 wins every duel for the first ``switch`` steps, then loses every one; other duels are coin flips."""

    def __init__(self, n_arms: int, switch: int, seed: int) -> None:
        self.n_arms, self.switch, self.t, self.rng = n_arms, switch, 0, np.random.default_rng(seed)

    def duel(self, c: int, d: int) -> float:
        self.t += 1
        if c == d:
            return 1.0
        if 1 in (c, d):
            return float((c == 1) == (self.t <= self.switch))
        return float(self.rng.random() < 0.5)


@stub("rucb", points=1, hint=HINT)
def test_plays_through_the_environment(student, rng):
    """Returns (horizon, 2) integer duels, calls env.duel once per step and explores every arm"""
    P, _ = _bt_instance(rng, 4)
    pairs = _run(student, P, 300, 0)
    again = _run(student, P, 300, 0)
    assert np.array_equal(pairs, again), ("two runs with the same rng seed (and the same bandit) dueled differently: draw "
                                          "every random choice from the rng argument")
    unseen = sorted(set(range(len(P))) - set(pairs.ravel().tolist()))
    assert not unseen, (f"arms {unseen} were never played in 300 duels: with no duels yet every U is 1, so every "
                        "arm is a candidate and RUCB explores them all")
    u = rng.permutation(np.array([1.5, 0.0, -0.2, -0.4]))          # one clearly best arm
    easy, best = expit(u[:, None] - u[None, :]), int(np.argmax(u))
    share = np.mean(_run(student, easy, 300, 1)[150:] == best)
    assert share > 0.6, ("with one clearly best arm, the second half of 300 duels should mostly play it (the reference: "
                         "over 90%; uniform pairs: 25%): are the candidates and the challenger chosen from U?")


@stub("rucb", points=2, hint=HINT)
def test_candidates_and_challengers_follow_the_bounds(student, rng):
    """Every one of 400 duels on noisy bandits (Bradley–Terry, and cyclic) is a candidate against its optimistic challenger"""
    P, _ = _bt_instance(rng, 5)
    for seed in range(2):
        _check_rules(_played(student, DuelingBandit(P, seed), 400, seed), f"a Bradley–Terry bandit (run {seed + 1})")
    perm = rng.permutation(5)
    _check_rules(_played(student, DuelingBandit(_cyclic_instance()[np.ix_(perm, perm)], 2), 400, 2), "a cyclic bandit")


@stub("rucb", points=1, hint="The bonus is sqrt(alpha ln t / N): it grows with t, so an arm that has lost stays a "
                             "candidate until it has lost about 4 alpha ln t times, and RUCB keeps exploring.")
def test_explores_at_the_rate_of_its_bonus(student, rng):
    """Noiseless duels among 6 arms: every loser stays a candidate exactly while its bonus sqrt(alpha ln t / N) allows"""
    rank = rng.permutation(6)
    for seed in range(2):
        _check_rules(_played(student, _StrictOrder(rank), 400, seed), f"a noiseless bandit (run {seed + 1})")


@stub("rucb", points=2, hint="Remember the single candidate b whenever |C| = 1, forget it as soon as it leaves C "
                             "(B = B ∩ C every step), and play it with probability 1/2 while it is remembered.")
def test_remembers_and_forgets_a_candidate(student):
    """An early leader that then loses every duel: the remembered arm is played half the time, and forgotten once it leaves C"""
    offers = []
    for seed in range(2):
        offers += _check_rules(_played(student, _LeaderFalls(4, 100, 100 + seed), 400, seed),
                               f"a bandit whose early leader (arm 1) loses every duel after step 100 (run {seed + 1})")
    # The reference meets a remembered arm among two or more candidates 52 to 100 times a run and plays it in
    # 34% to 68% of them in one run; two runs pooled stay well inside [0.3, 0.7] (a binomial sd of about 0.04).
    assert len(offers) >= 40, (f"the remembered arm was among two or more candidates in only {len(offers)} steps of "
                               "800 (the reference: over 100)")
    share = float(np.mean(offers))
    assert 0.3 <= share <= 0.7, (f"while the remembered arm b was one of two or more candidates, c was b in {share:.0%} "
                                 "of the steps: it should be b with probability 1/2, another candidate otherwise")


@stub("rucb", points=2, hint=HINT)
def test_converges_to_condorcet_winner(student, rng):
    """600 duels on two planted instances (a Condorcet winner over arms that cycle): the last 200 mostly play the winner"""
    # The reference plays the winner in at least 80% of the last 200 duels on each of 300 draws (seed 3). The two
    # instances put the winner on different arms, so an answer that always plays one arm fails one of them.
    first = rng.permutation(5)
    second = rng.permutation(5)
    if np.argmin(second) == np.argmin(first):
        second = np.roll(second, 1)
    for run, perm in enumerate((first, second)):
        P, best = _cyclic_instance(win=0.8)[np.ix_(perm, perm)], int(np.argmin(perm))
        share = np.mean(_run(student, P, 600, 3 + run)[-200:] == best)
        assert share > 0.6, (f"on a bandit whose Condorcet winner (arm {best}) beats every other arm with probability "
                             f"0.8, only {share:.0%} of the arms played in the last 200 of 600 duels are the winner: RUCB "
                             "should be dueling it against itself by then (the reference: over 80%)")
