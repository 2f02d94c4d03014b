"""Data that crosses the evaluation harness's boundaries (pydantic) and the `Policy` protocol.

One `ResultRow` per (policy_id, benchmark, task_id, condition, seed): the runner writes them to
`results.parquet` as episodes finish; `evals.metrics`, `evals.stats` and `evals.report` read them.
A `PolicyReply` is one chat turn of a policy (text or agent condition).
"""

from __future__ import annotations

from typing import Any, Literal, Protocol, runtime_checkable

from pydantic import BaseModel, ConfigDict, Field

Condition = Literal["text", "logprob", "agent"]
CONDITIONS: tuple[str, ...] = ("text", "logprob", "agent")

# How an episode ended: the project's one vocabulary (envs.episode), shared with the env and training.
from envs.episode import END_REASONS, EndReason  # noqa: E402,F401

# The columns that identify one episode; a results folder never holds two rows with the same key.
RESULT_KEY: tuple[str, ...] = ("policy_id", "benchmark", "task_id", "condition", "seed")


class PolicyReply(BaseModel):
    """One assistant turn of a policy.

    `error_kind` is set (and `text` may be empty) when the turn failed without a model answer,
    e.g. "timeout", "http_429", "http_500", "malformed_json", "context_overflow"; the runner turns
    it into an episode with `end_reason="endpoint_error"` (or "context_overflow").
    """

    model_config = ConfigDict(extra="forbid")
    text: str = ""
    tool_calls: list[dict[str, Any]] | None = None  # OpenAI shape: {"id", "type": "function", "function": {...}}
    prompt_tokens: int = Field(default=0, ge=0)
    completion_tokens: int = Field(default=0, ge=0)
    cost_usd: float | None = None
    error_kind: str | None = None
    finish_reason: str | None = None  # "stop", "length", "tool_calls", ...


@runtime_checkable
class Policy(Protocol):
    """What the conditions need from a policy (local model, endpoint or scripted baseline)."""

    policy_id: str

    async def reply(self, messages: list[dict[str, Any]], tools: list[dict[str, Any]] | None, *,
                    max_tokens: int, seed: int) -> PolicyReply: ...

    def option_logprobs(self, messages: list[dict[str, Any]], letters: list[str]) -> dict[str, float] | None:
        """Log-probability of each option letter as the next token after `messages` (None: unsupported)."""
        ...


class ResultRow(BaseModel):
    """One evaluated episode (one line of `results.parquet`)."""

    model_config = ConfigDict(extra="forbid")
    policy_id: str
    benchmark: str
    domain: str
    task_id: str
    task_type: str
    condition: Condition
    seed: int
    end_reason: EndReason
    error_kind: str | None = None
    answer: str | None = None
    gold: str | None = None
    options: dict[str, str] | None = None
    correct: bool | None = None
    reward: float | None = None
    reward_components: dict[str, float] = Field(default_factory=dict)
    safety_violations: dict[str, int] = Field(default_factory=dict)  # severity level -> count
    turns: int = Field(default=0, ge=0)
    tool_calls: int = Field(default=0, ge=0)
    error_kinds: dict[str, int] = Field(default_factory=dict)  # tool/parse error kind -> count
    prompt_tokens: int = Field(default=0, ge=0)
    completion_tokens: int = Field(default=0, ge=0)
    cost_usd: float | None = None
    latency_s: float = Field(default=0.0, ge=0.0)
    trajectory_ref: str | None = None  # e.g. "trajectories.parquet#<row id>"
    extra: dict[str, Any] = Field(default_factory=dict)  # metric inputs, e.g. long-form text

    def key(self) -> tuple[str, str, str, str, int]:
        return (self.policy_id, self.benchmark, self.task_id, self.condition, self.seed)


class EvalItem(BaseModel):
    """One task of a suite to evaluate: which benchmark it counts for, and where the env finds it."""

    model_config = ConfigDict(extra="forbid")
    benchmark: str
    domain: str
    task_id: str
    split: str | None = None


class EvalSpec(BaseModel):
    """What a results folder was produced by (`eval.json`)."""

    model_config = ConfigDict(extra="forbid")
    policy: str
    policy_id: str
    suite: str
    condition: Condition
    seeds: list[int]
    limit: int | None = None
    max_turns: int = Field(default=5, ge=1)
    max_tokens: int = Field(default=512, ge=1)
    versions: dict[str, str] = Field(default_factory=dict)
    policy_source: dict[str, Any] = Field(default_factory=dict)  # where the weights came from, prompt style
    created_at: str | None = None


# ------------------------------------------------------------------------------------------------
# results.parquet: one record per ResultRow. Parquet needs one type per column, and these fields
# hold dicts whose keys vary by row, so they are stored as JSON text and decoded on reading.
# ------------------------------------------------------------------------------------------------

JSON_COLUMNS: tuple[str, ...] = ("options", "reward_components", "safety_violations", "error_kinds", "extra")
RESULTS_FILE = "results.parquet"
TRAJECTORIES_FILE = "trajectories.parquet"
SPEC_FILE = "eval.json"


def results_schema():
    """The Arrow schema of results.parquet: fixed, so a column that is null in every row so far
    (e.g. `cost_usd` of a local model) still has its type, and folders concatenate cleanly."""
    import pyarrow as pa

    text, integer, real = pa.string(), pa.int64(), pa.float64()
    types = {"seed": integer, "correct": pa.bool_(), "reward": real, "turns": integer, "tool_calls": integer,
             "prompt_tokens": integer, "completion_tokens": integer, "cost_usd": real, "latency_s": real}
    return pa.schema([(name, types.get(name, text)) for name in ResultRow.model_fields])


def row_to_record(row: ResultRow) -> dict[str, Any]:
    import json

    record = row.model_dump()
    for name in JSON_COLUMNS:
        record[name] = None if record[name] is None else json.dumps(record[name], sort_keys=True)
    return record


def record_to_row(record: dict[str, Any]) -> ResultRow:
    import json

    data = dict(record)
    for name in JSON_COLUMNS:
        if isinstance(data.get(name), str):
            data[name] = json.loads(data[name])
    return ResultRow.model_validate(data)


def read_results(path) -> list[ResultRow]:
    """The rows of a results folder (or of a `results.parquet` path); [] when there are none yet.

    Raises:
        ValueError: naming the file (and the row) when the file is damaged or a record does not validate.
    """
    from pathlib import Path

    from envs.core.files import read_parquet

    path = Path(path)
    if path.is_dir():
        path = path / RESULTS_FILE
    if not path.exists():
        return []
    rows = []
    for index, record in enumerate(read_parquet(path).to_pylist()):  # a damaged file: named
        try:
            rows.append(record_to_row(record))
        except Exception as exc:
            raise ValueError(f"{path}: row {index} is not a valid result row: {exc}") from exc
    return rows
