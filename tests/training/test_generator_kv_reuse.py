"""actors/generator_hf.py: a conversation's KV cache is reused across its turns (HFOptions.reuse_kv_cache),
tokens are drawn by the inverse CDF at per-request uniforms, and finished rows leave the batch
(HFOptions.compact_finished_rows).

Turn t+1 of an episode is turn t's context plus the sampled turn and the tool result; with reuse the
generator encodes only those new tokens. The sampled tokens and their log-probs must be the ones a
generator without reuse returns for the same requests (same seeds), in mixed batches too.
"""

from __future__ import annotations

import pytest
import torch

from actors.generator import GenerationRequest, SamplingConfig
from actors.generator_hf import HFGenerator
from modeling.model import ENDOFTEXT, IM_END, load_tokenizer, tool_turn_text
from tests.training.learner_fixtures import tiny_model_dir

TICKETS = ["Check warfarin and aspirin.", "A 64-year-old man with chest pain.", "Creatinine clearance 45 mL/min.",
           "Answer: B. Revisit the differential."]


def _generators():
    model_dir = tiny_model_dir()
    tok = load_tokenizer(model_dir)
    stop = [tok.convert_tokens_to_ids(IM_END), tok.convert_tokens_to_ids(ENDOFTEXT)]
    sampling = SamplingConfig(temperature=0.9)
    reuse = HFGenerator(model_dir, sampling, stop, options={"reuse_kv_cache": True})
    # The reference keeps finished rows in the batch: reuse (which stores a row's keys/values when it
    # leaves a compacted batch) is checked against the plainest computation.
    plain = HFGenerator(model_dir, sampling, stop, options={"reuse_kv_cache": False, "compact_finished_rows": False})
    return tok, reuse, plain


def _prompt(tok, ticket):
    text = tok.apply_chat_template([{"role": "user", "content": ticket}], tokenize=False, add_generation_prompt=True)
    return tok.encode(text, add_special_tokens=False)


def _turns(tok, gen, turns=3, lengths=(9, 14, 6)):
    """Run the four conversations for `turns` turns; the second conversation sits out turn 2, so later
    batches mix rows with and without a cached prefix and of different cached lengths. Rows get
    different token limits, so they finish at different steps (and leave a compacting batch)."""
    contexts = {f"ep{i}": _prompt(tok, t) for i, t in enumerate(TICKETS)}
    history = []
    for turn in range(turns):
        requests = [GenerationRequest(request_id=f"{key}:t{turn}", prompt_ids=ids, max_new_tokens=lengths[turn] + 4 * i,
                                      seed=1000 * turn + i)
                    for i, (key, ids) in enumerate(contexts.items()) if not (turn == 1 and key == "ep1")]
        results = gen.generate(requests)
        history.append(results)
        for req, res in zip(requests, results):
            observation = tok.encode(tool_turn_text(f"result {turn} of {req.request_id}"), add_special_tokens=False)
            tail = ([] if res.token_ids[-1] in gen.stop_token_ids else [tok.convert_tokens_to_ids(IM_END)])
            contexts[req.request_id.rpartition(":t")[0]] = list(req.prompt_ids) + res.token_ids + tail + observation
    return history


def test_reuse_gives_the_tokens_and_logprobs_of_a_full_encode():
    tok, reuse, plain = _generators()
    with_reuse = _turns(tok, reuse)
    without = _turns(tok, plain)
    assert reuse.cache_stats["reused_requests"] == 3 + 4  # turn 2: ep0, ep2, ep3; turn 3: all four
    assert plain.cache_stats["reused_requests"] == 0
    assert reuse.cache_stats["compactions"] >= 3 and plain.cache_stats["compactions"] == 0
    # Only the new tokens were encoded: the cached prefixes were not read again.
    assert reuse.cache_stats["encoded_prompt_tokens"] + reuse.cache_stats["reused_tokens"] == \
        plain.cache_stats["encoded_prompt_tokens"]
    assert reuse.cache_stats["encoded_prompt_tokens"] < plain.cache_stats["encoded_prompt_tokens"] / 2
    for turn_a, turn_b in zip(with_reuse, without):
        for a, b in zip(turn_a, turn_b):
            assert a.request_id == b.request_id
            assert a.token_ids == b.token_ids, a.request_id
            assert a.finish_reason == b.finish_reason
            assert torch.allclose(torch.tensor(a.logprobs), torch.tensor(b.logprobs), atol=1e-4), a.request_id


def test_finished_rows_leave_the_batch_and_every_request_gets_the_same_tokens():
    """Rows finishing at very different steps: the compacting batch, the batch that keeps its
    finished rows, and each request alone give the same tokens, log-probs and finish reasons, and
    the compacting batch computes far fewer row-steps for the same live ones."""
    model_dir = tiny_model_dir()
    tok = load_tokenizer(model_dir)
    stop = [tok.convert_tokens_to_ids(IM_END), tok.convert_tokens_to_ids(ENDOFTEXT)]
    sampling = SamplingConfig(temperature=0.9)
    compact = HFGenerator(model_dir, sampling, stop)
    full = HFGenerator(model_dir, sampling, stop, options={"compact_finished_rows": False})
    assert compact.options.compact_finished_rows  # the default
    prompts = [_prompt(tok, t) for t in TICKETS]
    requests = [GenerationRequest(request_id=f"m{j}", prompt_ids=prompts[j % 4], max_new_tokens=n, seed=50 + j,
                                  greedy=j == 3)
                for j, n in enumerate([2, 40, 7, 23, 1, 31, 12, 4])]
    packed, kept = compact.generate(requests), full.generate(requests)
    cs, fs = dict(compact.cache_stats), dict(full.cache_stats)
    alone = [full.generate([r])[0] for r in requests]
    assert len({len(r.token_ids) for r in packed}) >= 6
    for a, b, c in zip(packed, kept, alone):
        assert a.token_ids == b.token_ids == c.token_ids, a.request_id
        assert a.finish_reason == b.finish_reason == c.finish_reason, a.request_id
        assert torch.allclose(torch.tensor(a.logprobs), torch.tensor(b.logprobs), atol=1e-4), a.request_id
        assert torch.allclose(torch.tensor(a.logprobs), torch.tensor(c.logprobs), atol=1e-4), a.request_id
    # Every row is fed all its sampled tokens but the last, in both batches.
    live = sum(len(r.token_ids) - 1 for r in packed)
    assert cs["live_row_steps"] == fs["live_row_steps"] == live
    assert fs["decode_row_steps"] == len(requests) * (max(len(r.token_ids) for r in packed) - 1)
    assert fs["compactions"] == 0 and 2 <= cs["compactions"] <= 8
    assert live <= cs["decode_row_steps"] < 0.6 * fs["decode_row_steps"]


def test_new_weights_or_a_changed_prefix_are_never_served_from_the_cache():
    tok, reuse, _ = _generators()
    prompt = _prompt(tok, TICKETS[0])
    first = reuse.generate([GenerationRequest(request_id="e:t0", prompt_ids=prompt, max_new_tokens=5, seed=1)])[0]
    follow = prompt + first.token_ids + tok.encode(tool_turn_text("x"), add_special_tokens=False)
    # New weights: the keys and values of the old ones are dropped.
    reuse.update_weights({k: v.clone() for k, v in reuse.model.state_dict().items()}, 1)
    reuse.generate([GenerationRequest(request_id="e:t1", prompt_ids=follow, max_new_tokens=3, seed=2)])
    assert reuse.cache_stats["reused_requests"] == 0
    # A context that does not start with the cached tokens (an edited history) is encoded in full.
    edited = [follow[0] + 1] + follow[1:]
    reuse.generate([GenerationRequest(request_id="e:t2", prompt_ids=edited, max_new_tokens=3, seed=3)])
    assert reuse.cache_stats["reused_requests"] == 0
    # Request ids outside the agent loop's `<episode>:t<turn>` naming are never cached.
    assert HFGenerator.conversation_key(GenerationRequest(request_id="free-form", prompt_ids=[1],
                                                          max_new_tokens=1, seed=0)) is None


def test_the_cache_stays_within_its_token_budget():
    model_dir = tiny_model_dir()
    tok = load_tokenizer(model_dir)
    gen = HFGenerator(model_dir, SamplingConfig(), [tok.convert_tokens_to_ids(IM_END)],
                      options={"reuse_kv_cache": True, "kv_cache_max_tokens": 60})
    prompts = [_prompt(tok, t) for t in TICKETS]
    gen.generate([GenerationRequest(request_id=f"e{i}:t0", prompt_ids=p, max_new_tokens=4, seed=i)
                  for i, p in enumerate(prompts)])
    assert 0 < gen._cached_tokens <= 60
    assert sum(len(e.token_ids) for e in gen._prefixes.values()) == gen._cached_tokens
    with pytest.raises(ValueError):
        HFGenerator(model_dir, SamplingConfig(), [0], options={"kv_cache_max_tokens": -1})


def test_sampling_follows_the_distribution_and_each_requests_seed():
    """Tokens are drawn by the inverse CDF at per-request uniforms: over many seeds the most probable
    tokens come up as often as their probability says (3 sigma), and a seed gives the same token in any
    batch. A low temperature makes the untrained model's distribution peaked enough to test."""
    from actors.generator import processed_logprobs

    model_dir = tiny_model_dir()
    tok = load_tokenizer(model_dir)
    sampling = SamplingConfig(temperature=0.05)
    gen = HFGenerator(model_dir, sampling, [tok.convert_tokens_to_ids(IM_END)])
    prompt = _prompt(tok, TICKETS[1])
    with torch.no_grad():
        probs = processed_logprobs(gen.model(torch.tensor([prompt])).logits[:, -1], sampling)[0].exp()
    n = 1200
    results = []
    for lo in range(0, n, 300):
        results += gen.generate([GenerationRequest(request_id=f"s{i}", prompt_ids=prompt, max_new_tokens=1, seed=i)
                                 for i in range(lo, lo + 300)])
    drawn = torch.tensor([r.token_ids[0] for r in results])
    top = torch.topk(probs, 3).indices.tolist()
    assert probs[top[0]] < 0.9 and probs[top[2]] > 0.03  # several tokens in play, each often drawn
    for token in top:
        p = float(probs[token])
        freq = float((drawn == token).float().mean())
        assert abs(freq - p) <= 3 * (p * (1 - p) / n) ** 0.5 + 1e-3, (token, freq, p)
    alone = gen.generate([GenerationRequest(request_id="x", prompt_ids=prompt, max_new_tokens=1, seed=7)])[0]
    assert alone.token_ids == results[7].token_ids
