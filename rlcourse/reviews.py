"""A small synthetic language of film and product reviews, its tokenizer and its gold reward.

``hw5_lm_alignment`` aligns a tiny language model on this language. Everything a real
alignment experiment hides is known here: the grammar that wrote the corpus, the hidden
sentiment of every review, and a *gold reward* that is a fixed function of the text, so that
reward models, PPO, DPO and best-of-n can all be measured against the truth.

**The grammar.** A review is ``<bos>``, an opening sentence about the item (``this film was
really great .``), one to four further sentences drawn from eight templates (an aspect and an
adjective, a verb of liking, a contrast with ``but``, a recommendation, ...), then ``<eos>``;
at most :data:`MAX_LEN` tokens in all. Each review has a hidden score ``z`` uniform on
``[-1, 1]``; every sentiment slot is positive with probability ``sigmoid(4 z)``, sometimes
intensified (``very``, ``really``, ``truly``, ``so``) and sometimes expressed by negating the
opposite word (``not bad``). Words are tokens: the tokenizer splits on spaces.

**The gold reward** of a review ``y`` (token ids, ``<bos>`` first; everything after the first
``<eos>`` is ignored) is::

    gold(y) = tanh(S(y) / 3) - 0.5 B(y) - 0.2 R(y) - 1.0 U(y)

- ``S`` (sentiment): the sum over tokens of the lexicon weight (:data:`LEXICON`: +2 for
  ``great``, +1 for ``good``, -1 for ``dull``, -2 for ``awful``; +1 for ``recommend``, ``buy``
  and ``watch``; 0 for every other word), multiplied by 1.5 when the previous token is an
  intensifier, and by -1 when the previous token is ``not``, or is an intensifier preceded
  by ``not`` (``not very good`` scores -1.5).
- ``B`` (ungrammatical): the number of adjacent token pairs, counting ``<bos>`` before the first
  word and ``<eos>`` after the last, that the grammar can never produce (:func:`grammar_bigrams`).
- ``R`` (repetition): extra occurrences of sentiment-bearing words: for each word with a
  non-zero weight, its count minus one, when positive.
- ``U`` (unfinished): 1 when the review has no ``<eos>``.

The sentiment term saturates (``tanh``), while piling up positive words, repeating them or
breaking the grammar is penalised without bound: a policy that hacks an imperfect learned
reward by repetition or gibberish gets a visibly lower gold reward.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np

PAD, BOS, EOS, UNK = "<pad>", "<bos>", "<eos>", "<unk>"
MAX_LEN = 32
"""Longest review in tokens, ``<bos>`` and ``<eos>`` included (the model's context)."""

FILM_ITEMS = ("film", "movie", "show", "series", "documentary", "sequel")
PRODUCT_ITEMS = ("phone", "laptop", "camera", "kettle", "blender", "headset", "watch", "speaker", "tablet", "printer")
FILM_ASPECTS = ("plot", "acting", "ending", "script", "music", "cast", "dialogue", "pacing", "story", "soundtrack",
                "direction", "humour", "villain", "hero", "finale", "editing", "lighting", "premise", "costumes",
                "effects", "scenery", "score", "jokes", "tone", "stunts", "casting", "opening", "sequence", "romance",
                "narrator", "animation", "runtime")
PRODUCT_ASPECTS = ("battery", "screen", "price", "design", "sound", "keyboard", "case", "charger", "lid", "handle",
                   "button", "display", "app", "motor", "cable", "strap", "lens", "manual", "speed", "memory", "fan",
                   "stand", "plug", "hinge", "grip", "blade", "filter", "microphone", "software", "warranty",
                   "packaging", "touchscreen")
COPULAS = ("is", "was")
INTENSIFIERS = ("very", "really", "truly", "so")
POSITIVE = {2: ("great", "excellent", "wonderful", "brilliant", "superb", "fantastic", "amazing", "perfect"),
            1: ("good", "nice", "fine", "solid", "decent", "pleasant", "clever", "charming", "sturdy", "smooth")}
NEGATIVE = {1: ("bad", "weak", "dull", "poor", "slow", "flimsy", "boring", "bland", "noisy", "clumsy"),
            2: ("awful", "terrible", "horrible", "dreadful", "useless", "painful", "pathetic", "atrocious")}
NEUTRAL = ("long", "short", "new", "simple", "big", "small", "heavy", "light", "modern", "old", "quiet", "loud",
           "familiar", "unusual", "dark", "bright")
VERBS = {"loved": 2.0, "enjoyed": 1.0, "liked": 1.0, "disliked": -1.0, "hated": -2.0}
NEUTRAL_VERBS = ("noticed", "expected", "remember", "tried", "studied")
ADJECTIVES = POSITIVE[2] + POSITIVE[1] + NEGATIVE[1] + NEGATIVE[2] + NEUTRAL

LEXICON: dict[str, float] = {**{w: 2.0 for w in POSITIVE[2]}, **{w: 1.0 for w in POSITIVE[1]},
                             **{w: -1.0 for w in NEGATIVE[1]}, **{w: -2.0 for w in NEGATIVE[2]},
                             **VERBS, "recommend": 1.0, "buy": 1.0, "watch": 1.0}
"""Lexicon weight of every sentiment-bearing word (all other words weigh 0)."""

SENTIMENT_SCALE = 3.0
BIGRAM_PENALTY, REPEAT_PENALTY, UNFINISHED_PENALTY = 0.5, 0.2, 1.0

ITEMS = FILM_ITEMS + PRODUCT_ITEMS
ASPECTS = FILM_ASPECTS + PRODUCT_ASPECTS
_FUNCTION = ("this", "the", "i", "it", "and", "but", "were", "would", "not", "recommend", "to", "a", "friend",
             "buy", "watch", "again", "overall", ".")
# "watch" is both a product and the verb of "watch it again": one token, listed once.
VOCAB: tuple[str, ...] = tuple(dict.fromkeys(
    (PAD, BOS, EOS, UNK) + _FUNCTION + ITEMS + ASPECTS + COPULAS + INTENSIFIERS + ADJECTIVES + tuple(VERBS)
    + NEUTRAL_VERBS))
"""Every token, in id order: ``<pad>`` is 0, ``<bos>`` 1, ``<eos>`` 2, ``<unk>`` 3."""
PAD_ID, BOS_ID, EOS_ID, UNK_ID = 0, 1, 2, 3
_INDEX = {w: i for i, w in enumerate(VOCAB)}

# ---------------------------------------------------------------------------------------------
# The grammar. A template is a list of slots; a slot is (words, optional). A slot's words may be
# a placeholder filled at sampling time: "ITEM", "ASPECT", "ADJ", "VERB".
_OPT, _REQ = True, False
_PLACEHOLDERS = {"ITEM": ITEMS, "ASPECT": ASPECTS, "ADJ": ADJECTIVES, "VERB": tuple(VERBS) + NEUTRAL_VERBS,
                 "COP": COPULAS, "INT": INTENSIFIERS}
OPENING = [(("this",), _REQ), ("ITEM", _REQ), ("COP", _REQ), (("not",), _OPT), ("INT", _OPT), ("ADJ", _REQ),
           ((".",), _REQ)]
TEMPLATES = {
    "aspect": [(("the",), _REQ), ("ASPECT", _REQ), ("COP", _REQ), (("not",), _OPT), ("INT", _OPT), ("ADJ", _REQ),
               ((".",), _REQ)],
    "verb": [(("i",), _REQ), ("INT", _OPT), ("VERB", _REQ), (("the",), _REQ), ("ASPECT", _REQ), ((".",), _REQ)],
    "contrast": [(("the",), _REQ), ("ASPECT", _REQ), ("COP", _REQ), ("ADJ", _REQ), (("but",), _REQ), (("the",), _REQ),
                 ("ASPECT", _REQ), ("COP", _REQ), ("ADJ", _REQ), ((".",), _REQ)],
    "recommend": [(("i",), _REQ), (("would",), _REQ), (("not",), _OPT), (("recommend",), _REQ), (("it",), _REQ),
                  (("to",), _REQ), (("a",), _REQ), (("friend",), _REQ), ((".",), _REQ)],
    "again": [(("i",), _REQ), (("would",), _REQ), (("not",), _OPT), (("buy", "watch"), _REQ), (("it",), _REQ),
              (("again",), _REQ), ((".",), _REQ)],
    "overall": [(("overall",), _REQ), (("it",), _REQ), ("COP", _REQ), ("INT", _OPT), ("ADJ", _REQ), ((".",), _REQ)],
    "pair": [(("the",), _REQ), ("ASPECT", _REQ), (("and",), _REQ), (("the",), _REQ), ("ASPECT", _REQ),
             (("were",), _REQ), ("INT", _OPT), ("ADJ", _REQ), ((".",), _REQ)],
}


def _words(slot_words) -> tuple[str, ...]:
    return _PLACEHOLDERS[slot_words] if isinstance(slot_words, str) else slot_words


@lru_cache(maxsize=None)
def grammar_bigrams() -> np.ndarray:
    """``allowed[a, b]`` is True when token ``b`` can follow token ``a`` in some review of the grammar.

    Exact for the templates: consecutive slots, and slots separated only by optional ones, give
    every pair of their words; ``<bos>`` precedes ``this``; ``.`` precedes every sentence start and
    ``<eos>``. Shape ``(len(VOCAB), len(VOCAB))``.
    """
    allowed = np.zeros((len(VOCAB), len(VOCAB)), dtype=bool)

    def add(firsts, seconds):
        allowed[np.ix_([_INDEX[a] for a in firsts], [_INDEX[b] for b in seconds])] = True

    for slots in [OPENING, *TEMPLATES.values()]:
        for i, (a, _) in enumerate(slots):
            for b, optional in slots[i + 1:]:
                add(_words(a), _words(b))
                if not optional:
                    break
    add([BOS], ["this"])
    add(["."], [EOS] + sorted({w for t in TEMPLATES.values() for w in _words(t[0][0])}))
    return allowed


# ---------------------------------------------------------------------------------------------
# Sampling the corpus.
def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + np.exp(-x))


def _adjective(rng: np.random.Generator, positive: bool, z: float, negation: bool = True,
               intensifier: bool = True) -> list[str]:
    """An adjective phrase ``[not] [INT] ADJ`` meaning ``positive`` (or, 12% of the time, a neutral word).

    Negation writes the meaning with the opposite word (``not bad`` for a positive slot).
    """
    if rng.random() < 0.12:
        return [str(rng.choice(NEUTRAL))]
    negate = negation and rng.random() < 0.15
    strength = 2 if rng.random() < 0.3 + 0.4 * abs(z) else 1
    word = str(rng.choice((POSITIVE if positive != negate else NEGATIVE)[strength]))
    intens = [str(rng.choice(INTENSIFIERS))] if intensifier and rng.random() < 0.3 else []
    return ["not"] * negate + intens + [word]


def _sentence(rng: np.random.Generator, kind: str, z: float, film: bool) -> list[str]:
    """One sentence of template ``kind`` (or the opening) for a review of hidden score ``z``."""
    aspects = FILM_ASPECTS if film else PRODUCT_ASPECTS
    pol = lambda: bool(rng.random() < _sigmoid(4 * z))  # noqa: E731  one sentiment slot's polarity
    cop = lambda: str(rng.choice(COPULAS))  # noqa: E731
    asp = lambda: str(rng.choice(aspects))  # noqa: E731
    if kind == "opening":
        return ["this", str(rng.choice(FILM_ITEMS if film else PRODUCT_ITEMS)), cop(), *_adjective(rng, pol(), z), "."]
    if kind == "aspect":
        return ["the", asp(), cop(), *_adjective(rng, pol(), z), "."]
    if kind == "verb":
        if rng.random() < 0.15:
            return ["i", str(rng.choice(NEUTRAL_VERBS)), "the", asp(), "."]
        sign, strong = (1 if pol() else -1), rng.random() < 0.3 + 0.4 * abs(z)
        verb = str(rng.choice([v for v, w in VERBS.items() if np.sign(w) == sign and (abs(w) == 2) == strong]))
        intens = [str(rng.choice(INTENSIFIERS))] if rng.random() < 0.2 else []
        return ["i", *intens, verb, "the", asp(), "."]
    if kind == "contrast":
        first = pol()
        a1 = _adjective(rng, first, z, negation=False, intensifier=False)
        a2 = _adjective(rng, not first, z, negation=False, intensifier=False)
        a, b = rng.choice(aspects, size=2, replace=False)
        return ["the", str(a), cop(), *a1, "but", "the", str(b), cop(), *a2, "."]
    if kind in ("recommend", "again"):
        tail = ["recommend", "it", "to", "a", "friend", "."] if kind == "recommend" else \
               ["watch" if film else "buy", "it", "again", "."]
        return ["i", "would", *([] if pol() else ["not"]), *tail]
    if kind == "overall":
        return ["overall", "it", cop(), *_adjective(rng, pol(), z, negation=False), "."]
    if kind == "pair":
        a, b = rng.choice(aspects, size=2, replace=False)
        return ["the", str(a), "and", "the", str(b), "were", *_adjective(rng, pol(), z, negation=False), "."]
    raise ValueError(f"unknown sentence kind {kind!r}")


def sample_review(rng: np.random.Generator) -> tuple[list[str], float]:
    """One review as a list of words (``<bos>`` ... ``<eos>``) and its hidden score ``z``."""
    z = float(rng.uniform(-1.0, 1.0))
    film = bool(rng.random() < 0.5)
    kinds = list(TEMPLATES)
    while True:
        n_more = int(rng.integers(1, 5))
        words = [BOS, *_sentence(rng, "opening", z, film)]
        for kind in rng.choice(kinds, size=n_more):
            words += _sentence(rng, str(kind), z, film)
        words.append(EOS)
        if len(words) <= MAX_LEN:
            return words, z


def sample_corpus(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` reviews as right-padded token ids ``(n, MAX_LEN)`` (int64) and their hidden scores ``(n,)``."""
    rng = np.random.default_rng(seed)
    tokens = np.full((n, MAX_LEN), PAD_ID, dtype=np.int64)
    scores = np.empty(n)
    for i in range(n):
        words, scores[i] = sample_review(rng)
        tokens[i, : len(words)] = encode(words)
    return tokens, scores


# ---------------------------------------------------------------------------------------------
# Tokenizer.
def encode(text: str | Sequence[str]) -> np.ndarray:
    """Token ids of a space-separated string (or a list of words); unknown words map to ``<unk>``."""
    words = text.split() if isinstance(text, str) else text
    return np.array([_INDEX.get(w, UNK_ID) for w in words], dtype=np.int64)


def decode(ids: Sequence[int] | np.ndarray, skip_special: bool = True) -> str:
    """The text of one sequence of ids, stopping at the first ``<eos>``; ``<bos>``/``<pad>`` dropped."""
    words = []
    for i in np.asarray(ids).tolist():
        if i == EOS_ID:
            if not skip_special:
                words.append(EOS)
            break
        if skip_special and i in (PAD_ID, BOS_ID):
            continue
        words.append(VOCAB[i])
    return " ".join(words)


# ---------------------------------------------------------------------------------------------
# The gold reward.
@dataclass
class GoldTerms:
    """The parts of the gold reward, one value per review: ``gold = tanh(S/3) - 0.5 B - 0.2 R - U``."""

    sentiment: np.ndarray    # S, the modified lexicon sum
    ungrammatical: np.ndarray  # B, bigrams the grammar never produces
    repeats: np.ndarray      # R, extra occurrences of sentiment words
    unfinished: np.ndarray   # U, 1.0 when there is no <eos>

    @property
    def gold(self) -> np.ndarray:
        return (np.tanh(self.sentiment / SENTIMENT_SCALE) - BIGRAM_PENALTY * self.ungrammatical
                - REPEAT_PENALTY * self.repeats - UNFINISHED_PENALTY * self.unfinished)


_WEIGHT = np.array([LEXICON.get(w, 0.0) for w in VOCAB])
_IS_INTENSIFIER = np.isin(np.arange(len(VOCAB)), [_INDEX[w] for w in INTENSIFIERS])
_NOT = _INDEX["not"]


def gold_terms(tokens: np.ndarray) -> GoldTerms:
    """The gold reward's terms for ``tokens`` ``(N, T)`` int ids, each row ``<bos>`` first.

    Tokens after a row's first ``<eos>`` (padding) are ignored.
    """
    tokens = np.atleast_2d(np.asarray(tokens, dtype=np.int64))
    n, t = tokens.shape
    is_eos = tokens == EOS_ID
    finished = is_eos.any(axis=1)
    first_eos = np.where(finished, is_eos.argmax(axis=1), t)
    pos = np.arange(t)[None, :]
    inside = pos <= first_eos[:, None]          # the review, its <eos> included
    words = inside & (pos < first_eos[:, None]) & (pos > 0)   # real words (not <bos>, not <eos>)

    prev = np.pad(tokens, ((0, 0), (1, 0)), constant_values=PAD_ID)[:, :-1]
    prev2 = np.pad(tokens, ((0, 0), (2, 0)), constant_values=PAD_ID)[:, :-2]
    factor = np.where(_IS_INTENSIFIER[prev], 1.5, 1.0)
    negated = (prev == _NOT) | (_IS_INTENSIFIER[prev] & (prev2 == _NOT))
    weights = _WEIGHT[tokens] * factor * np.where(negated, -1.0, 1.0)
    sentiment = (weights * words).sum(axis=1)

    allowed = grammar_bigrams()
    pairs_bad = ~allowed[tokens[:, :-1], tokens[:, 1:]] & inside[:, 1:]
    ungrammatical = pairs_bad.sum(axis=1).astype(float)

    counts = np.zeros((n, len(VOCAB)))
    np.add.at(counts, (np.repeat(np.arange(n), t)[words.ravel()], tokens[words]), 1.0)
    repeats = (np.maximum(counts - 1.0, 0.0) * (_WEIGHT != 0)).sum(axis=1)
    return GoldTerms(sentiment, ungrammatical, repeats, (~finished).astype(float))


def gold_reward(tokens: np.ndarray) -> np.ndarray:
    """The gold reward ``(N,)`` of reviews ``tokens`` ``(N, T)`` (see the module docstring)."""
    return gold_terms(tokens).gold


def gold_reward_text(text: str) -> float:
    """The gold reward of one review written as text (``<bos>`` is added; add ``<eos>`` yourself)."""
    return float(gold_reward(encode([BOS, *text.split()])[None])[0])


# ---------------------------------------------------------------------------------------------
# The shipped preference set (datasets/lm/preferences.npz, made by datasets/scripts/make_lm_preferences.py).
def load_preferences() -> dict[str, np.ndarray]:
    """The verified preference set: token arrays as int64, see the making script for the fields."""
    from rlcourse import data

    d = data.load_npz("lm/preferences.npz")
    for key in ("chosen", "rejected", "eval_prompts"):
        d[key] = d[key].astype(np.int64)
    d["prompt_len"], d["temperature"] = int(d["prompt_len"]), float(d["temperature"])
    return d
