"""The task validator behind `hcgym tasks validate`.

A task ships only if it
  1. names only tools that exist in its domain, with arguments valid for their signatures;
  2. has a gradeable gold answer (or a rubric for long-form tasks);
  3. replays: in a fresh environment its expected actions run without error, then the gold answer
     is submitted, and the episode earns full action coverage and full accuracy;
  4. is about a coherent patient: every rule of `envs.coherence` that applies to its domain holds for
     the task and its record (sex and name, age and occupation, gestation and history, ...).
The reference implementation shipped hundreds of tasks naming tools that did not exist and half
its rows without a gradeable answer; this is the check that prevents it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from envs.core.contamination import Leak, find_leaks
from envs.core.task import Task
from envs.core.tools import ToolArgumentError


@dataclass
class TaskReport:
    task_id: str
    domain: str
    problems: list[str] = field(default_factory=list)
    reward_components: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems


def gold_answer_text(task: Task) -> str | None:
    """What a perfect agent submits."""
    return task.correct_answer


def gold_actions_as_text(task: Task) -> list[str]:
    """One Hermes-style action per expected tool call, in order."""
    return [
        "<tool_call>" + json.dumps({"name": a.name, "arguments": a.arguments}, ensure_ascii=False) + "</tool_call>"
        for a in task.evaluation_criteria.actions
    ]


def gold_replay(task: Task, domain: str, max_turns: int | None = None) -> tuple[Any, dict[str, Any]]:
    """Run the gold solution in a fresh environment; returns (trajectory, final info)."""
    from envs.env import HealthcareGymEnv

    actions = gold_actions_as_text(task)
    turns = max_turns or len(actions) + 2
    env = HealthcareGymEnv(domain=domain, max_turns=turns)
    # the task given is the one replayed, whether or not the domain has loaded it yet (`hcgym tasks import
    # --replay` checks tasks before they are written)
    env._tasks_by_id[task.id] = task
    env.reset(seed=0, options={"task_id": task.id})
    info: dict[str, Any] = {}
    for action in actions:
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    if not env._done:
        answer = gold_answer_text(task) or ""
        # a task's reference rationale (metadata.gold_reasoning: the recommendation its ticket asks for in
        # the reasoning) is part of the gold submission, so NL assertions on it can be met by the gold
        reasoning = str(task.metadata.get("gold_reasoning") or "gold replay")
        submit = {"name": "submit_answer", "arguments": {"answer": answer, "reasoning": reasoning}}
        _, _, _, _, info = env.step("<tool_call>" + json.dumps(submit, ensure_ascii=False) + "</tool_call>")
    return env.trajectory(), info


# Why a task is rejected at import (`hcgym tasks import`), as the per-domain table names them.
UNKNOWN_TOOL = "unknown tool"
EMPTY_REQUIRED = "empty required arguments"
BAD_ARGUMENTS = "invalid arguments"
NO_GOLD = "no gold answer"
NOTHING_TO_GRADE = "nothing to grade"
REPLAY_FAILS = "gold replay fails"


def static_problems(task: Task, domain: str, toolkit_definitions: dict) -> list[tuple[str, str]]:
    """(reason, message) for everything that makes a task ungradeable without running it: expected actions
    naming tools the domain lacks, arguments that do not fit the tool (required ones missing or empty), no
    gold answer. Reasons are the constants above; `hcgym tasks import` counts them per domain."""
    problems: list[tuple[str, str]] = []
    crit = task.evaluation_criteria
    for index, action in enumerate(crit.actions):
        where = f"expected action #{index} {action.name!r}"
        definition = toolkit_definitions.get(action.name)
        if definition is None:
            problems.append((UNKNOWN_TOOL, f"{where}: no such tool in domain {domain!r}"))
            continue
        try:
            definition.validate(action.arguments)
        except ToolArgumentError as exc:
            reason = EMPTY_REQUIRED if "missing required argument" in str(exc) else BAD_ARGUMENTS
            problems.append((reason, f"{where}: {exc}"))
        else:
            required = definition.parameters.get("required", [])
            empty = [k for k in required if action.arguments.get(k) in ("", None, [], {})]
            if empty:
                problems.append((EMPTY_REQUIRED, f"{where}: required argument(s) {empty} are empty"))
        for key in action.compare_args or []:
            if key not in action.arguments:
                message = f"{where}: compare_args names {key!r}, which is not among its arguments"
                problems.append((BAD_ARGUMENTS, message))
    if not (task.has_gold_answer or crit.rubric):
        reason = NO_GOLD if (crit.actions or crit.nl_assertions) else NOTHING_TO_GRADE
        problems.append((reason, "no gradeable gold answer (correct_answer with answer_type, or a rubric)"))
    return problems


def validate_task(task: Task, domain: str, toolkit_definitions: dict, *, replay: bool = True) -> TaskReport:
    report = TaskReport(task_id=task.id, domain=domain)
    report.problems.extend(message for _, message in static_problems(task, domain, toolkit_definitions))
    if report.problems or not replay:
        return report
    trajectory, info = gold_replay(task, domain)
    for turn in trajectory.turns:
        for call in turn.tool_calls:
            if not call.ok:
                report.problems.append(f"gold replay: call {call.name!r} failed: {call.error}")
    details = info.get("reward_breakdown") or {}
    report.reward_components = info.get("reward_components", {})
    coverage = (details.get("details") or {}).get("process", {}).get("coverage")
    if task.evaluation_criteria.actions and coverage is not None and coverage < 1.0 - 1e-9:
        report.problems.append(f"gold replay: action coverage {coverage:.3f} < 1")
    accuracy = report.reward_components.get("accuracy")
    if task.has_gold_answer and (accuracy is None or accuracy < 1.0 - 1e-9):
        report.problems.append(f"gold replay: accuracy {accuracy} < 1 for gold answer {task.correct_answer!r}")
    # Accuracy reads the final DB hash only for a task without a gold answer; a task that has both must
    # still leave the database in its expected state.
    expected_hash = task.evaluation_criteria.expected_db_hash
    if expected_hash and trajectory.db_hash_final != expected_hash:
        report.problems.append(f"gold replay: final DB hash {trajectory.db_hash_final} != expected_db_hash {expected_hash}")
    return report


def validate_domain(domain: str, *, replay: bool = True, limit: int | None = None) -> list[TaskReport]:
    from envs import registry

    tasks = registry.get_tasks(domain)
    definitions = registry.get_environment(domain).toolkit.definitions
    # Domains whose tools depend on the task (pathways build their phase toolkits at reset) say
    # which tools each task may use.
    per_task = getattr(registry.domain_module(domain), "task_tool_definitions", None)
    from envs.coherence import check_tasks

    chosen = tasks[:limit] if limit else tasks
    incoherent: dict[str, list[str]] = {}
    for violation in check_tasks(domain, chosen):
        incoherent.setdefault(violation.task_id, []).append(str(violation))
    reports = []
    for task in chosen:
        report = validate_task(task, domain, per_task(task) if per_task else definitions, replay=replay)
        report.problems.extend(incoherent.get(task.id, []))
        reports.append(report)
    return reports


def check_domain_contamination(domain: str, threshold: float = 0.8) -> list[Leak]:
    """Leaks between a registered domain's train split and its held-out splits: an id in both, or a
    held-out task whose text nearly repeats a training task's (see envs.core.contamination)."""
    from envs import registry

    splits = registry.get_splits(domain)
    by_id = {t.id: t for t in registry.get_tasks(domain)}
    train = [by_id[i] for i in splits.get("train", [])]
    held = [by_id[i] for name in ("test", "validation") for i in splits.get(name, [])]
    overlap = set(splits.get("train", [])) & {t.id for t in held}
    leaks = [Leak(i, i, "same id", 1.0) for i in sorted(overlap)]
    return leaks + find_leaks(train, [t for t in held if t.id not in overlap], threshold)
