"""The TITO agent loop and the hf generator, in-process on the ward test domain."""

from __future__ import annotations

import asyncio
import math

import pytest
import torch

from actors.agent_loop import (AgentLoop, EpisodeSpec, GoldReplayPolicy, LocalEnv, PromptTooLongError, RolloutLimits,
                               gold_turn_actions)
from actors.generator import GenerationRequest, GeneratorService, SamplingConfig, make_generator, processed_logprobs
from actors.generator_hf import HFGenerator


def run(coro):
    return asyncio.run(coro)


@pytest.fixture(scope="module")
def tokenizer(ward_policy_dir):
    from modeling.model import load_tokenizer

    return load_tokenizer(ward_policy_dir)


@pytest.fixture(scope="module")
def stop_ids(tokenizer):
    from modeling.model import ENDOFTEXT, IM_END

    return [tokenizer.convert_tokens_to_ids(IM_END), tokenizer.convert_tokens_to_ids(ENDOFTEXT)]


@pytest.fixture(scope="module")
def hf(ward_policy_dir, stop_ids):
    return HFGenerator(ward_policy_dir, SamplingConfig(), stop_ids)


def ward_task(task_id: str):
    from envs import registry

    return {t.id: t for t in registry.get_tasks("ward", None)}[task_id]


def spec(task_id="ward_dose", seed=7, **kw) -> EpisodeSpec:
    return EpisodeSpec(sample_id=f"{task_id}:0:{seed}", task_id=task_id, domain="ward", group_id=f"g:{task_id}",
                       seed=seed, **kw)


class RecordingEnv(LocalEnv):
    """A LocalEnv that remembers what each step returned (to rebuild the expected ids)."""

    def __init__(self, max_turns):
        super().__init__(max_turns)
        self.steps = []

    async def step(self, action):
        out = await super().step(action)
        self.steps.append(out)
        return out


def recording(generate):
    calls = []

    async def wrapped(request):
        result = await generate(request)
        calls.append((list(request.prompt_ids), result))
        return result

    return wrapped, calls


def hf_generate(gen):
    async def generate(request):
        return gen.generate([request])[0]

    return generate


def test_next_turn_ids_are_previous_ids_plus_generated_plus_observation(tokenizer, hf):
    limits = RolloutLimits(max_turns=4, max_new_tokens_per_turn=10, max_response_tokens=2000)
    loop = AgentLoop(tokenizer, limits)
    env = RecordingEnv(limits.max_turns)
    generate, calls = recording(hf_generate(hf))
    sample = run(loop.run(spec(), env, generate))

    assert len(calls) == len(sample.turns) >= 2
    im_end = loop.im_end_id
    for k in range(len(calls) - 1):
        prev_ids, result = calls[k]
        observation, _, _, _, info = env.steps[k]
        closing = [im_end] if result.token_ids[-1] != im_end else []
        expected = prev_ids + result.token_ids + closing + loop.observation_ids(observation, bool(info["tool_calls"]))
        assert calls[k + 1][0] == expected, f"turn {k + 1} input ids are not previous + generated + observation"
    last_prompt, last = calls[-1]
    assert sample.input_ids[: len(last_prompt) + len(last.token_ids)] == last_prompt + last.token_ids
    # The prompt is the chat template rendered once.
    assert sample.input_ids[: sample.prompt_length] == calls[0][0]


def test_loss_mask_spans_and_logprobs_line_up(tokenizer, hf):
    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=3, max_new_tokens_per_turn=12))
    generate, calls = recording(hf_generate(hf))
    sample = run(loop.run(spec(seed=11), RecordingEnv(3), generate))
    generated = set()
    for span, (_, result) in zip(sample.turns, calls):
        assert sample.input_ids[span.start:span.end] == result.token_ids
        assert sample.sampling_logprobs[span.start:span.end] == result.logprobs
        assert span.truncated == (result.finish_reason == "length")
        generated.update(range(span.start, span.end))
    for p, m in enumerate(sample.loss_mask):
        assert m == (1 if p in generated else 0), f"loss mask wrong at position {p}"
        assert (sample.policy_versions[p] >= 0) == bool(m)
        if not m:
            assert sample.sampling_logprobs[p] == 0.0
    assert sample.response_tokens == len(generated)


def test_sampling_logprobs_are_the_models_own(tokenizer, hf, ward_policy_dir):
    """With top_p = 1 the generator's log-probs must equal the learner's per-token log-probs."""
    from modeling.model import load_policy, per_token_logprobs

    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=2, max_new_tokens_per_turn=16))
    sample = run(loop.run(spec(seed=3), LocalEnv(2), hf_generate(hf)))
    model, _ = load_policy(ward_policy_dir)
    ids = torch.tensor([sample.input_ids])
    with torch.no_grad():
        learner_lp = per_token_logprobs(model, ids, torch.ones_like(ids))[0]
    positions = [p for p, m in enumerate(sample.loss_mask) if m]
    diffs = [abs(learner_lp[p].item() - sample.sampling_logprobs[p]) for p in positions]
    assert max(diffs) < 1e-4, f"generator and learner log-probs differ by {max(diffs)}"


def test_text_equals_the_chat_template_rendering(tokenizer):
    """Gold replay through TITO decodes to exactly what the chat template renders for the transcript."""
    task = ward_task("ward_dose")
    limits = RolloutLimits(max_turns=5)
    loop = AgentLoop(tokenizer, limits)
    env = RecordingEnv(limits.max_turns)
    policy = GoldReplayPolicy(tokenizer, {task.id: gold_turn_actions(task, limits.max_turns)})
    sample = run(loop.run(spec(task.id, seed=1), env, policy))
    assert sample.correct, sample.reward_components
    info = env.env.unwrapped
    messages = [{"role": "system", "content": info.trajectory().system_prompt},
                {"role": "user", "content": info.trajectory().messages[1]["content"]}]
    for action, (obs, _, term, trunc, step_info) in zip(gold_turn_actions(task, limits.max_turns), env.steps):
        messages.append({"role": "assistant", "content": action})
        if not (term or trunc):
            messages.append({"role": "tool" if step_info["tool_calls"] else "user", "content": obs})
    rendered = tokenizer.apply_chat_template(messages, tokenize=False)
    assert tokenizer.decode(sample.input_ids) + "\n" == rendered


def test_turn_token_limit_closes_the_turn_without_training_on_it(tokenizer, hf):
    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=3, max_new_tokens_per_turn=4))
    generate, calls = recording(hf_generate(hf))
    sample = run(loop.run(spec(seed=5), RecordingEnv(3), generate))
    cut = [(span, result) for span, (_, result) in zip(sample.turns, calls) if result.finish_reason == "length"]
    assert cut, "a 4-token limit should cut at least one turn of a random model"
    for span, _ in cut:
        assert span.truncated and span.end - span.start == 4
        if span.end < len(sample.input_ids):  # not the final turn: <|im_end|> closes it, untrained
            assert sample.input_ids[span.end] == loop.im_end_id and sample.loss_mask[span.end] == 0
    assert sample.truncated  # a random model never submits: it runs out of turns
    assert sample.metadata["truncation"] == "max_turns" and sample.metadata["end_reason"] == "turn_limit"


def test_response_budget_truncates_the_episode(tokenizer, hf):
    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=5, max_new_tokens_per_turn=8, max_response_tokens=30))
    sample = run(loop.run(spec(seed=9), LocalEnv(5), hf_generate(hf)))
    assert sample.truncated and sample.metadata["truncation"] == "response_tokens"
    assert sample.metadata["end_reason"] == "token_limit"
    assert len(sample.input_ids) - sample.prompt_length <= 30
    assert "accuracy" in sample.reward_components  # scored by the env's grader despite the early stop


def test_turn_limit_and_prompt_limit(tokenizer, hf):
    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=2, max_new_tokens_per_turn=6))
    sample = run(loop.run(spec(seed=2), LocalEnv(2), hf_generate(hf)))
    assert len(sample.turns) <= 2
    short = AgentLoop(tokenizer, RolloutLimits(max_prompt_tokens=16))
    with pytest.raises(PromptTooLongError, match="max_prompt_tokens=16"):
        run(short.run(spec(), LocalEnv(2), hf_generate(hf)))


def test_same_seed_same_tokens_whatever_the_batch(hf, tokenizer):
    ids = tokenizer.encode("<|im_start|>user\nWhich patient?<|im_end|>\n<|im_start|>assistant\n",
                           add_special_tokens=False)
    alone = hf.generate([GenerationRequest(request_id="a", prompt_ids=ids, max_new_tokens=12, seed=42)])[0]
    batch = hf.generate([
        GenerationRequest(request_id="x", prompt_ids=ids[:5] + ids, max_new_tokens=20, seed=1),
        GenerationRequest(request_id="a", prompt_ids=ids, max_new_tokens=12, seed=42),
        GenerationRequest(request_id="y", prompt_ids=ids[3:], max_new_tokens=3, seed=2),
    ])
    assert batch[1].token_ids == alone.token_ids
    assert max(abs(a - b) for a, b in zip(batch[1].logprobs, alone.logprobs)) < 1e-4
    other = hf.generate([GenerationRequest(request_id="b", prompt_ids=ids, max_new_tokens=12, seed=43)])[0]
    assert other.token_ids != alone.token_ids


def test_top_p_samples_inside_the_nucleus_and_renormalises():
    torch.manual_seed(0)
    logits = torch.randn(3, 50) * 3
    sampling = SamplingConfig(temperature=0.8, top_p=0.6)
    logp = processed_logprobs(logits, sampling)
    probs = logp.exp()
    assert torch.allclose(probs.sum(-1), torch.ones(3), atol=1e-5)
    full = torch.softmax(logits / 0.8, -1)
    for row in range(3):
        kept = torch.isfinite(logp[row])
        order = torch.argsort(full[row], descending=True)
        n = int(kept.sum())
        assert set(order[:n].tolist()) == set(torch.nonzero(kept).flatten().tolist())  # the most likely ones
        assert full[row][order[: n - 1]].sum() < 0.6 <= full[row][order[:n]].sum() + 1e-6
        # Renormalised inside the nucleus: log-prob = log(p / nucleus mass).
        mass = full[row][kept].sum()
        assert torch.allclose(logp[row][kept], torch.log(full[row][kept] / mass), atol=1e-5)


def test_greedy_requests_take_the_argmax(hf, tokenizer):
    ids = tokenizer.encode("<|im_start|>user\nDose?<|im_end|>\n<|im_start|>assistant\n", add_special_tokens=False)
    a = hf.generate([GenerationRequest(request_id="a", prompt_ids=ids, max_new_tokens=6, seed=1, greedy=True)])[0]
    b = hf.generate([GenerationRequest(request_id="b", prompt_ids=ids, max_new_tokens=6, seed=2, greedy=True)])[0]
    assert a.token_ids == b.token_ids
    assert all(lp <= 0 and not math.isnan(lp) for lp in a.logprobs)


def test_service_batches_concurrent_requests(ward_policy_dir, stop_ids, tokenizer):
    service = GeneratorService("hf", ward_policy_dir, SamplingConfig(), stop_ids, max_batch_size=8, batch_wait_s=0.05)
    ids = tokenizer.encode("<|im_start|>user\nPatient P1?<|im_end|>\n<|im_start|>assistant\n", add_special_tokens=False)
    requests = [GenerationRequest(request_id=str(i), prompt_ids=ids, max_new_tokens=5, seed=i) for i in range(6)]

    async def go():
        return await asyncio.gather(*[service.generate(r) for r in requests])

    results = run(go())
    assert [r.request_id for r in results] == [str(i) for i in range(6)]
    assert service.stats["batches"] < 6 and service.stats["requests"] == 6
    solo = service.generator.generate([requests[3]])[0]
    assert solo.token_ids == results[3].token_ids


def test_stale_generator_refuses_and_weights_update(ward_policy_dir, stop_ids, tokenizer):
    from actors.generator import GeneratorBehindError

    gen = make_generator("hf", ward_policy_dir, SamplingConfig(), stop_ids)
    ids = tokenizer.encode("<|im_start|>assistant\n", add_special_tokens=False)
    request = GenerationRequest(request_id="r", prompt_ids=ids, max_new_tokens=3, seed=0, min_version=2)
    with pytest.raises(GeneratorBehindError, match="version 0"):
        gen.generate([request])
    state = {k: v.clone() + 0.01 for k, v in gen.model.state_dict().items()}
    gen.update_weights(state, 2)
    out = gen.generate([request])[0]
    assert out.policy_version == 2
    assert torch.equal(gen.model.state_dict()["lm_head.weight"], state["lm_head.weight"])
    with pytest.raises(ValueError, match="unexpected"):
        gen.update_weights({**state, "bogus.weight": torch.zeros(1)}, 3)
    with pytest.raises(ValueError, match="unknown"):
        make_generator("nope", ward_policy_dir, SamplingConfig(), stop_ids)


def test_the_sample_carries_the_envs_episode_record_through_parquet(tokenizer, hf, tmp_path):
    """What `hcgym view` shows of a training episode is the env's own record: its turns are the
    actions the agent loop sent, its observations what the env answered, and it survives Parquet."""
    from learner.metrics import read_samples, write_samples

    loop = AgentLoop(tokenizer, RolloutLimits(max_turns=3, max_new_tokens_per_turn=12))
    env = RecordingEnv(3)
    sample = run(loop.run(spec(seed=5), env, hf_generate(hf)))
    record = sample.episode
    assert record is not None and record.task_id == "ward_dose" and record.system_prompt == ""
    assert [t.action for t in record.turns] == [loop.action_text(sample.input_ids[s.start:s.end]) for s in sample.turns]
    assert [t.observation for t in record.turns] == [step[0] for step in env.steps]
    assert record.reward == pytest.approx(sample.reward)
    again = run(loop.run(spec(seed=5), RecordingEnv(3), hf_generate(hf)))
    assert again.episode == record, "the record of a re-run episode differs (durations must stay out)"
    back, _ = read_samples(write_samples([sample], tmp_path / "s.parquet", step=1))
    assert back[0].episode == record
