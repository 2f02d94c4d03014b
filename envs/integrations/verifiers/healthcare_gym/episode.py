"""What a rollout's tool server and its scoring share: the calls the env ran, and how the episode ends.

The env of a rollout lives in its tool server (a process of its own, one per rollout), which verifiers
tears down before it scores the rollout. The server therefore records every call it ran in the
rollout's `EpisodeState` (verifiers syncs that state back to the rollout after each call), and scoring
rebuilds the episode from it: a fresh `HealthcareGymEnv` replays the same calls through `call_tool`
(each replayed result must equal what the server returned, or scoring fails naming the call, which
verifiers records as the rollout's task error) and then ends it through `finish`: a text reply is
graded as the answer; a rollout verifiers cut (its turn or token limit) gets the env's truncation
score. An episode the submit tool ended keeps that end.
"""

from __future__ import annotations

from typing import Any

import verifiers.v1 as vf
from pydantic import BaseModel, ConfigDict, Field

from envs.env import MAX_TOOL_RESULT_CHARS
from envs.episode import EndReason, EpisodeEnd

#: verifiers' stop conditions that cut a rollout, as the env's end reasons. Every cut is scored by
#: the domain's scorer as a truncation whatever its reason; the reason names it in the record.
CUT_REASONS: dict[str, EndReason] = {
    "max_turns": "turn_limit",
    "max_input_tokens": "token_limit",
    "max_output_tokens": "token_limit",
    "max_total_tokens": "token_limit",
    "compaction_failed": "context_overflow",
}


#: verifiers' stop condition of a rollout whose harness program ended on its own (the chat loop of
#: the `null` harness ends at the first reply that calls no tool).
AGENT_COMPLETED = "agent_completed"


class EnvLimits(vf.BaseConfig):
    """The `HealthcareGymEnv` limits of a rollout's episode (the same in the tool server and in
    scoring's replay, so both count turns and calls alike).

    Attributes:
        max_turns: The env's own cap on assistant turns; each tool call is one turn, as in the TRL
            adapter (the server does not see where a model reply starts). verifiers' own
            `--env.agent.max-turns` (model turns) normally cuts the rollout first.
        max_tool_calls: Tool calls before the env ends the episode ("tool_call_limit"); None: no limit.
        max_tool_result_chars: A tool result longer than this is cut with a marker; None keeps it whole.
    """

    max_turns: int = Field(64, ge=1)
    max_tool_calls: int | None = Field(None, ge=1)
    max_tool_result_chars: int | None = Field(MAX_TOOL_RESULT_CHARS, ge=1)

    def env_kwargs(self) -> dict[str, Any]:
        return self.model_dump()


class RecordedCall(BaseModel):
    """One call the rollout's env ran: its name and arguments exactly as the model sent them, and
    the observation the env returned (what the model saw)."""

    model_config = ConfigDict(extra="forbid")
    name: str
    arguments: Any
    observation: str


class EpisodeState(vf.State):
    """The rollout state verifiers syncs between the tool server and the rollout.

    Attributes:
        task_id: The task the server's env started (checked by scoring).
        calls: Every call the server's env ran, in order.
        end: The episode's end as scoring computed it (`EpisodeEnd`), read by the reward and metrics.
    """

    task_id: str | None = None
    calls: list[RecordedCall] = Field(default_factory=list)
    end: EpisodeEnd | None = None


def cut_reason(trace: vf.Trace) -> EndReason | None:
    """The env's end reason for a rollout verifiers cut, or None when the model ended it with a
    reply that calls no tool (its text is then the answer)."""
    if trace.stop_condition in CUT_REASONS:
        return CUT_REASONS[trace.stop_condition]
    if trace.is_truncated:  # the last reply stopped at the token limit (finish_reason "length")
        return "token_limit"
    replies = trace.assistant_messages
    if trace.stop_condition in (None, AGENT_COMPLETED) and replies and not replies[-1].tool_calls:
        return None
    # Stopped by anything else (a timeout, a @vf.stop) or without a final text reply: a cut, scored
    # like every cut by the domain's truncation rule.
    return "turn_limit"


def replay_episode(*, domain: str, split: str, task_id: str, calls: list[RecordedCall],
                   limits: EnvLimits, final_text: str | None, cut: EndReason | None) -> EpisodeEnd:
    """Rebuild one rollout's episode in a fresh env and end it.

    Args:
        domain, split, task_id: The task.
        calls: The calls the rollout's tool server ran, in order.
        limits: The env limits the server ran with.
        final_text: The model's final reply, graded as the answer when the rollout was not cut.
        cut: The end reason when verifiers cut the rollout (`cut_reason`), else None.

    Raises:
        ValueError: A replayed call returned another observation than the server's (the tools
            were not deterministic for this episode, so the score would not be the one the model
            played for).
    """
    from envs.env import HealthcareGymEnv

    env = HealthcareGymEnv(domain=domain, split=split, **limits.env_kwargs())
    env.reset(options={"task_id": task_id})
    for index, call in enumerate(calls):
        result = env.call_tool(call.name, call.arguments, message="")
        if result.observation != call.observation:
            raise ValueError(
                f"task {task_id!r}: replaying call {index} ({call.name}) returned another result than the "
                f"rollout's tool server did ({result.observation[:200]!r} vs {call.observation[:200]!r})")
    if env.end is not None:  # the submit tool (or the env's own limit) ended it during the rollout
        return env.end
    if cut is not None:
        return env.finish(reason=cut)
    return env.finish(final_text=final_text or "")
