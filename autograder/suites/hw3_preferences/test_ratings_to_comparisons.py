"""Hidden tests of hw3's ratings_to_comparisons (section C.3)."""
import numpy as np

from autograder.suite import check_array, stub

HINT = ("For each annotator, take their own ratings in session order and pair each with each of their next "
        "`window` ratings (lags 1..window); skip pairs of the same segment; mu = 1, 0.5, 0 when the earlier "
        "rating is higher, equal, lower.")


def _canonical(result, name: str = "the comparisons") -> np.ndarray:
    """``(pairs, mu)`` as rows (smaller segment, larger segment, label for the smaller), sorted: order-free."""
    assert isinstance(result, (tuple, list)) and len(result) == 2, \
        f"{name}: return a pair (pairs, mu), got {type(result).__name__}"
    pairs, mu = np.asarray(result[0]), np.asarray(result[1])
    assert pairs.ndim == 2 and pairs.shape[1] == 2, f"{name}: pairs should have shape (M, 2), got {pairs.shape}"
    assert mu.shape == (len(pairs),), f"{name}: mu should have shape ({len(pairs)},) to match pairs, got {mu.shape}"
    assert not pairs.size or pairs.dtype.kind in "iu", f"{name}: pairs should hold integer indices, got {pairs.dtype}"
    pairs, mu = pairs.astype(np.int64), mu.astype(float)
    flip = pairs[:, 0] > pairs[:, 1]
    rows = np.stack([np.where(flip, pairs[:, 1], pairs[:, 0]), np.where(flip, pairs[:, 0], pairs[:, 1]),
                     np.where(flip, 1 - mu, mu)], 1).astype(float)
    return rows[np.lexsort(rows.T[::-1])]


def _session(rng, n, n_annotators, n_segments):
    return rng.integers(0, n_annotators, n), rng.integers(0, n_segments, n), rng.integers(1, 11, n)


# annotator 1 rates segments 4, 5, 4, 6 (ratings 6, 6, 1, 3); annotator 0 rates 2, 3 (9, 8)
HAND = (np.array([1, 0, 1, 0, 1, 1]), np.array([4, 2, 5, 3, 4, 6]), np.array([6, 9, 6, 8, 1, 3]))
HAND_WINDOW_1 = [(2, 3, 1.0), (4, 5, 0.0), (4, 5, 0.5), (4, 6, 0.0)]
HAND_WINDOW_3 = HAND_WINDOW_1 + [(4, 6, 1.0), (5, 6, 1.0)]      # the lag-2 pair (4, 4) is skipped


@stub("ratings_to_comparisons", points=1, hint=HINT)
def test_hand_made_session(student):
    """Two annotators, six ratings, windows 1 and 3"""
    for window, want in ((1, HAND_WINDOW_1), (3, HAND_WINDOW_3)):
        got = _canonical(student.ratings_to_comparisons(*HAND, window=window), f"window {window}")
        want = np.array(want, dtype=float)
        check_array(got, want[np.lexsort(want.T[::-1])], name=f"the comparisons (sorted) for window {window}")


@stub("ratings_to_comparisons", points=2, hint=HINT)
def test_random_sessions_match_reference(student, reference, rng):
    """Four annotators, 80 ratings of 12 segments (repeats occur), windows 1, 3 and 7"""
    ann, seg, rat = _session(rng, 80, 4, 12)
    for window in (1, 3, 7):
        got = _canonical(student.ratings_to_comparisons(ann, seg, rat, window=window), f"window {window}")
        want = _canonical(reference.ratings_to_comparisons(ann, seg, rat, window=window))
        check_array(got, want, name=f"the comparisons (sorted) for window {window}")


@stub("ratings_to_comparisons", points=1, hint="Compare each annotator's ratings only with their own, in their own order.")
def test_offsets_of_annotators_cancel(student, rng):
    """Adding a constant to every rating of one annotator changes no comparison"""
    ann, seg, rat = _session(rng, 60, 3, 500)
    base = _canonical(student.ratings_to_comparisons(ann, seg, rat, window=4))
    shifted = rat + np.array([0, 3, -2])[ann]
    check_array(_canonical(student.ratings_to_comparisons(ann, seg, shifted, window=4)), base,
                name="the comparisons after shifting annotators 1 and 2 by +3 and -2")
    # two annotators' ratings of distinct segments, interleaved: no pair may mix them
    pairs = np.asarray(student.ratings_to_comparisons(np.arange(40) % 2, np.arange(40), np.zeros(40, int), 3)[0])
    assert len(pairs) == 2 * (19 + 18 + 17), f"expected {2 * (19 + 18 + 17)} pairs, got {len(pairs)}"
    assert np.all(pairs[:, 0] % 2 == pairs[:, 1] % 2), "a pair mixes two annotators' ratings"


@stub("ratings_to_comparisons", points=1, hint="With no pair to form, return pairs of shape (0, 2) and mu of shape (0,).")
def test_short_sessions(student):
    """A window longer than every session; one rating each; no ratings at all"""
    got = _canonical(student.ratings_to_comparisons(np.array([0, 1, 0]), np.array([3, 4, 5]), np.array([2, 2, 9]),
                                                    window=10))
    check_array(got, np.array([[3.0, 5.0, 0.0]]), name="the comparisons of a window longer than the session")
    for ann in (np.array([0, 1, 2]), np.zeros(0, dtype=int)):
        pairs, mu = student.ratings_to_comparisons(ann, np.arange(len(ann)), np.ones(len(ann), dtype=int), window=2)
        assert np.shape(pairs) == (0, 2) and np.shape(mu) == (0,), \
            f"with {len(ann)} ratings by different annotators: pairs {np.shape(pairs)}, mu {np.shape(mu)}"
