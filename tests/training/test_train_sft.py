"""The warm start: gold replays through the TITO loop, hint-augmented examples, and SFT itself."""

from __future__ import annotations

import os

import pytest
import torch

from actors.agent_loop import RolloutLimits


@pytest.fixture(scope="module")
def gold(ward_policy_dir):
    from modeling.model import load_tokenizer
    from learner.sft import gold_replay_samples

    previous = os.environ.get("HCGYM_EMBEDDINGS")
    os.environ["HCGYM_EMBEDDINGS"] = "0"
    try:
        tokenizer = load_tokenizer(ward_policy_dir)
        refs = [("ward", "ward_dose", "train"), ("ward", "ward_record", "train")]
        samples = gold_replay_samples(tokenizer, refs, RolloutLimits(max_turns=5), prompt_style="compact")
    finally:
        if previous is None:
            os.environ.pop("HCGYM_EMBEDDINGS")
        else:
            os.environ["HCGYM_EMBEDDINGS"] = previous
    return tokenizer, samples


def test_gold_replays_are_correct_tito_episodes(gold):
    tokenizer, samples = gold
    assert [s.task_id for s in samples] == ["ward_dose", "ward_record"]
    for s in samples:
        assert s.correct and s.reward > 0.9 and not s.truncated
        assert s.turns[-1].end == len(s.input_ids)  # ends with the submit turn
        assert "submit_answer" in tokenizer.decode(s.input_ids[s.turns[-1].start:s.turns[-1].end])
        assert "Tools: " in tokenizer.decode(s.input_ids[:s.prompt_length])  # the compact prompt


def test_hinted_examples_match_the_teachers_context(gold, ward_policy_dir):
    """The SFT hint turn is exactly the teacher's: same tokens, same place; hint tokens untrained."""
    from actors.teacher import Teacher
    from modeling.config_models import TeacherConfig
    from learner.sft import hinted_example

    tokenizer, samples = gold
    config = TeacherConfig(enabled=True)
    teacher = Teacher(config, ward_policy_dir, start_worker=False)
    for kind, correct in (("reinforcing", True), ("corrective", False)):
        sample = samples[0].model_copy(update={"correct": correct})
        example = hinted_example(sample, tokenizer, config.hints, kind)
        context = teacher.build_context(sample)
        assert context.hint == kind
        assert example.input_ids == context.input_ids
        shift = context.hint_tokens
        trained = [p for p, m in enumerate(example.loss_mask) if m]
        assert trained == [p + shift for p, m in enumerate(sample.loss_mask) if m]


def test_sft_lowers_the_loss_on_gold_turns(gold, ward_policy_dir, tmp_path):
    from modeling.model import load_policy, pad_batch, per_token_logprobs
    from learner.sft import run_sft

    tokenizer, samples = gold

    def nll(model_dir):
        model, _ = load_policy(model_dir)
        ids, mask = pad_batch([s.input_ids for s in samples], tokenizer.pad_token_id)
        loss_mask, _ = pad_batch([s.loss_mask for s in samples], 0)
        with torch.no_grad():
            lp = per_token_logprobs(model, ids, mask)
        return float(-(lp * loss_mask).sum() / loss_mask.sum())

    info = run_sft(ward_policy_dir, tmp_path / "sft", samples, epochs=10, lr=3e-3, batch_size=2, seed=0,
                   log=lambda line: None)
    assert info["steps"] == 10 and info["last_loss"] < info["first_loss"]
    assert nll(tmp_path / "sft") < nll(ward_policy_dir) - 1.0
    assert (tmp_path / "sft" / "model.safetensors.index.json").exists() and (tmp_path / "sft" / "tokenizer.json").exists()
    with pytest.raises(ValueError, match="no training samples"):
        run_sft(ward_policy_dir, tmp_path / "x", [], epochs=1, lr=1e-3, batch_size=1, seed=0)
