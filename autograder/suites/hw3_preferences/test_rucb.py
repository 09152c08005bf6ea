"""Hidden tests of hw3's rucb (dueling bandits)."""
import numpy as np
from scipy.special import expit

from autograder.suite import lend, stub
from rlcourse.preferences import DuelingBandit, dueling_regret

HINT = ("U = W/N + sqrt(alpha ln t / N) (1 where N = 0, 1/2 on the diagonal); candidates c with U[c, j] >= 1/2 for all j; "
        "challenger d = argmax_j U[j, c]; duel (c, d) through env.duel and update W.")



class _Recorder:
    """An environment as lent to the stub, with the grader's own record of every duel asked of it: the tests
    judge this record, never the duels the stub says it played."""

    def __init__(self, env) -> None:
        self.env, self.n_arms, self.duels = env, env.n_arms, []

    def duel(self, c, d) -> float:
        self.duels.append((int(c), int(d)))
        return self.env.duel(c, d)


def _played(student, env, horizon, seed):
    """The duels the stub asked of ``env`` (the grader's record), after checking it returned exactly them."""
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
    return played


def _bt_instance(rng, k, gap=0.3):
    u = np.sort(rng.normal(size=k))[::-1].copy()
    u[0] += gap                                          # a clear best arm
    perm = rng.permutation(k)
    u = u[perm]
    return expit(u[:, None] - u[None, :]), int(np.argmax(u))


def _cyclic_instance():
    """Arm 0 beats everyone; arms 1..4 form a cycle (no strong stochastic transitivity among them)."""
    P = np.full((5, 5), 0.5)
    for j in range(1, 5):
        P[0, j], P[j, 0] = 0.7, 0.3
    for a, b in ((1, 2), (2, 3), (3, 4), (4, 1)):
        P[a, b], P[b, a] = 0.9, 0.1
    for a, b in ((1, 3), (2, 4)):
        P[a, b], P[b, a] = 0.5 + 1e-3, 0.5 - 1e-3
    return P


def _uniform_regret(P, horizon, best):
    k = len(P)
    off = ~np.eye(k, dtype=bool)
    a, b = np.nonzero(off)
    return horizon * dueling_regret(P, np.stack([a, b], 1), best).mean()


def _run(student, P, horizon, seed):
    pairs = _played(student, DuelingBandit(P, seed), horizon, seed)
    assert pairs.min() >= 0 and pairs.max() < len(P), "arm indices out of range"
    return pairs


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
def test_regret_well_below_uniform(student, rng):
    """6 Bradley–Terry arms, 2,000 duels, 2 seeds: regret under 40% of uniform pairs'"""
    # The instance varies with the submission, so it must be one the reference passes on every draw: with the best
    # arm 0.6 above the second, the reference's regret was at most 31% of uniform pairs' over 100 draws (3% of
    # draws passed 40% with a gap of 0.3, which would have cost a correct RUCB its points at random).
    P, best = _bt_instance(rng, 6, gap=0.6)
    regret = np.mean([dueling_regret(P, _run(student, P, 2000, s), best).sum() for s in range(2)])
    base = _uniform_regret(P, 2000, best)
    assert regret < 0.4 * base, f"cumulative regret {regret:.0f} is not well below uniform pairs' {base:.0f}"


@stub("rucb", points=2, hint=HINT)
def test_converges_to_condorcet_winner(student, rng):
    """Late duels concentrate on the Condorcet winner, also when the other arms cycle"""
    for name, (P, best) in (("a Bradley–Terry instance", _bt_instance(rng, 5)), ("a cyclic instance", (_cyclic_instance(), 0))):
        pairs = _run(student, P, 2500, 3)
        share = np.mean(pairs[-800:] == best)
        assert share > 0.7, (f"on {name}, only {share:.0%} of the arms played in the last 800 duels are the Condorcet "
                             f"winner (arm {best}); RUCB should be dueling it against itself by then")


@stub("rucb", points=1, hint="Keep the confidence bonus sqrt(alpha ln t / N): without it an early unlucky loss "
                             "can rule the best arm out for good.")
def test_does_not_lock_onto_early_luck(student):
    """A small gap (P = 0.6), 10 runs: the best arm dominates the late duels on average"""
    P = np.array([[0.5, 0.6, 0.6], [0.4, 0.5, 0.6], [0.4, 0.4, 0.5]])
    order = np.array([2, 0, 1])  # relabelled so the best arm is arm 2: favouring arm 0 earns nothing here
    P = P[np.ix_(np.argsort(order), np.argsort(order))]
    best = int(np.flatnonzero((P > 0.5).sum(axis=1) == 2)[0])
    shares = [np.mean(_run(student, P, 2000, seed)[-500:] == best) for seed in range(10)]
    assert np.mean(shares) > 0.6, (f"the best arm ({best}) is only {np.mean(shares):.0%} of the arms played in the last 500 "
                                   f"duels on average over 10 runs (per run: {np.round(shares, 2).tolist()})")


class _StrictOrder:
    """A bandit without noise: of two arms, the one ranked higher always wins (ranks are a hidden permutation)."""

    def __init__(self, rank: np.ndarray) -> None:
        self.rank, self.n_arms = rank, len(rank)

    def duel(self, c: int, d: int) -> float:
        return 1.0 if self.rank[c] <= self.rank[d] else 0.0


@stub("rucb", points=1, hint="The bonus is sqrt(alpha ln t / N): it grows with t, so an arm that has lost stays a "
                             "candidate until it has lost about 4 alpha ln t times, and RUCB keeps exploring.")
def test_explores_at_the_rate_of_its_bonus(student, rng):
    """Noiseless duels among 6 arms, 2,000 steps: every loser is tried until its bonus, sqrt(alpha ln t / N), runs out"""
    rank = rng.permutation(6)
    best = int(np.argmin(rank))
    counts = []
    for seed in range(3):
        pairs = _played(student, _StrictOrder(rank), 2000, seed)
        counts.append(int((np.asarray(pairs) != best).any(axis=1).sum()))
    # A loser j stays a candidate while its bonus against the winner is >= 1/2, N_j <= 4 alpha ln t: about 15 losses
    # each by t = 2,000, so the reference plays 107 to 170 duels that involve a loser; a bonus that shrinks with t
    # (alpha / ln t, say) or no bonus at all plays about 10.
    assert min(counts) >= 40, (f"with noiseless duels, only {counts} of 2,000 duels (3 runs) involved an arm other than "
                               "the best: RUCB should keep each loser as a candidate while sqrt(alpha ln t / N) >= 1/2, "
                               "about 4 alpha ln t ≈ 15 losses each; is the bonus growing with ln t?")
    assert max(counts) <= 600, (f"with noiseless duels, {counts} of 2,000 duels (3 runs) involved an arm other than the "
                                "best: once every loser's bonus has run out RUCB should duel the winner against itself")


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


@stub("rucb", points=1, hint="Keep the remembered candidate only while it is still in the candidate set (B = B ∩ C "
                             "every step): once it leaves C, forget it.")
def test_forgets_a_candidate_that_left_the_set(student):
    """An early leader that then loses every duel stops being played as the candidate c (the remembered arm is
    forgotten once it leaves the candidate set)"""
    shares, leading = [], []
    for seed in range(2):
        pairs = _played(student, _LeaderFalls(4, 300, 100 + seed), 3000, seed)
        shares.append(float(np.mean(np.asarray(pairs)[-1000:, 0] == 1)))
        leading.append(float(np.mean(np.asarray(pairs)[100:300, 0] == 1)))
    assert min(leading) > 0.5, (f"arm 1 won every duel of the first 300 steps, yet it was the candidate c in only "
                                f"{leading} of steps 100 to 300: the sole candidate should be played (the reference: "
                                "over 97%)")
    # Arm 1 is the sole candidate early (so it is remembered), then loses everything: the reference plays it as c
    # in 0.1% of the last 1,000 duels; keeping it remembered after it left C plays it half the time.
    assert max(shares) < 0.1, (f"arm 1 lost every duel after step 300, yet it was the candidate c in {shares} of the "
                               "last 1,000 duels of each run: is the remembered candidate kept after it left C?")
