"""The three conditions on the real environment (the ward test domain, in-process envs).

The logprob condition is checked against an independent forward pass: the test loads the tiny
policy with plain `transformers.AutoModelForCausalLM` and computes the letters' next-token
log-probs itself. The small policy classes below are real policies with fixed behaviour (inputs
of the conditions), so each end reason can be provoked on purpose.
"""

from __future__ import annotations

import asyncio
import json
import math

import pytest

from actors.agent_loop import LocalEnv
from evals.conditions import (
    LOGPROB_SYSTEM_PROMPT,
    ConditionSettings,
    action_text,
    run_agent,
    run_logprob,
    run_text,
)
from evals.policies import LocalModelPolicy, ScriptedPolicy
from evals.types import PolicyReply

pytestmark = pytest.mark.usefixtures("ward_domain")


def ward_task(task_id: str):
    from envs import registry

    return {t.id: t for t in registry.get_tasks("ward", None)}[task_id]


class FixedTextPolicy:
    """Answers every turn with the same text (or the same error)."""

    def __init__(self, text: str = "", error_kind: str | None = None, completion_tokens: int = 10) -> None:
        self.policy_id = "fixed"
        self.text, self.error_kind, self.completion_tokens = text, error_kind, completion_tokens
        self.calls: list[dict] = []

    async def reply(self, messages, tools, *, max_tokens, seed):
        self.calls.append({"messages": [dict(m) for m in messages], "tools": tools, "max_tokens": max_tokens})
        return PolicyReply(text=self.text, error_kind=self.error_kind, completion_tokens=self.completion_tokens,
                           prompt_tokens=5)

    def option_logprobs(self, messages, letters):
        return None


def run(coro):
    return asyncio.run(coro)


def test_text_condition_reads_the_answer_with_the_reward_extractor():
    task = ward_task("ward_choice")
    policy = FixedTextPolicy("After looking at the chart, the answer is (B).")
    out = run(run_text(policy, LocalEnv(3), task, "ward", None, 0, ConditionSettings()))
    assert (out.end_reason, out.answer, out.correct) == ("answer", "B", True)
    assert policy.calls[0]["tools"] is None and len(policy.calls) == 1  # one turn, no tools
    assert out.reward is not None and out.reward > 0.5
    hedge = run(run_text(FixedTextPolicy("A or C"), LocalEnv(3), task, "ward", None, 0, ConditionSettings()))
    assert (hedge.end_reason, hedge.answer, hedge.correct) == ("parse_failure", None, False)


def test_text_condition_records_an_endpoint_error_and_still_scores():
    out = run(run_text(FixedTextPolicy(error_kind="http_500"), LocalEnv(3), ward_task("ward_choice"), "ward",
                       None, 0, ConditionSettings()))
    assert (out.end_reason, out.error_kind, out.correct) == ("endpoint_error", "http_500", False)
    assert out.error_kinds == {"http_500": 1} and out.reward is not None


def test_agent_condition_end_reasons():
    task = ward_task("ward_dose")
    settings = ConditionSettings(max_turns=3, max_tokens=50, max_response_tokens=1000)
    gold = run(run_agent(ScriptedPolicy("gold").for_episode(task, 0, "ward", 3), LocalEnv(3), task, "ward",
                         None, 0, settings))
    assert (gold.end_reason, gold.answer, gold.correct, gold.turns, gold.tool_calls) == ("answer", "375", True, 2, 2)
    assert gold.reward == pytest.approx(1.0, abs=0.02)

    silent = FixedTextPolicy("I am not sure.")
    out = run(run_agent(silent, LocalEnv(3), task, "ward", None, 0, settings))
    assert (out.end_reason, out.turns, out.answer) == ("parse_failure", 3, None)
    assert out.error_kinds["no_tool_call"] == 3
    # The observation of a turn without a tool call comes back as a user turn, as in training.
    assert silent.calls[1]["messages"][-1]["role"] == "user"

    looping = FixedTextPolicy('<tool_call>{"name": "get_patient", "arguments": {"patient_id": "P2"}}</tool_call>')
    out = run(run_agent(looping, LocalEnv(3), task, "ward", None, 0, settings))
    assert (out.end_reason, out.turns, out.tool_calls) == ("turn_limit", 3, 3)
    assert out.error_kinds == {}  # every call succeeded

    wrong = FixedTextPolicy('<tool_call>{"name": "get_patients", "arguments": {}}</tool_call>\n'
                            '<tool_call>{"name": "get_patient", "arguments": {"patient": 2}}</tool_call>\n<tool_call>{')
    out = run(run_agent(wrong, LocalEnv(3), task, "ward", None, 0, ConditionSettings(max_turns=1)))
    assert out.error_kinds == {"unknown_tool": 1, "invalid_arguments": 1, "parse_error": 1}
    assert looping.calls[1]["messages"][-1]["role"] == "tool"  # a tool result, rendered as <tool_response>

    chatty = FixedTextPolicy("thinking...", completion_tokens=400)
    out = run(run_agent(chatty, LocalEnv(3), task, "ward", None, 0, ConditionSettings(max_turns=5, max_tokens=400,
                                                                                       max_response_tokens=700)))
    assert (out.end_reason, out.turns, out.completion_tokens) == ("token_limit", 2, 800)
    assert chatty.calls[1]["max_tokens"] == 300  # the remaining response budget caps the turn
    assert out.reward is not None  # the env scored the cut episode

    broken = run(run_agent(FixedTextPolicy(error_kind="context_overflow"), LocalEnv(3), task, "ward", None, 0,
                           settings))
    assert (broken.end_reason, broken.turns, broken.error_kind) == ("context_overflow", 0, "context_overflow")


def test_native_tool_calls_become_the_env_action_text():
    reply = PolicyReply(text="", tool_calls=[
        {"id": "c1", "type": "function", "function": {"name": "get_patient", "arguments": '{"patient_id": "P1"}'}},
        {"id": "c2", "type": "function", "function": {"name": "submit_answer", "arguments": "{not json"}}])
    text = action_text(reply)
    first, second = text.split("\n")
    assert json.loads(first[len("<tool_call>"):-len("</tool_call>")]) == {"name": "get_patient",
                                                                           "arguments": {"patient_id": "P1"}}
    assert "{not json" in second  # passed through: the env's parser reports it


def independent_letter_logprobs(model_dir: str, ticket: str, letters: list[str]) -> dict[str, float]:
    """Plain transformers: load, render the chat template, one forward pass, log-softmax."""
    import torch
    from transformers import AutoModelForCausalLM, AutoTokenizer

    tokenizer = AutoTokenizer.from_pretrained(model_dir, local_files_only=True)
    model = AutoModelForCausalLM.from_pretrained(model_dir, local_files_only=True, dtype=torch.float32).eval()
    text = tokenizer.apply_chat_template([{"role": "system", "content": LOGPROB_SYSTEM_PROMPT},
                                          {"role": "user", "content": ticket}], tokenize=False,
                                         add_generation_prompt=True)
    ids = tokenizer(text, add_special_tokens=False, return_tensors="pt").input_ids
    with torch.no_grad():
        logits = model(ids).logits[0, -1]
    logprobs = torch.log_softmax(logits.double(), dim=-1)
    return {letter: float(logprobs[tokenizer.convert_tokens_to_ids(letter)]) for letter in letters}


def test_logprob_condition_matches_an_independent_forward_pass(ward_policy_dir):
    task = ward_task("ward_choice")
    policy = LocalModelPolicy(ward_policy_dir)
    out = run(run_logprob(policy, LocalEnv(3), task, "ward", None, 0, ConditionSettings()))
    from envs.env import render_ticket

    expected = independent_letter_logprobs(ward_policy_dir, render_ticket(task), sorted(task.options))
    got = out.extra["option_logprobs"]
    assert set(got) == {"A", "B", "C", "D"}
    for letter in got:
        assert got[letter] == pytest.approx(expected[letter], abs=1e-4)
    assert out.answer == max(expected, key=expected.get)
    assert out.correct == (out.answer == "B") and out.end_reason == "answer"
    assert sum(math.exp(v) for v in got.values()) < 1.0  # full-vocabulary probabilities, not renormalised


def test_logprob_condition_refuses_a_question_without_options():
    with pytest.raises(ValueError, match="ward_dose.*not multiple-choice"):
        run(run_logprob(ScriptedPolicy("gold"), LocalEnv(3), ward_task("ward_dose"), "ward", None, 0,
                        ConditionSettings()))


def test_logprob_condition_turns_a_failed_endpoint_into_an_episode():
    """Nothing listens on the port: the endpoint policy's request fails for good (connection_error);
    the episode is recorded as endpoint_error and scored, the run goes on."""
    import socket

    from evals.openai_policy import policy_from_string

    with socket.socket() as probe:  # a port that was free a moment ago, now closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    policy = policy_from_string(f"openai:http://127.0.0.1:{port}/v1:absent", max_retries=0, connect_timeout_s=2.0)
    out = run(run_logprob(policy, LocalEnv(3), ward_task("ward_choice"), "ward", None, 0, ConditionSettings()))
    assert (out.end_reason, out.error_kind, out.correct) == ("endpoint_error", "connection_error", False)
    assert out.error_kinds == {"connection_error": 1} and out.reward is not None


def test_text_condition_sends_a_vision_tasks_image_as_a_content_part():
    from envs import registry

    task = next(t for t in registry.get_tasks("visual_diagnosis", "test") if t.image_path)
    policy = FixedTextPolicy("The answer is A.")
    run(run_text(policy, LocalEnv(3), task, "visual_diagnosis", "test", 0, ConditionSettings()))
    content = policy.calls[0]["messages"][1]["content"]
    assert isinstance(content, list) and content[0] == {"type": "image", "image": task.image_path}
    assert content[1]["type"] == "text" and content[1]["text"].strip()
