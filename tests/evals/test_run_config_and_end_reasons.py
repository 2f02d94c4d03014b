"""Evaluation reads a run's config through the run config's own loader, and every end reason it, the
training metrics and the viewer show comes from the one vocabulary (`envs.episode.EndReason`)."""

from __future__ import annotations

import pyarrow as pa
import pytest
import yaml

from actors.types import RolloutSample
from envs.episode import END_REASONS, EndReason
from learner.config import ConfigError, RolloutConfig
from learner.metrics import episode_index_fields


def run_dir(tmp_path, rollout: dict):
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"rollout": rollout}))
    return {"kind": "run", "run_dir": str(tmp_path)}


def test_a_runs_rollout_settings_come_through_the_run_config_loader(tmp_path):
    from evals.cli import _run_rollout

    notes = run_dir(tmp_path, {"max_turns": 3, "max_observation_chars": 400, "text_turn_ends_episode": True,
                               "env_vars": {"HCGYM_EMBEDDINGS": "0"}})
    rollout = _run_rollout(notes)
    assert isinstance(rollout, RolloutConfig)
    assert (rollout.max_turns, rollout.max_observation_chars, rollout.text_turn_ends_episode) == (3, 400, True)
    assert rollout.env_vars == {"HCGYM_EMBEDDINGS": "0"} and rollout.max_response_tokens == 12288  # its default
    assert _run_rollout({"kind": "model"}) is None


@pytest.mark.parametrize("rollout, key", [({"max_turns": 0}, "rollout.max_turns"),
                                          ({"text_turn_ends_episode": "yes"}, "rollout.text_turn_ends_episode"),
                                          ({"max_turn": 3}, "rollout.max_turn")])
def test_an_invalid_run_config_is_refused_naming_the_file_and_key(tmp_path, rollout, key):
    from evals.cli import _run_rollout

    with pytest.raises(ConfigError, match=rf"config.yaml: invalid config[\s\S]*{key}"):
        _run_rollout(run_dir(tmp_path, rollout))


def test_evaluation_training_and_the_viewer_share_one_vocabulary():
    from evals.types import END_REASONS as EVAL_END_REASONS, EndReason as EvalEndReason
    from viewer.data import _current_end_reasons

    assert EvalEndReason is EndReason and EVAL_END_REASONS == END_REASONS

    def sample(metadata):
        return RolloutSample(sample_id="t:0:0", task_id="t", domain="d", group_id="t", seed=0, prompt_length=1,
                             input_ids=[1], loss_mask=[0], sampling_logprobs=[0.0], policy_versions=[-1],
                             metadata=metadata)

    # a sample the agent loop wrote names its end; one written before is mapped from its truncation label
    assert episode_index_fields(sample({"truncation": "max_turns", "end_reason": "turn_limit"}))["end_reason"] == "turn_limit"
    assert episode_index_fields(sample({"truncation": "max_turns"}))["end_reason"] == "turn_limit"
    assert episode_index_fields(sample({"truncation": "response_tokens"}))["end_reason"] == "token_limit"
    old_file = pa.table({"end_reason": pa.array(["max_turns", "answer", None, "response_tokens"], pa.string())})
    assert _current_end_reasons(old_file).column("end_reason").to_pylist() == ["turn_limit", "answer", None,
                                                                               "token_limit"]
    current = pa.table({"end_reason": pa.array(["answer"], pa.string())})
    assert _current_end_reasons(current) is current
