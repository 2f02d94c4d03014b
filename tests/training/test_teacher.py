"""The EMA teacher: hint contexts, token-by-token alignment, EMA / hard copy, asynchronous service."""

from __future__ import annotations

import random

import pytest
import torch

from actors.teacher import GENERATION_PROMPT, Teacher
from modeling.config_models import TeacherConfig, teacher_update_action
from modeling.model import load_policy, per_token_logprobs, token_stats
from tests.training.learner_fixtures import make_batch, make_sample, tiny_model_dir


@pytest.fixture(scope="module")
def model_dir():
    return tiny_model_dir()


@pytest.fixture(scope="module")
def teacher(model_dir):
    t = Teacher(TeacherConfig(enabled=True, serve_topk=3, batch_size=2), model_dir)
    yield t
    t.shutdown()


def _chat_sample(tok, rng, *, correct, turn_lens, sample_id):
    """A sample whose prompt ends with the ChatML generation header, as the agent loop renders it."""
    prompt = tok.apply_chat_template([{"role": "user", "content": "Which drug interacts with warfarin?"}],
                                     tokenize=False, add_generation_prompt=True)
    prompt_ids = tok.encode(prompt, add_special_tokens=False)
    s = make_sample(rng, group_id="g", index=0, prompt_len=len(prompt_ids), turn_lens=turn_lens, correct=correct)
    ids = prompt_ids + s.input_ids[len(prompt_ids):]
    return s.model_copy(update={"input_ids": ids, "sample_id": sample_id})


def test_hint_goes_before_the_generation_header(teacher):
    tok = teacher.tokenizer
    rng = random.Random(0)
    s = _chat_sample(tok, rng, correct=True, turn_lens=[4, 3], sample_id="a")
    ctx = teacher.build_context(s)
    header = tok.encode(GENERATION_PROMPT, add_special_tokens=False)
    hint_ids = tok.encode(teacher.config.hints.template.format(hint=teacher.config.hints.reinforcing),
                          add_special_tokens=False)
    assert ctx.hint == "reinforcing" and ctx.hint_tokens == len(hint_ids) > 0
    assert ctx.insert_at == s.prompt_length - len(header)
    assert ctx.input_ids == s.input_ids[: ctx.insert_at] + hint_ids + s.input_ids[ctx.insert_at:]
    text = tok.decode(ctx.input_ids[: s.prompt_length + len(hint_ids)])
    assert text.endswith(teacher.config.hints.reinforcing + "<|im_end|>\n<|im_start|>assistant\n")
    # Incorrect -> corrective; a prompt without the header -> inserted exactly at prompt_length.
    bad = s.model_copy(update={"correct": False})
    assert teacher.build_context(bad).hint == "corrective"
    plain = make_sample(rng, group_id="g", index=1, prompt_len=7, turn_lens=[3])
    assert teacher.build_context(plain).insert_at == 7


def test_correctness_rule_and_disabled_hints(model_dir):
    rng = random.Random(1)
    s = make_sample(rng, group_id="g", index=0, prompt_len=5, turn_lens=[3], reward=0.4, correct=False)
    by_reward = Teacher(TeacherConfig(hints={"correctness_rule": "reward_above", "reward_threshold": 0.0}),
                        model_dir, start_worker=False)
    assert by_reward.hint_kind(s) == "reinforcing"  # the reference's rule: reward > 0 counts as correct
    assert by_reward.hint_kind(s.model_copy(update={"reward": 0.0})) == "corrective"
    no_hints = Teacher(TeacherConfig(hints={"enabled": False}), model_dir, start_worker=False)
    ctx = no_hints.build_context(s)
    assert ctx.hint == "none" and ctx.input_ids == s.input_ids
    with pytest.raises(ValueError, match="hint"):
        TeacherConfig(hints={"template": "no placeholder"})


def test_teacher_logprobs_align_token_by_token_with_unequal_lengths(teacher, model_dir):
    # Unequal lengths in one teacher batch: the reference's (sequence, candidates) layout crashed here.
    batch = make_batch(seed=3, groups=2, group_size=3)
    assert len({len(s.input_ids) for s in batch}) > 1
    outs = teacher.compute(batch)
    model, _ = load_policy(model_dir)
    for s, out in zip(batch, outs):
        assert out.sample_id == s.sample_id and out.input_length == len(s.input_ids) == len(out.logprobs)
        ctx = teacher.build_context(s)
        shift = ctx.hint_tokens
        ids = torch.tensor([ctx.input_ids])
        with torch.no_grad():
            stats = token_stats(model, ids, torch.ones_like(ids), topk=3)
        for p, m in enumerate(s.loss_mask):
            if not m:
                assert out.logprobs[p] == 0.0 and out.topk_ids[p] == [] and out.topk_logprobs[p] == []
                continue
            # The same token on both sides, and the teacher's value is the unpadded forward's value.
            assert ctx.input_ids[p + shift] == s.input_ids[p]
            assert out.logprobs[p] == pytest.approx(float(stats.logprobs[0, p + shift]), abs=1e-5)
            assert len(out.topk_ids[p]) == 3 and out.topk_ids[p] == stats.topk_ids[0, p + shift].tolist()
            assert out.topk_logprobs[p] == pytest.approx(stats.topk_logprobs[0, p + shift].tolist(), abs=1e-5)
        # Hint tokens are excluded: no output position refers to the hint.
        assert sum(1 for v in out.logprobs if v != 0.0) == sum(s.loss_mask)


def test_the_hint_changes_the_teacher_logprobs(model_dir):
    rng = random.Random(5)
    s = make_sample(rng, group_id="g", index=0, prompt_len=8, turn_lens=[6, 4], correct=True)
    with_hints = Teacher(TeacherConfig(), model_dir, start_worker=False)
    without = Teacher(TeacherConfig(hints={"enabled": False}), model_dir, start_worker=False)
    reinforcing = with_hints.compute([s])[0]
    corrective = with_hints.compute([s.model_copy(update={"correct": False})])[0]
    plain = without.compute([s])[0]
    positions = [p for p, m in enumerate(s.loss_mask) if m]
    diff_rc = max(abs(reinforcing.logprobs[p] - corrective.logprobs[p]) for p in positions)
    diff_rn = max(abs(reinforcing.logprobs[p] - plain.logprobs[p]) for p in positions)
    assert reinforcing.hint == "reinforcing" and corrective.hint == "corrective" and plain.hint == "none"
    assert diff_rc > 1e-4 and diff_rn > 1e-4
    # Without a hint the teacher (= initial student) reproduces the student's own log-probs.
    model, _ = load_policy(model_dir)
    ids = torch.tensor([s.input_ids])
    with torch.no_grad():
        student = per_token_logprobs(model, ids, torch.ones_like(ids))[0]
    assert max(abs(plain.logprobs[p] - float(student[p])) for p in positions) < 1e-5


def _perturbed(weights, scale, seed):
    gen = torch.Generator().manual_seed(seed)
    return {k: v + scale * torch.randn(v.shape, generator=gen) for k, v in weights.items()}


def test_ema_hard_copy_schedule_and_values(model_dir):
    cfg = TeacherConfig(ema_alpha=0.9, ema_interval=5, hard_copy_interval=30)
    assert [teacher_update_action(s, cfg) for s in (1, 4, 5, 10, 29, 30, 60)] == \
        ["none", "none", "ema", "ema", "none", "hard_copy", "hard_copy"]
    t = Teacher(cfg, model_dir, start_worker=False)
    before = t.get_weights()
    student = _perturbed(before, 0.05, seed=0)
    # A step off the schedule changes nothing.
    assert t.update(student, 3)["action"] == "none"
    assert all(torch.equal(before[k], v) for k, v in t.get_weights().items())
    # EMA step: theta_T = 0.9 theta_T + 0.1 theta_S, exactly.
    out = t.update(student, 5)
    assert out == {"action": "ema", "alpha": 0.9, "teacher_version": 1, "step": 5}
    after = t.get_weights()
    for k in before:
        assert torch.allclose(after[k], 0.9 * before[k] + 0.1 * student[k], atol=1e-6)
    assert any(not torch.equal(after[k], before[k]) for k in before)
    # Hard copy: the teacher equals the student bit for bit.
    student2 = _perturbed(before, 0.05, seed=1)
    assert t.update(student2, 30)["action"] == "hard_copy"
    assert all(torch.equal(t.get_weights()[k], student2[k]) for k in before)
    assert t.teacher_version() == 2 and [h["action"] for h in t.history()] == ["ema", "hard_copy"]
    # The served log-probs come from the new weights and carry the new version.
    s = make_sample(random.Random(0), group_id="g", index=0, prompt_len=5, turn_lens=[4])
    assert t.compute([s])[0].teacher_version == 2
    # A subset of the teacher's names is accepted (a frozen vision tower left out); an unknown name is not.
    with pytest.raises(ValueError, match="unknown name.*bogus.weight"):
        t.ema_update({**student, "bogus.weight": torch.zeros(1)})


def test_bf16_teacher_keeps_an_fp32_ema_master(model_dir):
    t = Teacher(TeacherConfig(dtype="bfloat16", ema_alpha=0.995), model_dir, start_worker=False)
    base = t.get_weights()
    assert all(v.dtype == torch.float32 for v in base.values())
    student = {k: v + 1e-3 for k, v in base.items()}
    t.ema_update(student)
    got = t.get_weights()
    k = next(iter(base))
    # 0.005 * 1e-3 = 5e-6 would vanish in bf16 rounding; the fp32 master keeps it.
    assert torch.allclose(got[k] - base[k], torch.full_like(base[k], 5e-6), atol=1e-7)


def test_async_submit_fetch_order_timeouts_and_errors(model_dir):
    t = Teacher(TeacherConfig(batch_size=2), model_dir)
    try:
        batch = make_batch(seed=4, groups=2, group_size=3)
        assert t.submit(batch[:3]) >= 0
        assert t.submit(batch[3:]) >= 0
        t.submit(batch[:1])  # resubmission is a no-op
        wanted = [batch[5].sample_id, batch[0].sample_id]
        got = t.fetch(wanted, timeout_s=60)
        assert [o.sample_id for o in got.outputs] == wanted and got.wait_s >= 0
        rest = t.fetch([s.sample_id for s in batch[1:5]], timeout_s=60)
        assert len(rest.outputs) == 4
        with pytest.raises(KeyError, match="never submitted"):
            t.fetch([batch[0].sample_id])  # consumed already
        stats = t.stats()
        assert stats["computed"] == 6 and stats["queued"] == 0
    finally:
        t.shutdown()
    idle = Teacher(TeacherConfig(), model_dir, start_worker=False)  # nothing computes
    s = make_sample(random.Random(2), group_id="g", index=0, prompt_len=5, turn_lens=[3])
    idle.submit([s])
    with pytest.raises(TimeoutError, match=s.sample_id):
        idle.fetch([s.sample_id], timeout_s=0.2)


def test_scoring_error_is_reported_with_the_sample_id(model_dir):
    t = Teacher(TeacherConfig(), model_dir)
    try:
        rng = random.Random(3)
        s = make_sample(rng, group_id="g", index=0, prompt_len=5, turn_lens=[3])
        broken = s.model_copy(update={"loss_mask": [1] + s.loss_mask[1:], "sample_id": "broken"})
        t.submit([broken])
        with pytest.raises(RuntimeError, match="broken"):
            t.fetch(["broken"], timeout_s=60)
    finally:
        t.shutdown()


def test_state_roundtrip_and_checkpoint(model_dir, tmp_path):
    t = Teacher(TeacherConfig(), model_dir, start_worker=False)
    student = _perturbed(t.get_weights(), 0.05, seed=2)
    t.ema_update(student)
    t.save(str(tmp_path))
    fresh = Teacher(TeacherConfig(), model_dir, start_worker=False)
    fresh.load(str(tmp_path))
    assert fresh.teacher_version() == 1
    assert all(torch.equal(fresh.get_weights()[k], v) for k, v in t.get_weights().items())
    other = Teacher(TeacherConfig(), model_dir, start_worker=False)
    other.set_state(t.get_state())
    assert all(torch.equal(other.get_weights()[k], v) for k, v in t.get_weights().items())


def test_length_batches_come_back_in_order_and_pad_less(model_dir):
    """Teacher forwards of 2 samples grouped by length hold other pairs than in arrival order: the
    outputs come back in the samples' order with the same log-probs, and less of what the teacher
    computed is padding. The worker takes the oldest queued sample with its nearest in length, the
    samples a learner step waits for first."""
    rng = random.Random(5)
    samples = [make_sample(rng, group_id="g", index=i, prompt_len=5, turn_lens=[n])
               for i, n in enumerate((3, 30, 4, 28, 6, 25))]  # lengths 8, 35, 9, 33, 11, 30
    cfg = {"batch_size": 2, "hints": {"enabled": False}, "pack_sequences": False}  # padded: padding is compared
    by_index = Teacher(TeacherConfig(**cfg, batch_order="index"), model_dir, start_worker=False)
    by_length = Teacher(TeacherConfig(**cfg), model_dir, start_worker=False)
    index_outs, length_outs = by_index.compute(samples), by_length.compute(samples)
    assert [o.sample_id for o in length_outs] == [s.sample_id for s in samples]
    for a, b in zip(index_outs, length_outs):
        assert max(abs(x - y) for x, y in zip(a.logprobs, b.logprobs)) < 1e-5, a.sample_id

    def padded(outs):
        return sum(o.padded_positions for o in outs), sum(o.computed_positions for o in outs)

    assert padded(index_outs) == (196 - 126, 196)  # pairs (8, 35), (9, 33), (11, 30)
    assert padded(length_outs) == (148 - 126, 148)  # pairs (35, 33), (30, 11), (9, 8)
    by_length.submit(samples)
    with by_length._cv:
        oldest = [s.sample_id for s in by_length._take_batch()]
        by_length._wanted.update(samples[i].sample_id for i in (1, 4, 5))
        waited = [s.sample_id for s in by_length._take_batch()]
    assert oldest == [samples[2].sample_id, samples[0].sample_id]
    # Sample 3 (33 tokens) is nearer to sample 1 (35) than sample 5 (30) is, but no step waits for it.
    assert waited == [samples[1].sample_id, samples[5].sample_id]
