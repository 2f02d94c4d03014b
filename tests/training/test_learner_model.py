"""modeling/model.py: the local tokenizer, the chat format for token-in/token-out, the tiny model, log-probs."""

from __future__ import annotations

import pytest
import torch

from modeling.model import (
    TOOL_TOKENS,
    build_tiny_model,
    load_policy,
    load_tokenizer,
    pad_batch,
    per_token_entropy,
    per_token_logprobs,
    token_stats,
    tool_turn_text,
)
from tests.training.learner_fixtures import tiny_model_dir


@pytest.fixture(scope="module")
def policy():
    return load_policy(tiny_model_dir())


def test_tokenizer_special_tokens_padding_and_roundtrip(policy):
    _, tok = policy
    assert tok.padding_side == "left"  # survives save/reload only when passed to the constructor
    assert tok.eos_token == "<|im_end|>" and tok.pad_token == "<|pad|>"
    for special in ("<|endoftext|>", "<|im_start|>", "<|im_end|>", "<|pad|>", *TOOL_TOKENS):
        ids = tok.encode(special, add_special_tokens=False)
        assert len(ids) == 1, special  # one id each, never split into bytes
    text = 'Dose: 5 mg\n<tool_call>\n{"name": "x", "arguments": {}}\n</tool_call>'
    assert tok.decode(tok.encode(text, add_special_tokens=False)) == text
    assert len(tok) == 2048


def test_tool_turn_text_matches_the_chat_template(policy):
    _, tok = policy
    convo = [
        {"role": "system", "content": "Policy text."},
        {"role": "user", "content": "Ticket: check warfarin."},
        {"role": "assistant", "content": "", "tool_calls": [{"function": {"name": "lookup", "arguments": {"drug": "warfarin"}}}]},
    ]
    prefix = tok.apply_chat_template(convo, tokenize=False)
    full = tok.apply_chat_template(convo + [{"role": "tool", "content": "INR 3.1"}], tokenize=False,
                                   add_generation_prompt=True)
    # The generator stops right after <|im_end|>; the template's closing "\n" belongs to tool_turn_text.
    assert prefix.endswith("</tool_call><|im_end|>\n")
    assert full == prefix[:-1] + tool_turn_text("INR 3.1")
    # Token-level: appending the tokenized tool turn reproduces the re-rendered ids exactly.
    ids_prefix = tok.encode(prefix[:-1], add_special_tokens=False)
    ids_full = tok.encode(full, add_special_tokens=False)
    assert ids_prefix + tok.encode(tool_turn_text("INR 3.1"), add_special_tokens=False) == ids_full
    enc = tok.apply_chat_template(convo[:2], tokenize=True, add_generation_prompt=True)
    ids = enc["input_ids"] if hasattr(enc, "keys") else enc
    assert tok.decode(ids).endswith("<|im_start|>assistant\n")


def test_build_tiny_model_defaults_overrides_and_errors(tmp_path):
    tok_dir = tiny_model_dir()  # has a tokenizer next to the model
    out = build_tiny_model(tmp_path / "m", tok_dir, hidden_size=32, intermediate_size=64, num_attention_heads=2,
                           num_key_value_heads=1, head_dim=16)
    model, tok = load_policy(out)
    assert model.config.hidden_size == 32 and model.config.vocab_size == len(tok)
    assert (out / "model.safetensors").exists()
    again = build_tiny_model(tmp_path / "m2", tok_dir, hidden_size=32, intermediate_size=64, num_attention_heads=2,
                             num_key_value_heads=1, head_dim=16)
    m2, _ = load_policy(again)
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), m2.state_dict().values()))
    with pytest.raises(ValueError, match="hiden_size"):
        build_tiny_model(tmp_path / "bad", tok_dir, hiden_size=32)
    with pytest.raises(ValueError, match="architecture"):
        build_tiny_model(tmp_path / "bad", tok_dir, architecture="gpt2")
    with pytest.raises(FileNotFoundError):
        load_tokenizer(tmp_path / "nothing")


def test_per_token_logprobs_match_a_manual_forward_and_ignore_padding(policy):
    model, tok = policy
    seqs = [[5, 17, 99, 300, 42, 7], [8, 9, 10]]
    ids, mask = pad_batch(seqs, tok.pad_token_id, side="right")
    lp = per_token_logprobs(model, ids, mask)
    assert lp.shape == ids.shape and lp.dtype == torch.float32
    with torch.no_grad():
        logits = model(torch.tensor([seqs[0]])).logits[0]
    manual = torch.log_softmax(logits[:-1], -1).gather(-1, torch.tensor(seqs[0][1:]).unsqueeze(-1)).squeeze(-1)
    assert lp[0, 0].item() == 0.0
    assert torch.allclose(lp[0, 1:], manual, atol=1e-5)
    # Left padding gives the same values at the same tokens; padding positions hold 0.
    ids_l, mask_l = pad_batch(seqs, tok.pad_token_id, side="left")
    lp_l = per_token_logprobs(model, ids_l, mask_l)
    assert torch.allclose(lp_l[1, 3:], lp[1, :3], atol=1e-5) and lp[1, 3:].abs().sum() == 0
    # Temperature divides the logits.
    hot = per_token_logprobs(model, ids, mask, temperature=2.0)
    manual_hot = torch.log_softmax(logits[:-1] / 2.0, -1).gather(-1, torch.tensor(seqs[0][1:]).unsqueeze(-1)).squeeze(-1)
    assert torch.allclose(hot[0, 1:], manual_hot, atol=1e-5)


def test_entropy_topk_gather_and_chunking_agree(policy):
    model, tok = policy
    ids, mask = pad_batch([[5, 17, 99, 300, 42, 7, 11, 12]], tok.pad_token_id)
    with torch.no_grad():
        probs = torch.softmax(model(ids).logits[0, :-1], -1)
    ent = per_token_entropy(model, ids, mask)
    assert torch.allclose(ent[0, 1:], -(probs * probs.log()).sum(-1), atol=1e-4)
    gather = torch.tensor([[[1, 2, 3]] * 8])
    a = token_stats(model, ids, mask, topk=4, gather_ids=gather, chunk_size=3)
    b = token_stats(model, ids, mask, topk=4, gather_ids=gather, chunk_size=1024)
    for x, y in ((a.logprobs, b.logprobs), (a.topk_logprobs, b.topk_logprobs), (a.gathered, b.gathered)):
        assert torch.allclose(x, y, atol=1e-5)
    assert torch.equal(a.topk_ids, b.topk_ids)
    assert torch.allclose(a.gathered[0, 1:], probs.log()[:, [1, 2, 3]], atol=1e-4)
    with pytest.raises(ValueError, match="attention_mask"):
        token_stats(model, ids, mask[:, :3])


def test_sliced_stats_equal_the_full_pass_at_the_trained_positions(policy):
    """`positions` (the loss mask) runs the LM head only there: every statistic equals the full
    pass's at those positions, is 0 elsewhere, and gradients flow only through them."""
    model, tok = policy
    seqs = [[5, 17, 99, 300, 42, 7, 11, 12, 13], [8, 9, 10, 61, 62]]
    for side in ("right", "left"):
        ids, mask = pad_batch(seqs, tok.pad_token_id, side=side)
        B, T = ids.shape
        # Trained tokens of a multi-turn layout: two "turns", a prompt and a tool result between; one
        # position on padding and position 0, which have no prediction and must stay 0.
        wanted = torch.zeros((B, T), dtype=torch.bool)
        real = [torch.nonzero(mask[b]).flatten().tolist() for b in range(B)]
        for b, cols in enumerate(real):
            for j in (3, 4, 7, 8):
                if j < len(cols):
                    wanted[b, cols[j]] = True
        wanted[0, 0] = True
        if side == "left":
            wanted[1, 0] = True  # padding
        gather = torch.randint(0, len(tok), (B, T, 3), generator=torch.Generator().manual_seed(0))
        full = token_stats(model, ids, mask, temperature=0.7, with_entropy=True, gather_ids=gather, topk=4)
        sliced = token_stats(model, ids, mask, temperature=0.7, with_entropy=True, gather_ids=gather, topk=4,
                             positions=wanted, chunk_size=3)
        keep = wanted & (full.logprobs != 0)  # the full pass's 0 = no prediction (position 0, padding)
        assert keep.sum() == 6  # real tokens 3, 4, 7, 8 of the first row; 3, 4 of the second
        for name in ("logprobs", "entropy", "gathered", "topk_logprobs"):
            a, b = getattr(full, name), getattr(sliced, name)
            assert a.shape == b.shape, name
            assert torch.allclose(a[keep], b[keep], atol=1e-5), name
            assert b[~keep].abs().sum() == 0, name
        assert torch.equal(full.topk_ids[keep], sliced.topk_ids[keep])
        # Gradients: the same at the trained positions' loss, none from elsewhere.
        model.zero_grad()
        token_stats(model, ids, mask, positions=wanted).logprobs.sum().backward()
        g_sliced = model.lm_head.weight.grad.clone()
        model.zero_grad()
        (token_stats(model, ids, mask).logprobs * keep).sum().backward()
        assert torch.allclose(g_sliced, model.lm_head.weight.grad, atol=1e-5)
        model.zero_grad()
    with pytest.raises(ValueError, match="positions"):
        token_stats(model, ids, mask, positions=wanted[:, :2])
