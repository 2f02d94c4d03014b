"""The task schema and task-file loading.

A task is what the agent is asked (`ticket`), how it is graded (`evaluation_criteria`, and for
questions with a single right answer `correct_answer` with `answer_type`), and where it comes
from (`description.source`). Field names follow the reference implementation's files so those
files import (see `envs/converters/reference.py`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from envs.core.db import DataFileError, format_validation_error, read_json_file

AnswerType = Literal["choice", "exact", "numeric", "category", "free_text", "none"]
RewardBasis = Literal["ACTION", "NL_ASSERTION", "ANSWER", "DB", "RUBRIC"]


class TaskDescription(BaseModel):
    model_config = ConfigDict(extra="forbid")
    purpose: str | None = None
    difficulty: str | None = None
    source: str | None = None
    category: str | None = None
    task_type: str | None = None
    key_challenges: list[str] = Field(default_factory=list)
    provenance: dict[str, str] = Field(default_factory=dict)


class UserScenario(BaseModel):
    model_config = ConfigDict(extra="forbid")
    persona: str | None = None
    instructions: str | dict[str, Any] | None = None


class ExpectedAction(BaseModel):
    """A tool call the gold solution makes. It matches a logged call with the same name whose
    `compare_args` (all arguments when None) are equal after normalisation."""

    model_config = ConfigDict(extra="forbid")
    action_id: str | None = None
    name: str
    arguments: dict[str, Any] = Field(default_factory=dict)
    compare_args: list[str] | None = None
    info: str | None = None

    @property
    def compared_arguments(self) -> dict[str, Any]:
        keys = self.arguments.keys() if self.compare_args is None else self.compare_args
        return {k: self.arguments.get(k) for k in keys}


class RubricItem(BaseModel):
    """One rubric criterion (HealthBench style): positive points reward, negative penalise."""

    model_config = ConfigDict(extra="forbid")
    criterion: str
    points: float = 1.0
    kind: Literal["required_element", "required_tool", "forbidden_element"] = "required_element"
    tags: list[str] = Field(default_factory=list)


class EvaluationCriteria(BaseModel):
    model_config = ConfigDict(extra="forbid")
    actions: list[ExpectedAction] = Field(default_factory=list)
    nl_assertions: list[str] = Field(default_factory=list)
    rubric: list[RubricItem] = Field(default_factory=list)
    reward_basis: list[RewardBasis] = Field(default_factory=lambda: ["ACTION", "ANSWER"])
    expected_db_hash: str | None = None


class Task(BaseModel):
    """One task. `id` is stable: a content hash of the ticket and criteria when not given."""

    model_config = ConfigDict(extra="forbid")
    id: str = ""
    domain: str | None = None
    ticket: str = Field(min_length=1)
    description: TaskDescription = Field(default_factory=TaskDescription)
    user_scenario: UserScenario | None = None
    evaluation_criteria: EvaluationCriteria = Field(default_factory=EvaluationCriteria)
    options: dict[str, str] | None = None
    correct_answer: str | None = None
    answer_type: AnswerType = "none"
    answer_aliases: list[str] = Field(default_factory=list)
    answer_tolerance: float | None = Field(default=None, ge=0)
    answer_unit: str | None = None
    patient_id: str | None = None
    image_path: str | None = None
    emergency: str | None = None
    raw_question: str | None = None
    raw_answer: str | None = None
    metadata: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check_answer(self) -> "Task":
        if self.answer_type == "none" and self.correct_answer is not None:
            self.answer_type = "choice" if self.options else "exact"
        if self.answer_type == "choice":
            if not self.options:
                raise ValueError("answer_type 'choice' needs 'options'")
            if self.correct_answer is None or self.correct_answer not in self.options:
                raise ValueError(
                    f"correct_answer {self.correct_answer!r} is not one of the option letters {sorted(self.options)}"
                )
        if self.answer_type == "numeric" and self.correct_answer is not None:
            try:
                float(self.correct_answer)
            except ValueError:
                raise ValueError(f"numeric correct_answer {self.correct_answer!r} is not a number") from None
        if not self.id:
            self.id = stable_task_id(self)
        return self

    @property
    def has_gold_answer(self) -> bool:
        if self.answer_type in ("choice", "exact", "numeric", "category", "free_text"):
            return bool(self.correct_answer and self.correct_answer.strip())
        return False

    @property
    def is_gradeable(self) -> bool:
        """Gradeable = a gold answer, or expected actions / assertions / rubric to grade against."""
        crit = self.evaluation_criteria
        return self.has_gold_answer or bool(crit.actions or crit.nl_assertions or crit.rubric)


def stable_task_id(task: Task) -> str:
    payload = json.dumps(
        {"ticket": task.ticket, "criteria": task.evaluation_criteria.model_dump(mode="json"),
         "options": task.options, "answer": task.correct_answer},
        sort_keys=True, ensure_ascii=False,
    )
    return "task_" + hashlib.sha256(payload.encode("utf-8")).hexdigest()[:16]


def parse_tasks(raw: Any, *, source: str, domain: str | None = None) -> list[Task]:
    """Validate a list of task dicts; errors name the file, the task id (or index) and the field."""
    if isinstance(raw, dict) and "tasks" in raw:
        raw = raw["tasks"]
    if not isinstance(raw, list):
        raise DataFileError(f"{source}: expected a JSON list of tasks, got {type(raw).__name__}")
    tasks: list[Task] = []
    seen: dict[str, int] = {}
    problems: list[str] = []
    for index, item in enumerate(raw):
        label = f"task #{index}"
        if isinstance(item, dict) and item.get("id"):
            label = f"task {item['id']!r}"
        if not isinstance(item, dict):
            problems.append(f"{source} [{label}]: expected an object, got {type(item).__name__}")
            continue
        try:
            task = Task.model_validate({**item, "domain": item.get("domain") or domain})
        except ValidationError as exc:
            problems.append(format_validation_error(exc, source=source, item=label))
            continue
        if task.id in seen:
            problems.append(f"{source} [{label}]: duplicate task id (first at index {seen[task.id]})")
            continue
        seen[task.id] = index
        tasks.append(task)
    if problems:
        raise DataFileError("\n".join(problems))
    return tasks


def load_tasks(path: str | Path, *, domain: str | None = None) -> list[Task]:
    path = Path(path)
    if not path.exists():
        raise DataFileError(f"{path}: task file not found (run `hcgym data build`)")
    raw = read_json_file(path, "task file")
    return parse_tasks(raw, source=str(path), domain=domain)


def dump_tasks(tasks: list[Task], path: str | Path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    data = [t.model_dump(mode="json", exclude_defaults=True) | {"id": t.id} for t in tasks]
    Path(path).write_text(json.dumps(data, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")


def without_repeated_tickets(groups: dict[str, list[Task]], authored: list[Task]) -> dict[str, list[Task]]:
    """`groups` of generated tasks without those whose ticket (case and white space folded) repeats an
    authored task's or an earlier generated one's: the same question in two splits would leak a held-out
    task into training."""
    seen = {" ".join(t.ticket.lower().split()) for t in authored}
    kept: dict[str, list[Task]] = {}
    for group, items in groups.items():
        kept[group] = []
        for task in items:
            key = " ".join(task.ticket.lower().split())
            if key not in seen:
                seen.add(key)
                kept[group].append(task)
    return kept


def load_split(path: str | Path) -> dict[str, list[str]]:
    """`split_tasks.json`: {"train": [ids], "test": [ids], ...}."""
    path = Path(path)
    if not path.exists():
        raise DataFileError(f"{path}: split file not found (run `hcgym data build`)")
    raw = read_json_file(path, "split file")
    if not isinstance(raw, dict):
        raise DataFileError(f"{path}: expected {{split name: [task ids]}}, got a JSON {type(raw).__name__}")
    for split, ids in raw.items():
        if not isinstance(ids, list):
            raise DataFileError(f"{path} split {split!r}: expected a list of task ids, got {type(ids).__name__}")
        for index, task_id in enumerate(ids):
            if not isinstance(task_id, str):
                raise DataFileError(f"{path} split {split!r} entry #{index}: expected a task id string, "
                                    f"got {type(task_id).__name__}")
    return raw
