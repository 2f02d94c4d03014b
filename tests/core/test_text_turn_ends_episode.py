"""`HealthcareGymEnv(text_turn_ends_episode=True)`: a turn without a tool call (and without a parse
error) ends the episode as the submitted answer, graded as one (the chat-agent
convention TRL's tools mode follows). The default still continues the episode."""

from __future__ import annotations

import json

import pytest

from envs.env import TEXT_ANSWER_END_REASON, HealthcareGymEnv, text_answer


def submit(answer: str) -> str:
    return "<tool_call>" + json.dumps({"name": "submit_answer", "arguments": {"answer": answer}}) + "</tool_call>"


LOOKUP = '<tool_call>{"name": "get_patient", "arguments": {"patient_id": "P1"}}</tool_call>'


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def run(actions: list[str], **kwargs) -> tuple[HealthcareGymEnv, list[tuple]]:
    env = HealthcareGymEnv(domain="ward", task_id="ward_choice", max_turns=4, **kwargs)
    env.reset(seed=0)
    steps = []
    for action in actions:
        steps.append(env.step(action))
        if steps[-1][2] or steps[-1][3]:
            break
    return env, steps


@pytest.mark.parametrize("answer, right", [("The answer is B.", True), ("The answer is A.", False),
                                           ("<think>A or B?</think>\nB", True)])
def test_a_text_turn_ends_the_episode_with_the_reward_of_that_answer_submitted(answer, right):
    env, steps = run([LOOKUP, answer], text_turn_ends_episode=True)
    assert len(steps) == 2
    observation, reward, terminated, truncated, info = steps[-1]
    assert (terminated, truncated) == (True, False)
    assert info["end_reason"] == TEXT_ANSWER_END_REASON == "text_answer"
    record = env.trajectory()
    assert record.submitted_answer == text_answer(answer) and "<think>" not in record.submitted_answer
    assert record.metadata["end_reason"] == "text_answer" and record.terminated and not record.truncated
    assert "final answer" in observation
    # the episode is over: the record ends with the assistant's text, no reminder was sent to it
    assert record.messages[-1] == {"role": "assistant", "content": answer}

    # the same answer through submit_answer, in the default mode: the same 5D reward, component by component
    env_submit, submitted = run([LOOKUP, submit(text_answer(answer))])
    assert submitted[-1][2] is True
    assert reward == pytest.approx(submitted[-1][1])
    assert info["reward_components"] == pytest.approx(submitted[-1][4]["reward_components"])
    assert info["is_correct"] == submitted[-1][4]["is_correct"] == right
    assert env.step("anything")[4] == {"error": "episode_over"}


def test_by_default_a_text_turn_is_answered_with_the_call_format_and_the_episode_goes_on():
    env, steps = run([LOOKUP, "The answer is B.", submit("B")])
    assert len(steps) == 3
    observation, reward, terminated, truncated, info = steps[1]
    assert (reward, terminated, truncated) == (0.0, False, False)
    assert observation.startswith("No tool call found in your message.") and "end_reason" not in info
    assert steps[2][2] is True
    record = env.trajectory()
    assert "end_reason" not in record.metadata and record.submitted_answer == "B"


@pytest.mark.parametrize("malformed", [
    '<tool_call>{"name": "get_patient", "arguments": {"patient_id": </tool_call>',  # broken JSON in a block
    '{"name": "submit_answer", "arguments": {"answer": "B"',                          # a bare JSON call cut short
])
def test_a_malformed_call_does_not_end_the_episode(malformed):
    env, steps = run([malformed, "B"], text_turn_ends_episode=True)
    observation, reward, terminated, truncated, info = steps[0]
    assert info["parse_errors"] and (terminated, truncated) == (False, False) and "end_reason" not in info
    assert "could not parse action" in observation
    # the next turn, plain text, ends it
    assert steps[1][2] is True and steps[1][4]["end_reason"] == "text_answer"
    assert env.trajectory().submitted_answer == "B" and steps[1][4]["is_correct"]


def test_a_turn_with_calls_still_continues_and_the_turn_limit_still_truncates():
    env, steps = run([LOOKUP] * 4, text_turn_ends_episode=True)
    assert [s[2] for s in steps] == [False] * 4 and steps[-1][3] is True
    assert "end_reason" not in steps[-1][4] and env.trajectory().submitted_answer is None


def test_an_empty_action_ends_the_episode_with_no_answer():
    env, steps = run([""], text_turn_ends_episode=True)
    _, reward, terminated, _, info = steps[0]
    assert terminated and info["end_reason"] == "text_answer" and info["is_correct"] is False
    assert env.trajectory().submitted_answer == "" and info["reward_components"]["accuracy"] == 0.0


@pytest.mark.parametrize("bad", ["yes", 1, None])
def test_the_option_must_be_a_bool(bad):
    with pytest.raises(ValueError, match="text_turn_ends_episode must be true or false"):
        HealthcareGymEnv(domain="ward", text_turn_ends_episode=bad)
