"""The wire types of the OpenEnv server: OpenEnv's own MCP actions, the reset observation and the state.

Actions are OpenEnv's `CallToolAction` and `ListToolsAction` and nothing else: OpenEnv routes its
`/mcp` endpoint to an environment's `step` only when the server's action class is exactly one of
them, so the project's own actions (start, finish with a text answer or a cut, read the score) are
episode tools, the same three the MCP server offers (`EPISODE_TOOLS`). A call's assistant text (the
turn it opens) rides in the action's `metadata` (`MESSAGE_META_KEY`).
"""

from __future__ import annotations

from typing import Any

from openenv.core.env_server.mcp_types import (CallToolAction, CallToolObservation, ListToolsAction,
                                               ListToolsObservation, Tool, ToolError, ToolErrorType)
from openenv.core.env_server.types import Observation, State
from pydantic import BaseModel, ConfigDict, Field

__all__ = ["CallToolAction", "CallToolObservation", "ListToolsAction", "ListToolsObservation", "Tool", "ToolError",
           "ToolErrorType", "HealthcareGymObservation", "HealthcareGymState", "ResetArgs", "FinishArgs",
           "EPISODE_TOOLS", "MESSAGE_META_KEY", "SAME_TURN_META_KEY", "MAX_TOOL_NAME_CHARS", "ENV_NAME"]

#: The name the task API routes carry (`/healthcare_gym/splits`, ...).
ENV_NAME = "healthcare_gym"
#: Tools every episode has beside the task's: start one, end it (text answer or cut), read its score.
EPISODE_TOOLS = ("start_episode", "finish_episode", "episode_result")
#: `CallToolAction.metadata` key: the assistant text of the turn the call opens.
MESSAGE_META_KEY = "hcgym/message"
#: `CallToolAction.metadata` key: true adds the call to the open assistant turn instead of opening one.
SAME_TURN_META_KEY = "hcgym/same_turn"
#: The longest tool name a call may give (the MCP server's bound too).
MAX_TOOL_NAME_CHARS = 128


class HealthcareGymObservation(Observation):
    """What `reset` (and `start_episode`) returns: the episode and its prompt parts.

    `prompt` is the env's `PromptParts` (`system`, `policy`, `ticket`, `tools`, `image_path`,
    `system_prompt`); `messages` the first chat messages. The tools sit inside `prompt`, so OpenEnv's
    MCP client does not take this for a tool listing.
    """

    episode_id: str
    domain: str
    task_id: str
    split: str | None = None
    prompt: dict[str, Any] = Field(default_factory=dict)
    messages: list[dict[str, Any]] = Field(default_factory=list)


class HealthcareGymState(State):
    """The session's episode: which task, how far, and its score once ended."""

    domain: str | None = None
    task_id: str | None = None
    split: str | None = None
    done: bool = False
    reward: float | None = None
    reward_components: dict[str, float] = Field(default_factory=dict)
    end_reason: str | None = None


class ResetArgs(BaseModel):
    """What `reset` (or `start_episode`) accepts beside `seed` and `episode_id`: a task by id; or by
    `split` and `index` (the task API's order); or drawn from `split` (default the server's) with
    `seed`. `domain` defaults to the first served domain (a task id or index names its own)."""

    model_config = ConfigDict(extra="forbid")
    # Bounded so a hostile value is refused by its size, never echoed back whole.
    domain: str | None = Field(None, max_length=64)
    task_id: str | None = Field(None, max_length=256)
    split: str | None = Field(None, max_length=64)
    index: int | None = Field(None, ge=0, lt=2**63)
    seed: int | None = Field(None, ge=0, lt=2**63)
    episode_id: str | None = Field(None, max_length=128)


class FinishArgs(BaseModel):
    model_config = ConfigDict(extra="forbid")
    final_text: str | None = None
    reason: str | None = Field(None, max_length=64)
