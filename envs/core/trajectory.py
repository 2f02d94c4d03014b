"""Episode records: what the agent did, turn by turn, and how it was scored.

The record is the contract between the environment, the reward (`envs.rewards.score_episode`
reads it) and training (trajectories are stored and replayed). Parquet files hold one row per
episode: scalar columns for filtering, JSON columns for the nested parts, so a round trip is
lossless.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

ActionFormat = Literal["json", "openai", "hermes", "fenced", "function", "text", "empty"]
#: How a tool call failed, for rewards and analysis without parsing messages:
#: "unknown_tool" (no such tool, or not in this phase), "invalid_arguments" (the arguments do not fit
#: the signature: missing, unknown, wrong type), "tool_error" (the tool refused: a `ToolError`, e.g.
#: an unknown patient), "input_error" (a value the tool cannot compute with, e.g. a calculator
#: argument out of range), "internal_error" (an unexpected exception in the tool's code).
ErrorKind = Literal["unknown_tool", "invalid_arguments", "tool_error", "input_error", "internal_error"]


class ToolCallRecord(BaseModel):
    """One executed (or rejected) tool call."""

    model_config = ConfigDict(extra="forbid")
    name: str
    arguments: dict[str, Any] = Field(default_factory=dict)
    result: str | None = None          # the observation text returned to the agent
    error: str | None = None           # why the call failed (unknown tool, bad argument, tool error)
    error_kind: ErrorKind | None = None  # what kind of failure `error` is; None when the call succeeded
    tool_type: str | None = None       # read / write / think / generic
    format: ActionFormat = "json"      # how the agent wrote the call
    submit: bool = False
    duration_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None


class TurnRecord(BaseModel):
    """One agent action and the environment's answer to it."""

    model_config = ConfigDict(extra="forbid")
    index: int
    action: str                         # the raw text the agent sent
    message: str = ""                   # the agent's free text outside tool calls
    action_format: ActionFormat = "text"
    tool_calls: list[ToolCallRecord] = Field(default_factory=list)
    parse_errors: list[str] = Field(default_factory=list)
    observation: str = ""
    duration_s: float = 0.0


class Trajectory(BaseModel):
    """A whole episode."""

    model_config = ConfigDict(extra="forbid")
    task_id: str
    domain: str
    seed: int | None = None
    system_prompt: str = ""
    first_observation: str = ""
    turns: list[TurnRecord] = Field(default_factory=list)
    messages: list[dict[str, Any]] = Field(default_factory=list)  # chat-format transcript
    submitted_answer: str | None = None
    terminated: bool = False
    truncated: bool = False
    reward: float | None = None
    reward_components: dict[str, float] = Field(default_factory=dict)
    reward_details: dict[str, Any] = Field(default_factory=dict)
    db_hash_initial: str | None = None
    db_hash_final: str | None = None
    image_path: str | None = None
    metadata: dict[str, Any] = Field(default_factory=dict)

    # -- convenient views for graders ---------------------------------------------------------
    @property
    def tool_calls(self) -> list[ToolCallRecord]:
        return [call for turn in self.turns for call in turn.tool_calls]

    @property
    def successful_calls(self) -> list[ToolCallRecord]:
        return [call for call in self.tool_calls if call.ok]

    @property
    def final_text(self) -> str:
        """The agent's last words: the submitted answer, else the last turn's message."""
        if self.submitted_answer is not None:
            return self.submitted_answer
        return self.turns[-1].message if self.turns else ""

    @property
    def agent_text(self) -> str:
        """Everything the agent wrote, in order (free text and tool arguments)."""
        return "\n".join(turn.action for turn in self.turns)


_JSON_COLUMNS = ("turns", "messages", "reward_components", "reward_details", "metadata")


def trajectories_to_table(records: list[Trajectory]):
    import pyarrow as pa

    rows: dict[str, list] = {name: [] for name in Trajectory.model_fields}
    for record in records:
        data = record.model_dump(mode="json")
        for name in rows:
            value = data[name]
            rows[name].append(json.dumps(value, ensure_ascii=False) if name in _JSON_COLUMNS else value)
    schema = pa.schema([
        ("task_id", pa.string()), ("domain", pa.string()), ("seed", pa.int64()),
        ("system_prompt", pa.string()), ("first_observation", pa.string()),
        ("turns", pa.string()), ("messages", pa.string()), ("submitted_answer", pa.string()),
        ("terminated", pa.bool_()), ("truncated", pa.bool_()), ("reward", pa.float64()),
        ("reward_components", pa.string()), ("reward_details", pa.string()),
        ("db_hash_initial", pa.string()), ("db_hash_final", pa.string()), ("image_path", pa.string()),
        ("metadata", pa.string()),
    ])
    return pa.table({f.name: pa.array(rows[f.name], type=f.type) for f in schema}, schema=schema)


def write_trajectories(records: list[Trajectory], path: str | Path) -> None:
    """Write episode records to one Parquet file."""
    import pyarrow.parquet as pq

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(trajectories_to_table(records), str(path))


def read_trajectories(path: str | Path) -> list[Trajectory]:
    """Read records written by :func:`write_trajectories`."""
    import pyarrow.parquet as pq

    table = pq.read_table(str(path))
    out = []
    for row in table.to_pylist():
        for name in _JSON_COLUMNS:
            row[name] = json.loads(row[name])
        out.append(Trajectory.model_validate(row))
    return out
