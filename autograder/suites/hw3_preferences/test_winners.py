"""Hidden tests of hw3's condorcet_winner, copeland_winner and borda_winner."""
import numpy as np
from scipy.special import expit

from autograder.suite import stub

C_HINT = "The Condorcet winner beats every other arm with P > 1/2 strictly; return None when there is none."
CO_HINT = "Copeland: count, for each arm (row), the other arms it beats with P[i, j] > 1/2 strictly; argmax."
B_HINT = "Borda: for each arm (row), the mean of P[i, j] over the K - 1 other arms j; argmax (smallest index on ties)."


def _from_upper(upper, k):
    P = np.full((k, k), 0.5)
    for (a, b), p in upper.items():
        P[a, b], P[b, a] = p, 1.0 - p
    return P


# Condorcet: none; Copeland: 0 (3 wins); Borda: 1 (mean 0.70).
DIFFER = _from_upper({(0, 1): .55, (0, 2): .55, (0, 3): .55, (0, 4): .40, (1, 2): .45, (1, 3): .95, (1, 4): .95,
                      (2, 3): .40, (2, 4): .60, (3, 4): .60}, 5)
# Arm 2 beats 0 and 3 and ties arm 1 exactly: no Condorcet winner (ties do not count as wins).
TIED = _from_upper({(0, 1): .3, (0, 2): .4, (0, 3): .6, (1, 2): .5, (1, 3): .45, (2, 3): .8}, 4)
# Strict wins: arm 1 has two; counting P = 1/2 as a win would give arms 0 and 1 three each (and pick 0).
COPELAND_TIES = _from_upper({(0, 1): .5, (0, 2): .5, (0, 3): .7, (1, 2): .6, (1, 3): .6, (2, 3): .6}, 4)


def _permuted(P, rng):
    perm = rng.permutation(len(P))
    inv = np.argsort(perm)
    return P[np.ix_(perm, perm)], inv      # arm a of P is arm inv[a] of the permuted matrix


def _is_int(x):
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


def _shown(x):
    """A student's answer as plain text: 3, None, or its type (never numpy's repr, np.int64(3))."""
    if x is None or _is_int(x):
        return "None" if x is None else f"arm {int(x)}"
    return f"a {type(x).__name__}"


def _random_bt(rng, k):
    u = rng.normal(size=k)
    return expit(u[:, None] - u[None, :]), int(np.argmax(u))


@stub("condorcet_winner", points=1, hint=C_HINT)
def test_condorcet_exists(student, rng):
    """Bradley–Terry instances: the arm of highest utility, as an int"""
    for k in (3, 6, 9):
        P, best = _random_bt(rng, k)
        got = student.condorcet_winner(P)
        assert _is_int(got), f"return an int arm index, got {_shown(got)}"
        assert got == best, (f"on a {k}-arm Bradley–Terry instance you returned {_shown(got)}, which does not beat "
                             "every other arm with P > 1/2")


@stub("condorcet_winner", points=1, hint=C_HINT)
def test_condorcet_none(student, rng):
    """No Condorcet winner: a cycle, the hand-made instance permuted, and an exact tie; and one that has a winner"""
    cycle = _from_upper({(0, 1): .7, (1, 2): .7, (0, 2): .3}, 3)
    P, _ = _permuted(DIFFER, rng)
    for name, M in (("a 3-cycle", cycle), ("a 5-arm instance", P), ("an instance whose best arm ties one opponent", TIED)):
        got = student.condorcet_winner(M)
        assert got is None, f"{name} has no Condorcet winner, got {_shown(got)}"
    P, best = _random_bt(rng, 4)
    got = student.condorcet_winner(P)
    assert _is_int(got) and got == best, (f"a 4-arm Bradley–Terry instance has a Condorcet winner; you returned "
                                          f"{_shown(got)}")


@stub("condorcet_winner", points=1, hint=C_HINT)
def test_condorcet_random_matches_reference(student, reference, rng):
    """Random preference matrices (most without a Condorcet winner, one with a planted one)"""
    for i in range(6):
        A = rng.random((5, 5))
        P = np.triu(A, 1) + np.tril(1 - A.T, -1) + 0.5 * np.eye(5)
        if i == 5:  # a winner planted in the last one: on some draws no random matrix has one, and None passed them all
            k = rng.integers(5)
            others = np.arange(5) != k
            P[k, others] = 0.5 + 0.5 * rng.uniform(0.05, 1.0, 4)
            P[others, k] = 1.0 - P[k, others]
        want, got = reference.condorcet_winner(P), student.condorcet_winner(P)
        assert got == want and (got is None) == (want is None), (
            f"{_shown(got)} is wrong for P =\n{P.round(2)}\n"
            + ("(this matrix has a Condorcet winner)" if want is not None else "(this matrix has none: return None)"))


@stub("copeland_winner", points=2, hint=CO_HINT)
def test_copeland_hand_made(student, rng):
    """The instance where the three winners differ (permuted), and one with exact ties"""
    P, inv = _permuted(DIFFER, rng)
    got = student.copeland_winner(P)
    assert _is_int(got) and got == inv[0], (f"got {_shown(got)}, not the arm with the most strict wins "
                                            "(count P[i, j] > 1/2 over the other arms j)")
    got = student.copeland_winner(COPELAND_TIES)
    assert got == 1, f"got {_shown(got)}: P = 0.5 is not a win (count strict wins only)"


@stub("copeland_winner", points=1, hint=CO_HINT)
def test_copeland_random_matches_reference(student, reference, rng):
    """Random matrices, compared with the definition"""
    for _ in range(6):
        A = rng.random((6, 6))
        P = np.triu(A, 1) + np.tril(1 - A.T, -1) + 0.5 * np.eye(6)
        want, got = reference.copeland_winner(P), student.copeland_winner(P)
        assert got == want, f"{_shown(got)} is not the arm with the most strict wins for P =\n{P.round(2)}"


@stub("borda_winner", points=2, hint=B_HINT)
def test_borda_hand_made(student, rng):
    """The instance where the three winners differ, under two permutations that put its Borda winner at different arms"""
    perm = rng.permutation(len(DIFFER))
    for shift in (0, 1):                                   # arm a sits at (inv[a] + shift) % K: a constant fails one
        p = np.roll(perm, shift)
        got = student.borda_winner(DIFFER[np.ix_(p, p)])
        assert _is_int(got) and got == np.argsort(p)[1], (f"got {_shown(got)}, not the arm with the highest mean "
                                                          "P[i, j] over the K - 1 other arms (the diagonal excluded)")


@stub("borda_winner", points=1, hint=B_HINT)
def test_borda_random_matches_reference(student, reference, rng):
    """Random matrices, compared with the definition"""
    for _ in range(6):
        A = rng.random((7, 7))
        P = np.triu(A, 1) + np.tril(1 - A.T, -1) + 0.5 * np.eye(7)
        want, got = reference.borda_winner(P), student.borda_winner(P)
        assert got == want, (f"{_shown(got)} is not the arm with the highest mean P[i, j] over the other arms "
                             f"(smallest index on ties) for P =\n{P.round(2)}")
    two = np.array([[0.5, 0.35], [0.65, 0.5]])            # two arms: the mean is over the K - 1 = 1 other arm
    got = student.borda_winner(two)
    assert _is_int(got) and got == 1, f"with two arms, got {_shown(got)}: the arm that beats the other with P > 1/2 wins"
