"""The review grammar, its tokenizer and the documented gold reward (rlcourse.reviews)."""
import numpy as np
import pytest

from rlcourse import reviews as R


def review(text: str) -> np.ndarray:
    return R.encode([R.BOS, *text.split(), R.EOS])[None]


def test_vocabulary_ids_and_round_trip():
    assert R.VOCAB[:4] == (R.PAD, R.BOS, R.EOS, R.UNK) and len(set(R.VOCAB)) == len(R.VOCAB)
    assert 150 <= len(R.VOCAB) <= 300
    text = "this film was really great . i would recommend it to a friend ."
    ids = R.encode([R.BOS, *text.split(), R.EOS, R.PAD, R.PAD])
    assert R.decode(ids) == text
    assert R.encode("zebra")[0] == R.UNK_ID


def test_corpus_is_grammatical_finished_and_fits_the_context():
    tokens, z = R.sample_corpus(2000, seed=3)
    terms = R.gold_terms(tokens)
    assert tokens.shape == (2000, R.MAX_LEN) and tokens.dtype == np.int64
    assert (tokens[:, 0] == R.BOS_ID).all()
    assert terms.ungrammatical.max() == 0, "the grammar's own reviews must pass its bigram check"
    assert terms.unfinished.max() == 0
    assert np.corrcoef(terms.gold, z)[0, 1] > 0.6, "the gold reward should track the hidden sentiment"
    again, _ = R.sample_corpus(50, seed=3)
    assert (again == tokens[:50]).all(), "the corpus is a function of its seed"


@pytest.mark.parametrize("text, sentiment", [
    ("this film was great .", 2.0),
    ("this film was very great .", 3.0),
    ("this film was not good .", -1.0),
    ("this film was not very good .", -1.5),
    ("this phone is awful . i would not recommend it to a friend .", -3.0),
    ("this phone is new . i loved the battery .", 2.0),
])
def test_sentiment_rules_by_hand(text, sentiment):
    terms = R.gold_terms(review(text))
    assert terms.sentiment[0] == pytest.approx(sentiment)
    assert terms.ungrammatical[0] == 0 and terms.repeats[0] == 0 and terms.unfinished[0] == 0
    assert R.gold_reward(review(text))[0] == pytest.approx(np.tanh(sentiment / 3))


def test_penalties_by_hand():
    hack = R.gold_terms(review("great great great ."))
    # (<bos>, great) and (great, great) twice are bad; (great, .) and (., <eos>) are fine; "great" repeats twice.
    assert hack.ungrammatical[0] == 3 and hack.repeats[0] == 2
    assert hack.gold[0] == pytest.approx(np.tanh(6 / 3) - 0.5 * 3 - 0.2 * 2)
    unfinished = R.encode([R.BOS, "this", "film", "was", "good"])[None]
    assert R.gold_terms(unfinished).unfinished[0] == 1
    assert R.gold_reward(unfinished)[0] == pytest.approx(np.tanh(1 / 3) - 1.0)


def test_padding_after_eos_is_ignored():
    base = review("this film was good .")
    padded = np.concatenate([base, np.full((1, 5), R.PAD_ID)], axis=1)
    junk = padded.copy()
    junk[0, base.shape[1]:] = R.encode("great great great great great")
    assert R.gold_reward(padded)[0] == R.gold_reward(base)[0] == R.gold_reward(junk)[0]


def test_bigram_table_rejects_what_the_grammar_never_writes():
    allowed, i = R.grammar_bigrams(), {w: k for k, w in enumerate(R.VOCAB)}
    assert allowed[i["was"], i["not"]] and allowed[i["not"], i["very"]] and allowed[i["."], R.EOS_ID]
    assert not allowed[i["great"], i["great"]] and not allowed[i["the"], i["."]]
    assert not allowed[R.BOS_ID, i["the"]], "every review opens with 'this'"
