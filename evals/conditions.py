"""The three evaluation conditions of the paper. Each runs one episode of one task on an env
handle (`actors.agent_loop.EnvHandle`: in-process `LocalEnv` or a Ray `RemoteEnv`) and returns an
`EpisodeOutcome`; the env is always the scorer (its domain scorer, as in training).

* `text`: one turn, no tools. The policy sees a short instruction and the task's ticket; its free
  text is submitted through the env's `submit_answer`, so the reward's own extractor
  (`envs.rewards.choice.extract_choice` for multiple choice) reads the answer.
* `logprob`: multiple-choice only. `policy.option_logprobs(messages, letters)`: the next-token
  log-probability of each option letter after the question; the argmax is the answer.
* `agent`: the multi-turn runner: the env's system prompt (or the run's compact prompt), its tools,
  its action parser, a turn budget and a response-token budget, as in training.

End reasons: the env's one vocabulary (`envs.episode.EndReason`, re-exported as
`evals.types.EndReason`): "answer" (submitted), "text_answer" (a turn without a tool call taken as
the answer, `text_turn_ends_episode`), "turn_limit", "tool_call_limit", "token_limit",
"parse_failure" (no readable answer), "endpoint_error", "context_overflow", "env_error". Every
episode's score is the env's `EpisodeEnd`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from actors.agent_loop import EpisodeSpec, compact_system_prompt
from envs.episode import EndReason, EpisodeEnd, cut_observation
from evals.policies import submit_action
from evals.types import PolicyReply

TEXT_SYSTEM_PROMPT = ("You are a careful medical expert. Answer the question below directly. For a multiple-choice "
                      "question, state the letter of the single best option.")
LOGPROB_SYSTEM_PROMPT = "Answer the multiple-choice question with the letter of the single best option only."
MAX_ANSWER_CHARS = 8000  # what the text condition submits of a reply (the env caps actions too)


@dataclass
class ConditionSettings:
    max_turns: int = 5
    max_tokens: int = 512            # new tokens per turn
    max_response_tokens: int = 4096  # agent condition: completion tokens over the episode
    prompt_style: str = "env"        # agent condition: "env" or "compact" (a run's tiny-model prompt)
    # Agent condition: tool results longer than this are cut as in training (a run's
    # rollout.max_observation_chars); None keeps them whole.
    max_observation_chars: int | None = None
    # Agent condition: a turn without a tool call ends the episode as the final answer (end reason
    # "text_answer"), as in a run trained with rollout.text_turn_ends_episode.
    text_turn_ends_episode: bool = False

    def env_kwargs(self) -> dict[str, Any]:
        """The env arguments these settings imply (env actors and in-process envs alike)."""
        return {"text_turn_ends_episode": True} if self.text_turn_ends_episode else {}


@dataclass
class EpisodeOutcome:
    """What a condition learned about one episode (the runner adds identity and timing)."""

    end_reason: EndReason
    answer: str | None = None
    correct: bool | None = None
    reward: float | None = None
    reward_components: dict[str, float] = field(default_factory=dict)
    safety_violations: dict[str, int] = field(default_factory=dict)
    error_kind: str | None = None
    error_kinds: dict[str, int] = field(default_factory=dict)
    turns: int = 0
    tool_calls: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    messages: list[dict[str, Any]] = field(default_factory=list)


def is_multiple_choice(task) -> bool:
    return bool(task.options)


def episode_spec(task_id: str, domain: str, split: str | None, seed: int) -> EpisodeSpec:
    return EpisodeSpec(sample_id=f"{task_id}:0:{seed}", task_id=task_id, domain=domain, split=split,
                       group_id=task_id, seed=seed, greedy=True)


def _account(outcome: EpisodeOutcome, reply: PolicyReply) -> None:
    outcome.prompt_tokens += reply.prompt_tokens
    outcome.completion_tokens += reply.completion_tokens
    if reply.cost_usd is not None:
        outcome.cost_usd = (outcome.cost_usd or 0.0) + reply.cost_usd


def _error_end_reason(error_kind: str) -> EndReason:
    return "context_overflow" if error_kind == "context_overflow" else "endpoint_error"


def _apply_end(outcome: EpisodeOutcome, end: EpisodeEnd) -> None:
    outcome.reward = end.reward
    outcome.reward_components = dict(end.reward_components)
    outcome.safety_violations = dict(end.safety_violations)
    if outcome.correct is None:
        outcome.correct = end.is_correct
    if end.env_error:  # an env actor ended the episode unscored (a toolkit/scorer bug)
        outcome.error_kind, outcome.extra["env_error"] = "env_error", end.env_error


async def _submit(env, answer: str) -> tuple[EpisodeEnd, bool]:
    """Submit `answer` through the env; returns (the episode's end, whether the env accepted it)."""
    _, _, terminated, truncated, info = await env.step(submit_action(answer[:MAX_ANSWER_CHARS]))
    if terminated or truncated:
        return info["end"], terminated
    return await env.finish("parse_failure"), False


def user_content(info: dict[str, Any]) -> Any:
    """The task's user turn as the env renders it: the ticket, with the image first as a content part
    for vision tasks (endpoints send it as an image; text-only local models see its path)."""
    if info.get("image_path"):
        return [{"type": "image", "image": info["image_path"]}, {"type": "text", "text": info["ticket"]}]
    return info["ticket"]


async def run_text(policy, env, task, domain: str, split: str | None, seed: int,
                   settings: ConditionSettings) -> EpisodeOutcome:
    from envs.rewards.choice import extract_choice

    _, info = await env.reset(episode_spec(task.id, domain, split, seed))
    messages = [{"role": "system", "content": TEXT_SYSTEM_PROMPT}, {"role": "user", "content": user_content(info)}]
    reply = await policy.reply(messages, None, max_tokens=settings.max_tokens, seed=seed)
    outcome = EpisodeOutcome(end_reason="answer", turns=1)
    _account(outcome, reply)
    messages.append({"role": "assistant", "content": reply.text})
    outcome.messages = messages
    outcome.extra["text"] = reply.text
    if reply.error_kind:
        outcome.end_reason, outcome.error_kind = _error_end_reason(reply.error_kind), reply.error_kind
        outcome.error_kinds[reply.error_kind] = 1
        _apply_end(outcome, await env.finish(outcome.end_reason))
        outcome.correct = False
        return outcome
    if is_multiple_choice(task):
        outcome.answer = extract_choice(reply.text, task.options)
        if outcome.answer is None:
            outcome.end_reason = "parse_failure"
    else:
        outcome.answer = reply.text.strip() or None
        if outcome.answer is None:
            outcome.end_reason = "parse_failure"
    end, _ = await _submit(env, reply.text)
    _apply_end(outcome, end)
    return outcome


async def run_logprob(policy, env, task, domain: str, split: str | None, seed: int,
                      settings: ConditionSettings) -> EpisodeOutcome:
    if not is_multiple_choice(task):
        raise ValueError(f"task {task.id!r} is not multiple-choice; the logprob condition needs options")
    _, info = await env.reset(episode_spec(task.id, domain, split, seed))
    messages = [{"role": "system", "content": LOGPROB_SYSTEM_PROMPT}, {"role": "user", "content": info["ticket"]}]
    from evals.openai_policy import EndpointError

    letters = sorted(task.options)
    outcome = EpisodeOutcome(end_reason="answer", turns=1, messages=messages)
    failure: str | None = None
    try:
        if hasattr(policy, "aoption_logprobs"):  # the async form keeps other episodes' requests in flight
            scores = await policy.aoption_logprobs(messages, letters)
        else:
            scores = policy.option_logprobs(messages, letters)
        if scores is None:
            failure = "logprobs_unavailable"
    except EndpointError as exc:  # a request that failed for good: an episode outcome, not a crash
        scores, failure = None, exc.kind
    if failure is not None:
        outcome.end_reason = _error_end_reason(failure)
        outcome.error_kind = failure
        outcome.error_kinds[failure] = 1
        _apply_end(outcome, await env.finish(outcome.end_reason))
        outcome.correct = False
        return outcome
    outcome.answer = max(letters, key=lambda letter: (scores[letter], -ord(letter[0])))
    outcome.correct = outcome.answer == task.correct_answer
    outcome.extra["option_logprobs"] = {k: float(v) for k, v in scores.items()}
    end, _ = await _submit(env, outcome.answer)
    _apply_end(outcome, end)
    return outcome


def action_text(reply: PolicyReply) -> str:
    """The assistant turn as the env's parser reads it: native tool calls (OpenAI shape) become
    `<tool_call>` blocks after the text; malformed argument JSON is passed through so the env's
    parser reports it as it would for any model."""
    parts = [reply.text] if reply.text else []
    for call in reply.tool_calls or []:
        fn = call.get("function", call)
        arguments = fn.get("arguments", {})
        if isinstance(arguments, str):
            try:
                arguments = json.loads(arguments) if arguments.strip() else {}
            except json.JSONDecodeError:
                parts.append('<tool_call>{"name": ' + json.dumps(fn.get("name", "")) + ', "arguments": '
                             + arguments + "}</tool_call>")
                continue
        parts.append("<tool_call>" + json.dumps({"name": fn.get("name", ""), "arguments": arguments},
                                                ensure_ascii=False) + "</tool_call>")
    return "\n".join(parts)


def _observation_messages(reply: PolicyReply, observation: str, had_tool_calls: bool) -> list[dict[str, Any]]:
    """The env's answer as chat messages: one `tool` message per native tool call (the first
    carries the env's whole observation, which covers every call), a `tool` message without an
    id after text-format calls (the chat template renders it as `<tool_response>`, exactly as the
    agent loop's `tool_turn_text`), else a `user` message."""
    if reply.tool_calls:
        out = [{"role": "tool", "tool_call_id": reply.tool_calls[0].get("id", "call_0"), "content": observation}]
        for call in reply.tool_calls[1:]:
            out.append({"role": "tool", "tool_call_id": call.get("id", ""),
                        "content": "(the result of every call of this turn is in the first tool message)"})
        return out
    if had_tool_calls:
        return [{"role": "tool", "content": observation}]
    return [{"role": "user", "content": observation}]


async def run_agent(policy, env, task, domain: str, split: str | None, seed: int,
                    settings: ConditionSettings) -> EpisodeOutcome:
    from actors.agent_loop import turn_seed

    _, info = await env.reset(episode_spec(task.id, domain, split, seed))
    system = info["system_prompt"] if settings.prompt_style == "env" else compact_system_prompt(info["tools"])
    messages: list[dict[str, Any]] = [{"role": "system", "content": system},
                                      {"role": "user", "content": user_content(info)}]
    outcome = EpisodeOutcome(end_reason="turn_limit")
    end: EpisodeEnd | None = None
    last_unparsed = False
    while True:
        budget = settings.max_response_tokens - outcome.completion_tokens
        if budget <= 0:
            outcome.end_reason = "token_limit"
            break
        reply = await policy.reply(messages, info["tools"], max_tokens=min(settings.max_tokens, budget),
                                   seed=turn_seed(seed, outcome.turns))
        _account(outcome, reply)
        if reply.error_kind:
            outcome.end_reason, outcome.error_kind = _error_end_reason(reply.error_kind), reply.error_kind
            outcome.error_kinds[reply.error_kind] = outcome.error_kinds.get(reply.error_kind, 0) + 1
            break
        outcome.turns += 1
        action = action_text(reply)
        assistant: dict[str, Any] = {"role": "assistant", "content": reply.text}
        if reply.tool_calls:
            assistant["tool_calls"] = reply.tool_calls
        messages.append(assistant)
        observation, _, terminated, truncated, step_info = await env.step(action)
        calls = step_info.get("tool_calls") or []
        outcome.tool_calls += len(calls)
        kinds = ["parse_error"] * len(step_info.get("parse_errors") or []) + list(step_info.get("tool_errors") or [])
        for kind in kinds:  # per failed call: parse errors and the tools' error kinds
            outcome.error_kinds[kind] = outcome.error_kinds.get(kind, 0) + 1
        last_unparsed = not calls
        if not calls:
            outcome.error_kinds["no_tool_call"] = outcome.error_kinds.get("no_tool_call", 0) + 1
        if terminated or truncated:
            end = step_info["end"]
            # the env's end reason; a turn limit reached on a turn without a call had no readable answer
            outcome.end_reason = "parse_failure" if end.reason == "turn_limit" and last_unparsed else end.reason
            break
        observation = cut_observation(observation, settings.max_observation_chars)  # as the agent loop cuts it
        messages.extend(_observation_messages(reply, observation, bool(calls)))
        if outcome.turns >= settings.max_turns:  # the env enforces it too
            outcome.end_reason = "turn_limit"
            break
    if end is None:
        end = await env.finish(outcome.end_reason)
    _apply_end(outcome, end)
    answer = end.submitted_answer or None  # "" submitted = no answer
    if answer is not None and is_multiple_choice(task):
        from envs.rewards.choice import extract_choice

        outcome.extra["submitted_text"] = answer
        answer = extract_choice(answer, task.options) or answer
    outcome.answer = answer
    outcome.messages = messages
    return outcome


CONDITION_RUNNERS = {"text": run_text, "logprob": run_logprob, "agent": run_agent}
