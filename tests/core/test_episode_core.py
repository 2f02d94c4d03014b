"""The env's structured API (`call_tool` / `finish` / `prompt` / `tool_schemas`) and `step(text)` are one
episode core: the same episode through either scores the same, the limits (assistant turns, tool
calls, result size) are settings, and an episode's end is a typed `EpisodeEnd` in one vocabulary."""

from __future__ import annotations

import json

import pytest

from envs.env import MAX_TOOL_RESULT_CHARS, HealthcareGymEnv, call_as_text
from envs.episode import END_REASONS, EpisodeEnd, ToolResult, end_reason
from envs.validate import gold_answer_text

# Domains whose first test task's gold solution calls tools (and one that only answers).
GOLD_DOMAINS = ["drug_interaction", "ehr_management", "triage_emergency", "clinical_diagnosis", "medical_qa"]


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def gold_calls(task) -> list[tuple[str, dict]]:
    submit = {"answer": gold_answer_text(task) or "",
              "reasoning": str(task.metadata.get("gold_reasoning") or "gold replay")}
    return [(a.name, dict(a.arguments)) for a in task.evaluation_criteria.actions] + [("submit_answer", submit)]


def first_task_with_actions(env: HealthcareGymEnv):
    return next((t for t in env.tasks if t.evaluation_criteria.actions), env.tasks[0])


@pytest.mark.parametrize("domain", GOLD_DOMAINS)
def test_a_gold_episode_scores_the_same_through_step_and_through_call_tool(domain):
    env = HealthcareGymEnv(domain=domain, split="test", max_turns=40)
    task = first_task_with_actions(env)
    calls = gold_calls(task)

    env.reset(seed=0, options={"task_id": task.id})
    for name, args in calls:
        _, reward, terminated, truncated, info = env.step(call_as_text(name, args))
        if terminated or truncated:
            break
    assert terminated and info["end"].reason == "answer"
    by_step, step_record = info["end"], env.trajectory()

    env.reset(seed=0, options={"task_id": task.id})
    for name, args in calls:
        result = env.call_tool(name, args, message="")
        assert isinstance(result, ToolResult)
        if result.done:
            break
    assert result.done and result.submit and result.end is env.end and env.done
    by_call, call_record = env.end, env.trajectory()

    assert by_call.reason == "answer" and by_call.terminated and not by_call.truncated
    assert by_call.reward == by_step.reward == float(reward)
    assert by_call.reward_components == by_step.reward_components
    assert set(by_call.reward_components) >= {"accuracy", "process", "safety", "format", "coherence", "total"}
    assert env.reward == by_call.reward and env.reward_components == by_call.reward_components
    assert by_call.is_correct == by_step.is_correct and by_call.submitted_answer == by_step.submitted_answer
    # the same record, turn by turn: calls, results, the canonical action text
    assert [t.action for t in call_record.turns] == [t.action for t in step_record.turns]
    assert [[(c.name, c.arguments, c.result, c.error) for c in t.tool_calls] for t in call_record.turns] == \
        [[(c.name, c.arguments, c.result, c.error) for c in t.tool_calls] for t in step_record.turns]
    assert call_record.db_hash_final == step_record.db_hash_final


def test_several_calls_in_one_assistant_turn_count_as_one_turn_and_the_turn_limit_is_a_cut():
    env = HealthcareGymEnv(domain="drug_interaction", split="test", max_turns=2)
    task = first_task_with_actions(env)
    think = ("think", {"thought": "check the regimen"})
    env.reset(seed=0, options={"task_id": task.id})
    for i in range(3):  # three calls of the first turn
        assert not env.call_tool(*think, message="first turn" if i == 0 else None).done
    assert not env.call_tool(*think, message="second turn").done
    assert len(env.trajectory().turns) == 2 and len(env.trajectory().turns[0].tool_calls) == 3
    refused = env.call_tool(*think, message="third turn")  # a third assistant turn: over the limit
    assert refused.done and not refused.ok and refused.error_kind == "episode_over"
    assert refused.end.reason == "turn_limit" and refused.end.truncated and len(env.trajectory().turns) == 2
    # step scores the same two turns the same way at its turn limit
    env.reset(seed=0, options={"task_id": task.id})
    env.step("first turn\n" + "\n".join([call_as_text(*think)] * 3))
    *_, truncated, info = env.step("second turn\n" + call_as_text(*think))
    assert truncated and info["end"].reason == "turn_limit"
    assert info["end"].reward == refused.end.reward and info["end"].reward_components == refused.end.reward_components
    # end_turn() at the limit ends it where step would
    env.reset(seed=0, options={"task_id": task.id})
    env.call_tool(*think, message="a")
    assert env.end_turn() is None
    env.call_tool(*think, message="b")
    assert env.end_turn().reason == "turn_limit" and env.done


def test_max_tool_calls_is_apart_from_max_turns():
    think = ("think", {"thought": "x"})
    env = HealthcareGymEnv(domain="drug_interaction", split="test", max_turns=10, max_tool_calls=3)
    env.reset(seed=0)
    results = [env.call_tool(*think) for _ in range(3)]  # one turn: no message after the first call
    assert [r.done for r in results] == [False, False, True] and results[-1].end.reason == "tool_call_limit"
    assert len(env.trajectory().turns) == 1
    env.reset(seed=0)
    *_, truncated, info = env.step("\n".join([call_as_text(*think)] * 5))
    assert truncated and info["end"].reason == "tool_call_limit"
    assert len(info["tool_calls"]) == 3 and any("2 tool calls were not run" in e for e in info["parse_errors"])
    with pytest.raises(ValueError, match="max_tool_calls"):
        HealthcareGymEnv(domain="drug_interaction", split="test", max_tool_calls=0)


def test_the_result_size_limit_is_a_setting():
    name, args = "lookup_drug", {"name": "warfarin"}
    whole = HealthcareGymEnv(domain="drug_interaction", split="test", max_tool_result_chars=None)
    whole.reset(seed=0)
    full = whole.call_tool(name, args)
    assert full.ok and len(full.observation) > 120 and "[truncated" not in full.observation
    cut = HealthcareGymEnv(domain="drug_interaction", split="test", max_tool_result_chars=100)
    cut.reset(seed=0)
    short = cut.call_tool(name, args)
    assert short.observation == full.observation[:100] + "\n[truncated: result longer than 100 characters]"
    assert HealthcareGymEnv(domain="drug_interaction", split="test").max_tool_result_chars == MAX_TOOL_RESULT_CHARS


def test_finish_grades_a_text_answer_as_a_text_turn_does_and_is_idempotent():
    env = HealthcareGymEnv(domain="medical_qa", split="test", max_turns=5, text_turn_ends_episode=True)
    task = next(t for t in env.tasks if t.options)
    text = f"<think>weighing the options</think>\nThe answer is {task.correct_answer}."
    env.reset(seed=0, options={"task_id": task.id})
    *_, terminated, _, info = env.step(text)
    assert terminated and info["end"].reason == "text_answer"

    plain = HealthcareGymEnv(domain="medical_qa", split="test", max_turns=5)  # the default: text turns go on
    plain.reset(seed=0, options={"task_id": task.id})
    end = plain.finish(final_text=text)
    assert (end.reason, end.terminated, end.submitted_answer) == ("text_answer", True, f"The answer is {task.correct_answer}.")
    assert end.reward == info["end"].reward and end.reward_components == info["end"].reward_components
    assert end.is_correct
    assert plain.finish(final_text="something else") is end and plain.finish(reason="token_limit") is end
    assert plain.call_tool("think", {"thought": "late"}).error_kind == "episode_over"


def test_finish_cuts_an_episode_as_truncate_does_and_refuses_a_reason_outside_the_vocabulary():
    env = HealthcareGymEnv(domain="cross_domain", split="test", max_turns=10)
    task = env.tasks[0]
    env.reset(seed=0, options={"task_id": task.id})
    with pytest.raises(ValueError, match="needs final_text"):
        env.finish()
    with pytest.raises(ValueError, match="not one of"):
        env.finish(reason="out_of_tokens")
    with pytest.raises(ValueError, match="reason names a cut"):
        env.finish(reason="answer")
    env.call_tool("think", {"thought": "assess the patient before any order"}, message="")
    end = env.finish(reason="token_limit")
    assert isinstance(end, EpisodeEnd) and (end.reason, end.truncated, end.submitted_answer) == ("token_limit", True, None)
    env.reset(seed=0, options={"task_id": task.id})
    env.step(call_as_text("think", {"thought": "assess the patient before any order"}))
    reward, info = env.truncate("token_limit")
    assert reward == end.reward and info["end"].reward_components == end.reward_components
    assert end_reason("max_turns") == "turn_limit" and end_reason("response_tokens") == "token_limit"


def test_call_tool_reports_bad_calls_and_reads_arguments_as_json_text():
    env = HealthcareGymEnv(domain="drug_interaction", split="test")
    with pytest.raises(RuntimeError, match="reset"):
        env.call_tool("think", {})
    env.reset(seed=0)
    assert env.call_tool("no_such_tool", {}).error_kind == "unknown_tool"
    assert env.call_tool("lookup_drug", {"nope": 1}).error_kind == "invalid_arguments"
    assert env.call_tool("lookup_drug", "{not json").error_kind == "invalid_arguments"
    ok = env.call_tool("lookup_drug", json.dumps({"name": "warfarin"}))
    assert ok.ok and ok.arguments == {"name": "warfarin"} and not ok.done


def test_prompt_parts_and_tool_schemas_without_the_tool_block():
    env = HealthcareGymEnv(domain="drug_interaction", split="test")
    before_reset = env.tool_schemas
    _, info = env.reset(seed=0)
    parts = env.prompt()
    names = [s["function"]["name"] for s in parts.tools]
    assert parts.tools == before_reset == env.tool_schemas == info["tools"]
    assert names[:2] == ["think", "submit_answer"] and len(names) == len(set(names))
    # the tool block is in the text agent's system prompt only, listing the tools in the same order
    assert "<tools>" not in parts.system and "<tools>" in parts.system_prompt == info["system_prompt"]
    positions = [parts.system_prompt.index(f'"name": "{n}"') for n in names]
    assert positions == sorted(positions)
    assert parts.policy == info["policy"] and parts.ticket == info["ticket"]
    assert [m["role"] for m in parts.messages()] == ["system", "user"]


def test_warmup_scores_a_throwaway_episode_and_leaves_the_running_one_alone():
    env = HealthcareGymEnv(domain="drug_interaction", split="test", max_turns=3)
    env.reset(seed=0)
    env.call_tool("think", {"thought": "a"}, message="")
    before = env.trajectory()
    assert env.warmup() > 0
    assert env.trajectory() == before and not env.done and env.end is None


def test_the_vocabulary_is_one_literal():
    assert {"answer", "text_answer", "turn_limit", "tool_call_limit", "token_limit", "context_overflow",
            "parse_failure", "endpoint_error", "env_error"} == set(END_REASONS)
