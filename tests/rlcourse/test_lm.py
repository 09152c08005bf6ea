"""The tiny transformer of hw5 (rlcourse.lm): causality, generation, scalar heads, saving."""
import torch

from rlcourse import reviews
from rlcourse.lm import LMConfig, ScalarHeadLM, TinyLM, completion_mask, generate, load_lm, save_lm

CFG = LMConfig(vocab_size=20, context=12, n_layer=2, n_head=2, d_model=16)


def model(seed: int = 0) -> TinyLM:
    torch.manual_seed(seed)
    return TinyLM(CFG).eval()


def test_logits_are_causal():
    m, x = model(), torch.randint(3, 20, (3, 12))
    y = x.clone()
    y[:, 7:] = torch.randint(3, 20, (3, 5))
    with torch.no_grad():
        a, b = m(x), m(y)
    assert a.shape == (3, 12, 20)
    assert torch.allclose(a[:, :7], b[:, :7], atol=1e-6), "a later token changed an earlier position's logits"
    assert not torch.allclose(a[:, 7:], b[:, 7:])


def test_too_long_input_is_refused():
    try:
        model()(torch.zeros(1, 13, dtype=torch.long))
    except ValueError as err:
        assert "context" in str(err)
    else:
        raise AssertionError("a sequence longer than the context should raise")


def test_generate_keeps_prompt_pads_after_eos_and_is_seeded():
    m = model()
    prompts = torch.tensor([[1, 5, 6], [1, 7, 8]])
    out = generate(m, prompts, max_new_tokens=9, generator=torch.Generator().manual_seed(1))
    again = generate(m, prompts, max_new_tokens=9, generator=torch.Generator().manual_seed(1))
    assert out.shape == (2, 12) and torch.equal(out, again) and torch.equal(out[:, :3], prompts)
    for row in out:
        eos = (row == 2).nonzero()
        if len(eos):
            assert (row[int(eos[0]) + 1:] == 0).all(), "everything after <eos> must be padding"
    greedy = generate(m, prompts, 9, temperature=1e-6)
    with torch.no_grad():
        first = m(prompts)[:, -1].argmax(-1)
    assert torch.equal(greedy[:, 3], first), "temperature -> 0 should be greedy"


def test_generate_pads_to_full_length_when_all_rows_finish_early():
    m = model()
    with torch.no_grad():
        m.tok_emb.weight[2] += 50.0 * m.ln_f.weight.sign()   # make <eos> overwhelmingly likely
        m.ln_f.bias.zero_()
    out = generate(m, torch.tensor([[1, 5]]), max_new_tokens=6)
    assert out.shape == (1, 8)


def test_completion_mask_and_scalar_head():
    tokens = torch.tensor([[1, 5, 6, 7, 2, 0, 0], [1, 5, 8, 9, 10, 11, 2]])
    mask = completion_mask(tokens, prompt_len=2)
    assert mask.tolist() == [[0, 0, 1, 1, 1, 0, 0], [0, 0, 1, 1, 1, 1, 1]]
    rm = ScalarHeadLM(model())
    torch.nn.init.normal_(rm.head.weight)
    per_token = rm(tokens)
    assert per_token.shape == (2, 7)
    assert torch.allclose(rm.score(tokens), torch.stack([per_token[0, 4], per_token[1, 6]]))


def test_save_load_round_trip(tmp_path):
    m = model(3)
    save_lm(m, tmp_path / "m.pt", note="x")
    back = load_lm(tmp_path / "m.pt")
    x = torch.randint(0, 20, (2, 12))
    with torch.no_grad():
        assert torch.equal(m(x), back(x))
    assert back.metadata == {"note": "x"} and not back.training


def test_default_config_fits_the_review_language():
    cfg = LMConfig()
    assert cfg.vocab_size == len(reviews.VOCAB) and cfg.context == reviews.MAX_LEN
    assert 100_000 < TinyLM(cfg).n_params() < 1_000_000
