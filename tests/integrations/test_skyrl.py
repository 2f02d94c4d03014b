"""skyrl-gym 0.4 through `envs.integrations.skyrl`, with skyrl-gym's own registry, `make` and metric
aggregation: an exported row's gold episode, driven the way SkyRL's generator drives an env (init,
then one `step` per model reply as text), scores what the env's own gold replay scores; a reply with
no tool call ends the episode as a text answer graded as the env grades it; bad rows and configs are
refused naming what was wrong."""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest
import skyrl_gym
from skyrl_gym.envs.base_text_env import BaseTextEnv

from envs.env import HealthcareGymEnv
from envs.export import export_tasks
from envs.integrations.skyrl import ENV_ID, HealthcareSkyRLEnv, register
from envs.validate import gold_actions_as_text, gold_replay


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    """The ward domain's tasks as `hcgym tasks export` writes them, by task id."""
    out = tmp_path_factory.mktemp("export")
    export_tasks(out, domains=["ward"], fmt="parquet")
    return {row["task_id"]: row for row in pq.read_table(out / "ward.parquet").to_pylist()}


def _make(row, **env_config):
    register()
    extras = {k: v for k, v in row.items() if k not in ("prompt", "env_class")}  # SkyRL's PromptDataset
    extras["max_turns"] = 6  # the generator adds its max_turns
    return skyrl_gym.make(ENV_ID, env_config=env_config, extras=extras)


def test_registered_with_skyrl_gym_and_idempotent():
    register()
    register()
    assert skyrl_gym.registry[ENV_ID].entry_point == "envs.integrations.skyrl:HealthcareSkyRLEnv"


@pytest.mark.parametrize("task_id", ["ward_dose", "ward_record"])
def test_gold_episode_scores_as_the_envs_own_gold_replay(rows, task_id):
    env = _make(rows[task_id])
    assert isinstance(env, HealthcareSkyRLEnv) and isinstance(env, BaseTextEnv)
    chat, info = env.init(rows[task_id]["prompt"])
    reference = HealthcareGymEnv(domain="ward", max_turns=6)
    reference.reset(options={"task_id": task_id})
    parts = reference.prompt()
    assert [m["role"] for m in chat] == ["system", "user"] and chat[0]["content"] == parts.system_prompt
    assert chat[1]["content"] == parts.ticket == rows[task_id]["prompt"][1]["content"]
    assert info == {"task_id": task_id, "domain": "ward"}

    task = env.env.task
    outputs = [env.step(text) for text in gold_actions_as_text(task)]
    for out in outputs:
        assert out["done"] is False and out["reward"] == 0.0 and [m["role"] for m in out["observations"]] == ["tool"]
    submit = {"name": "submit_answer", "arguments": {"answer": task.correct_answer,
                                                     "reasoning": str(task.metadata.get("gold_reasoning") or "gold replay")}}
    last = env.step("<tool_call>" + json.dumps(submit) + "</tool_call>")
    expected = gold_replay(task, "ward", max_turns=6)[1]["end"]
    assert last["done"] is True and last["observations"] == []
    assert last["reward"] == expected.reward > 0.9
    assert last["metadata"]["reason"] == "answer" and last["metadata"]["is_correct"] is True
    assert last["metadata"]["reward_components"] == expected.reward_components
    metrics = env.get_metrics()
    assert metrics["turns"] == len(outputs) + 1 and metrics["reward_total"] == last["reward"]
    aggregated = HealthcareSkyRLEnv.aggregate_metrics([metrics, {**metrics, "reward_total": 0.0}])
    assert aggregated["reward_total"] == pytest.approx(last["reward"] / 2)
    env.close()


def test_reply_without_a_tool_call_is_the_text_answer(rows):
    env = _make(rows["ward_dose"])
    env.init(rows["ward_dose"]["prompt"])
    out = env.step("The dose is 450 mg.")
    reference = HealthcareGymEnv(domain="ward", max_turns=6)
    reference.reset(options={"task_id": "ward_dose"})
    end = reference.finish(final_text="The dose is 450 mg.")
    assert out["done"] is True and out["metadata"]["reason"] == "text_answer" == end.reason
    assert out["reward"] == end.reward and out["metadata"]["reward_components"] == reference.reward_components


def test_a_bad_call_is_fed_back_and_the_episode_goes_on(rows):
    env = _make(rows["ward_dose"], text_turn_ends_episode=True)
    env.init(rows["ward_dose"]["prompt"])
    out = env.step('<tool_call>{"name": "no_such_tool", "arguments": {}}</tool_call>')
    assert out["done"] is False and out["reward"] == 0.0
    assert "no_such_tool" in out["observations"][0]["content"]


def test_bad_rows_and_configs_name_what_is_wrong(rows):
    with pytest.raises(ValueError, match="missing task_id"):
        HealthcareSkyRLEnv(extras={"domain": "ward"})
    with pytest.raises(ValueError, match=r"unknown keys \['max_turn'\]"):
        _make(rows["ward_dose"], max_turn=3)
