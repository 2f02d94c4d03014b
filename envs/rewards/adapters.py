"""Adapters: the same reward for trainers that hand over text instead of a Trajectory.

* TRL (`GRPOTrainer(reward_funcs=[trl_reward])`): `reward(prompts, completions, **kwargs)`
  returns one float per completion. Completions may be strings or conversations (lists of
  message dicts, assistant and tool messages). The task comes from the dataset columns TRL
  passes as keyword lists: a `task` column (a Task dict or JSON), or `correct_answer` (or
  `answer`/`solution`/`ground_truth`) with optional `options`, `answer_type`, `question`.
* verl (`custom_reward_function.path=envs/rewards/adapters.py`, `name=compute_score`):
  `compute_score(data_source, solution_str, ground_truth, extra_info)` returns a dict with
  `score` (the total), `acc` (1.0 when correct) and the dimensions, as verl's reward managers
  expect. The task comes from `extra_info["task"]`, a JSON task in `ground_truth`, or
  `ground_truth` as the gold answer with `extra_info` options/answer_type/question.

Text is parsed into tool calls with the environment's own parser (`envs.core.actions`), so
format scores match the environment's. Tools are not executed: results are empty unless the
conversation includes tool messages.
"""

from __future__ import annotations

import json
from typing import Any, Callable, Iterable

from envs.core.actions import parse_action
from envs.core.task import Task
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord
from envs.rewards.dimensions import ALWAYS_REPORTED
from envs.rewards.score import score_episode
from envs.rewards.types import RewardWeights

_ANSWER_KEYS = ("correct_answer", "answer", "solution", "ground_truth", "gold")
_QUESTION_KEYS = ("question", "ticket", "problem", "raw_question")
_BASE_TOOLS = frozenset({"submit_answer", "think"})


def _maybe_json(value: Any) -> Any:
    if isinstance(value, str) and value.strip()[:1] in ("{", "["):
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    return value


def _prompt_text(prompt: Any) -> str:
    if isinstance(prompt, str):
        return prompt
    if isinstance(prompt, list):
        users = [m.get("content", "") for m in prompt if isinstance(m, dict) and m.get("role") == "user"]
        if users:
            return str(users[-1])
        return "\n".join(str(m.get("content", "")) for m in prompt if isinstance(m, dict))
    return str(prompt or "")


def task_from_fields(row: dict[str, Any], prompt_text: str = "") -> Task:
    """A Task from a dataset row: its `task` field, or gold answer + options + question."""
    raw_task = _maybe_json(row.get("task"))
    if isinstance(raw_task, Task):
        return raw_task
    if isinstance(raw_task, dict):
        return Task.model_validate(raw_task)
    answer = next((row[k] for k in _ANSWER_KEYS if row.get(k) not in (None, "")), None)
    answer = _maybe_json(answer)
    if isinstance(answer, dict):  # a JSON task given as the ground truth
        return Task.model_validate(answer)
    options = _maybe_json(row.get("options"))
    if isinstance(options, list):
        options = {chr(ord("A") + i): str(o) for i, o in enumerate(options)}
    question = next((str(row[k]) for k in _QUESTION_KEYS if row.get(k)), "") or prompt_text or "(no question)"
    fields: dict[str, Any] = {"ticket": question, "options": options or None,
                              "correct_answer": None if answer is None else str(answer).strip()}
    for key in ("answer_type", "answer_aliases", "answer_tolerance", "answer_unit", "patient_id", "emergency", "domain"):
        if row.get(key) not in (None, ""):
            fields[key] = _maybe_json(row[key])
    try:
        return Task.model_validate(fields)
    except ValueError:
        # e.g. a gold answer that is not an option letter: grade it as an exact answer
        fields["answer_type"] = "exact"
        return Task.model_validate(fields)


def completion_to_trajectory(completion: Any, task: Task, tool_names: Iterable[str] = (), *,
                             domain: str = "trainer", truncated: bool = False) -> Trajectory:
    """One completion (a string, or a list of assistant/tool messages) as a Trajectory."""
    names = set(tool_names) | _BASE_TOOLS
    messages = [{"role": "assistant", "content": completion}] if isinstance(completion, str) else list(completion or [])
    turns: list[TurnRecord] = []
    submitted: str | None = None
    pending: list[ToolCallRecord] = []
    for message in messages:
        if not isinstance(message, dict):
            continue
        role, content = message.get("role", "assistant"), message.get("content") or ""
        if not isinstance(content, str):
            content = json.dumps(content, ensure_ascii=False)
        if role == "tool":
            target = next((c for c in pending if c.result is None and c.error is None), None)
            if target is not None:
                target.result = content
            if turns:
                turns[-1].observation += content
            continue
        if role != "assistant":
            continue
        native = message.get("tool_calls")
        if native:
            parsed = parse_action(json.dumps({"tool_calls": native}), names)
            parsed.message = content
        else:
            parsed = parse_action(content, names)
        calls = []
        for call in parsed.calls:
            args = call.arguments if isinstance(call.arguments, dict) else {}
            record = ToolCallRecord(name=call.name, arguments=args, format=call.format,  # type: ignore[arg-type]
                                    submit=call.name == "submit_answer",
                                    error=None if isinstance(call.arguments, dict) else f"tool {call.name!r}: arguments must be a JSON object")
            calls.append(record)
            if record.submit and submitted is None:
                submitted = str(args.get("answer", ""))
        pending = calls
        turns.append(TurnRecord(index=len(turns), action=content, message=parsed.message,
                                action_format=parsed.format, tool_calls=calls, parse_errors=parsed.errors))  # type: ignore[arg-type]
    return Trajectory(task_id=task.id, domain=domain, turns=turns, submitted_answer=submitted,
                      terminated=submitted is not None, truncated=truncated,
                      first_observation=task.ticket)


def make_trl_reward(weights: RewardWeights | dict | None = None, context: Any = None, *,
                    tool_names: Iterable[str] = (), grader: Any = None,
                    name: str = "healthcare_gym_reward") -> Callable[..., list[float]]:
    """A TRL reward function scoring each completion with `score_episode`."""
    names = tuple(tool_names)

    def reward(prompts: list[Any], completions: list[Any], **kwargs: Any) -> list[float]:
        out: list[float] = []
        columns = {k: v for k, v in kwargs.items() if isinstance(v, (list, tuple)) and len(v) == len(completions)}
        for i, completion in enumerate(completions):
            row = {k: v[i] for k, v in columns.items()}
            task = task_from_fields(row, _prompt_text(prompts[i] if i < len(prompts) else ""))
            trajectory = completion_to_trajectory(completion, task, names)
            out.append(float(score_episode(trajectory, task, weights, context, grader=grader).total))
        return out

    reward.__name__ = name
    reward.__qualname__ = name
    return reward


trl_reward = make_trl_reward()

#: verl needs the same keys for every sample: the always-reported dimensions and the penalty.
_VERL_KEYS = ALWAYS_REPORTED + ("safety_penalty",)


def compute_score(data_source: str, solution_str: str, ground_truth: Any, extra_info: dict[str, Any] | None = None,
                  **kwargs: Any) -> dict[str, float]:
    """verl custom reward: `{"score": total, "acc": 0/1, <dimensions>}` for one response."""
    extra = dict(extra_info or {})
    row = {**extra, "ground_truth": ground_truth}
    if "task" not in extra and isinstance(_maybe_json(ground_truth), dict):
        row["task"] = _maybe_json(ground_truth)
    task = task_from_fields(row)
    trajectory = completion_to_trajectory(solution_str, task, extra.get("tool_names", ()), domain=str(data_source or "verl"))
    breakdown = score_episode(trajectory, task, extra.get("reward_weights"))
    components = breakdown.components()
    result = {"score": float(breakdown.total), "acc": 1.0 if breakdown.is_correct else 0.0}
    result.update({k: float(components.get(k, 0.0)) for k in _VERL_KEYS})
    return result
