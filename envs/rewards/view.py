"""A read-only view of one episode that every reward dimension shares.

It indexes the trajectory once (tool calls with their turn, the agent's texts, what the agent
was shown) and answers the questions the dimensions ask: what was the final answer, is this a
patient-management task or a knowledge question, which calls belong to which tool family.
Properties are computed lazily so a multiple-choice episode pays only for what it uses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

from envs.core.task import Task
from envs.core.trajectory import ToolCallRecord, Trajectory
from envs.rewards.conventions import DEFAULT_CONVENTIONS, ToolConventions

TaskKind = Literal["qa", "management"]

#: Expected-action families that make a task a patient-management task.
_CLINICAL_FAMILIES = frozenset({
    "prescribing", "place_order", "escalation", "follow_up", "confirmatory", "diagnosis", "discharge",
    "triage", "discontinue", "invasive",
})
_MANAGEMENT_TASK_TYPES = ("management", "treatment", "prescrib", "triage", "workup", "work-up", "disposition",
                          "diagnosis", "diagnostic", "emergency", "patient")


@dataclass(frozen=True)
class CallRef:
    """A tool call with its place in the episode."""

    turn: int                 # TurnRecord.index
    order: int                # position among all calls of the episode
    call: ToolCallRecord
    families: frozenset[str]

    @property
    def name(self) -> str:
        return self.call.name

    @property
    def args(self) -> dict[str, Any]:
        return self.call.arguments if isinstance(self.call.arguments, dict) else {}


def task_kind(task: Task, conventions: ToolConventions = DEFAULT_CONVENTIONS) -> TaskKind:
    """"management" for patient-management tasks, "qa" for knowledge questions.

    `task.metadata["task_kind"]` decides when set. Otherwise a task with a patient (`patient_id`)
    or a clinical expected action (prescribe, order, escalate, diagnose, triage, discharge, follow
    up) is "management", even when its final question is multiple choice; any other
    multiple-choice task is "qa"; a task with an emergency or a management
    `description.task_type` is "management"; anything else is "qa".
    """
    declared = task.metadata.get("task_kind") if isinstance(task.metadata, dict) else None
    if declared in ("qa", "management"):
        return declared
    if task.patient_id:
        return "management"
    for action in task.evaluation_criteria.actions:
        if conventions.families(action.name) & _CLINICAL_FAMILIES:
            return "management"
    if task.answer_type == "choice":
        return "qa"
    if task.emergency:
        return "management"
    task_type = (task.description.task_type or "").lower()
    if task_type and any(word in task_type for word in _MANAGEMENT_TASK_TYPES):
        return "management"
    return "qa"


class EpisodeView:
    """The trajectory and task, indexed for grading."""

    def __init__(self, trajectory: Trajectory, task: Task, conventions: ToolConventions | None = None) -> None:
        self.trajectory = trajectory
        self.task = task
        self.conv = conventions or DEFAULT_CONVENTIONS
        calls: list[CallRef] = []
        for turn in trajectory.turns:
            for call in turn.tool_calls:
                calls.append(CallRef(turn.index, len(calls), call, self.conv.families(call.name)))
        self.calls = calls

    # -- calls ---------------------------------------------------------------------------------
    def family(self, family: str, *, ok_only: bool = False) -> list[CallRef]:
        return [c for c in self.calls if family in c.families and (c.call.ok or not ok_only)]

    @cached_property
    def work_calls(self) -> list[CallRef]:
        """Calls other than submit: what the process score counts."""
        return [c for c in self.calls if not self._is_submit(c)]

    def _is_submit(self, ref: CallRef) -> bool:
        return ref.call.submit or "submit" in ref.families

    @cached_property
    def submit_ref(self) -> CallRef | None:
        subs = [c for c in self.calls if self._is_submit(c)]
        oks = [c for c in subs if c.call.ok]
        return (oks or subs or [None])[-1]

    # -- texts ---------------------------------------------------------------------------------
    @cached_property
    def answer_text(self) -> str:
        """The committed answer: `submitted_answer`, else the submit call's `answer`, else the
        last turn's free text (a chat answer), except in a truncated episode: an agent cut off
        at the turn or token limit committed to nothing."""
        if self.trajectory.submitted_answer is not None:
            return str(self.trajectory.submitted_answer)
        ref = self.submit_ref
        if ref is not None:
            value = ref.args.get("answer")
            if value is not None:
                return value if isinstance(value, str) else json.dumps(value, ensure_ascii=False)
        turns = self.trajectory.turns
        if self.trajectory.truncated or not turns:
            return ""
        return turns[-1].message

    @cached_property
    def submit_reasoning(self) -> str:
        ref = self.submit_ref
        if ref is None:
            return ""
        value = ref.args.get("reasoning") or ref.args.get("rationale") or ref.args.get("explanation")
        return str(value) if value else ""

    @cached_property
    def final_text(self) -> str:
        """The conclusion: answer, its reasoning, and the final turn's free text."""
        parts = [self.answer_text, self.submit_reasoning]
        turns = self.trajectory.turns
        if turns and turns[-1].message and turns[-1].message not in parts:
            parts.append(turns[-1].message)
        return "\n".join(p for p in parts if p)

    @cached_property
    def turn_texts(self) -> list[tuple[int, str]]:
        """Per turn, what the agent *said*: free text, `think` thoughts, submit reasoning."""
        out: list[tuple[int, str]] = []
        for turn in self.trajectory.turns:
            parts = [turn.message] if turn.message else []
            for call in turn.tool_calls:
                args = call.arguments if isinstance(call.arguments, dict) else {}
                if "think" in self.conv.families(call.name):
                    parts.extend(str(v) for v in args.values() if isinstance(v, str))
                elif call.submit or "submit" in self.conv.families(call.name):
                    for key in ("reasoning", "rationale", "explanation"):
                        if isinstance(args.get(key), str):
                            parts.append(args[key])
            out.append((turn.index, "\n".join(parts)))
        return out

    @cached_property
    def said_text(self) -> str:
        """All the agent's free text and answer, one string."""
        return "\n".join([t for _, t in self.turn_texts if t] + [self.answer_text])

    @cached_property
    def said_lower(self) -> str:
        return self.said_text.lower()

    @cached_property
    def shown_lower(self) -> str:
        """Everything the environment showed the agent (lower case): the task, the first
        observation, tool results (not the submit echo) and messages of turns without calls."""
        traj = self.trajectory
        parts = [self.task_text_lower, traj.first_observation or ""]
        for turn in traj.turns:
            if not turn.tool_calls:
                parts.append(turn.observation or "")
            for call in turn.tool_calls:
                # the submit tool echoes the answer back: that is not something the agent was shown
                if call.result and not (call.submit or "submit" in self.conv.families(call.name)):
                    parts.append(call.result)
        return "\n".join(parts).lower()

    @cached_property
    def task_text_lower(self) -> str:
        task = self.task
        parts = [task.ticket, task.raw_question or ""]
        if task.options:
            parts.extend(task.options.values())
        return "\n".join(parts).lower()

    # -- task ----------------------------------------------------------------------------------
    @cached_property
    def kind(self) -> TaskKind:
        return task_kind(self.task, self.conv)

    @property
    def is_management(self) -> bool:
        return self.kind == "management"

    @cached_property
    def patient_id(self) -> str | None:
        if self.task.patient_id:
            return self.task.patient_id
        for ref in self.calls:
            value = self.conv.first_arg(ref.args, self.conv.patient_args)
            if isinstance(value, (str, int)):
                return str(value)
        return None

    def render_calls(self, limit: int = 400) -> str:
        """Tool calls as `name(k=v, ...)` lines, for text graders."""
        lines = []
        for ref in self.calls:
            args = ", ".join(f"{k}={v!r}" for k, v in ref.args.items())
            status = "" if ref.call.ok else "  [failed]"
            lines.append(f"{ref.name}({args}){status}"[:limit])
        return "\n".join(lines)
