"""The episode's types: how an episode ended, what a tool call returned, what the prompt is made of.

`HealthcareGymEnv` (envs/env.py) speaks these types through its structured API (`call_tool`,
`finish`, `prompt`, `tool_schemas`); training's agent loop (actors/agent_loop.py), evaluation's
agent condition (evals/conditions.py), the training metrics and the viewer read the one end-reason
vocabulary defined here.
"""

from __future__ import annotations

from typing import Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field

from envs.core.trajectory import ErrorKind

#: How an episode ended, the one vocabulary of the project (env, training, evaluation, viewer):
#:   "answer"           the agent called the submit tool (`submit_answer`) successfully;
#:   "text_answer"      a turn without a tool call was taken as the final answer
#:                      (`text_turn_ends_episode`, or `finish(final_text=...)`);
#:   "turn_limit"       the assistant-turn limit (`max_turns`) was reached;
#:   "tool_call_limit"  the tool-call limit (`max_tool_calls`) was reached;
#:   "token_limit"      the runner's token budget (response or completion tokens) was spent;
#:   "context_overflow" the prompt no longer fits the policy's context;
#:   "parse_failure"    the episode ended without a readable answer (evaluation: the last turn held
#:                      no tool call, or a one-turn reply had no answer in it);
#:   "endpoint_error"   the policy's endpoint failed for good;
#:   "env_error"        the environment itself raised (a bug in a toolkit or scorer), unscored.
EndReason = Literal["answer", "text_answer", "turn_limit", "tool_call_limit", "token_limit", "context_overflow",
                    "parse_failure", "endpoint_error", "env_error"]
END_REASONS: tuple[str, ...] = get_args(EndReason)
#: End reasons of an episode the agent ended itself (`terminated`); every other one is a cut (`truncated`).
ANSWER_REASONS: tuple[str, ...] = ("answer", "text_answer")

#: Names older records and training's `metadata["truncation"]` used for the same ends.
LEGACY_END_REASONS: dict[str, str] = {"max_turns": "turn_limit", "response_tokens": "token_limit",
                                      "limit": "token_limit"}


def end_reason(value: str) -> EndReason:
    """`value` in the one vocabulary: an `EndReason` as is, a legacy name mapped; anything else is
    refused with the list of valid reasons."""
    mapped = LEGACY_END_REASONS.get(value, value)
    if mapped not in END_REASONS:
        raise ValueError(f"end reason {value!r} is not one of {', '.join(END_REASONS)}")
    return mapped  # type: ignore[return-value]


#: How a `call_tool` failed: the toolkit's error kinds (`envs.core.trajectory.ErrorKind`), plus
#: "episode_over" (a call after the episode ended; nothing ran).
CallErrorKind = Literal["unknown_tool", "invalid_arguments", "tool_error", "input_error", "internal_error",
                        "episode_over"]
assert set(get_args(ErrorKind)) < set(get_args(CallErrorKind))


class EpisodeEnd(BaseModel):
    """How one episode ended and how it was scored: what crosses process boundaries (Ray actors,
    evaluation rows), built by the env and read by training and evaluation alike.

    Attributes:
        reason: How it ended (`EndReason`).
        terminated: The agent ended it (an answer); otherwise it was cut (`truncated`).
        reward: The 5D reward's total (0 for an `env_error`).
        reward_components: The reward's dimensions (accuracy, process, safety, format, coherence,
            and assertion where the task has assertions) and `total`.
        is_correct: The reward's correctness verdict.
        safety_violations: Count of safety violations per severity ("1".."5").
        submitted_answer: The answer graded (a submit call's or the text answer), None for a cut.
        grader_error: A grader that raised (the episode is then scored 0).
        env_error: The environment raised (a toolkit or scorer bug); the episode is unscored.
        episode: The episode record (`Trajectory` as JSON, without the system prompt and durations),
            None where none exists (an env error).
    """

    model_config = ConfigDict(extra="forbid")
    reason: EndReason
    terminated: bool
    truncated: bool
    reward: float
    reward_components: dict[str, float] = Field(default_factory=dict)
    is_correct: bool = False
    safety_violations: dict[str, int] = Field(default_factory=dict)
    submitted_answer: str | None = None
    grader_error: str | None = None
    env_error: str | None = None
    episode: dict[str, Any] | None = None

    @classmethod
    def failed(cls, error: str) -> "EpisodeEnd":
        """The end of an episode whose env raised: cut, unscored (reward 0), the failure named."""
        return cls(reason="env_error", terminated=False, truncated=True, reward=0.0, env_error=error)


class ToolResult(BaseModel):
    """What `HealthcareGymEnv.call_tool` returns for one call.

    Attributes:
        name: The tool called.
        arguments: The arguments as the env read them.
        observation: The text the agent is shown (the result, or `{"error": ...}`), cut at the env's
            `max_tool_result_chars`.
        ok: The call ran and succeeded.
        error: Why it failed.
        error_kind: What kind of failure (`CallErrorKind`).
        submit: The call was the submit tool.
        done: The episode is over after this call (an accepted answer, or a limit reached).
        end: The episode's end when `done`.
    """

    model_config = ConfigDict(extra="forbid")
    name: str
    arguments: dict[str, Any] = Field(default_factory=dict)
    observation: str
    ok: bool
    error: str | None = None
    error_kind: CallErrorKind | None = None
    submit: bool = False
    done: bool = False
    end: EpisodeEnd | None = None


class PromptParts(BaseModel):
    """What an episode's prompt is made of.

    Attributes:
        system: The system message for an agent whose framework renders the tool definitions
            itself (TRL, OpenAI-style tool loops, MCP): the domain policy, without the env's tool
            block.
        policy: The domain's policy text alone.
        ticket: The user-facing task text (with the options of a choice question).
        tools: The task's tool schemas (OpenAI function format), in the toolkit's stable order.
        image_path: The task's image, for multimodal tasks.
        system_prompt: The system prompt of a text agent (`step`): the policy, the call format and
            the tool block.
    """

    model_config = ConfigDict(extra="forbid")
    system: str
    policy: str
    ticket: str
    tools: list[dict[str, Any]]
    image_path: str | None = None
    system_prompt: str

    def messages(self) -> list[dict[str, Any]]:
        """The first chat messages without the tool block (system, then the user's ticket, the
        image first as a content part for a vision task)."""
        user: Any = self.ticket
        if self.image_path:
            user = [{"type": "image", "image": self.image_path}, {"type": "text", "text": self.ticket}]
        return [{"role": "system", "content": self.system}, {"role": "user", "content": user}]


def cut_observation(observation: str, max_chars: int | None) -> str:
    """An observation cut to `max_chars` with a marker saying how much was left out (what an agent
    runner's own per-observation cap shows the policy); None keeps it whole."""
    if max_chars is not None and len(observation) > max_chars:
        return observation[:max_chars] + f" ...[{len(observation) - max_chars} more characters]"
    return observation


#: What `episode_record` leaves out: the system prompt (the same for every episode of a domain) and
#: wall-clock durations (so the record of a re-run episode is identical).
_EPISODE_EXCLUDE = {"system_prompt": True,
                    "turns": {"__all__": {"duration_s": True, "tool_calls": {"__all__": {"duration_s"}}}}}


def episode_record(trajectory: Any) -> dict[str, Any] | None:
    """The env's `Trajectory` as plain JSON data (None without one)."""
    if trajectory is None or not hasattr(trajectory, "model_dump"):
        return None
    return trajectory.model_dump(mode="json", exclude=_EPISODE_EXCLUDE)


def safety_violations(reward_details: dict[str, Any] | None) -> dict[str, int]:
    """Safety violations of a scored episode counted by severity ("1".."5")."""
    counts: dict[str, int] = {}
    for violation in (reward_details or {}).get("violations") or []:
        level = str(violation.get("severity"))
        counts[level] = counts.get(level, 0) + 1
    return counts
