"""Builders for reward tests: trajectories straight from the pydantic records."""

from __future__ import annotations

from typing import Any

from envs.core.task import Task
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord

MC_OPTIONS = {"A": "Vitamin A", "B": "Vitamin C", "C": "Iron", "D": "Vitamin D"}


def call(name: str, args: dict[str, Any] | None = None, *, result: str | None = "ok", error: str | None = None,
         fmt: str = "hermes") -> ToolCallRecord:
    return ToolCallRecord(name=name, arguments=args or {}, result=None if error else result, error=error,
                          format=fmt, submit=name == "submit_answer")


def turn(*calls: ToolCallRecord, message: str = "", fmt: str | None = None, parse_errors: list[str] | None = None) -> dict:
    return {"calls": list(calls), "message": message, "fmt": fmt, "parse_errors": parse_errors or []}


def episode(task: Task, *turns: dict, answer: str | None = None, reasoning: str = "", submit: bool = True,
            submit_fmt: str = "hermes", truncated: bool = False, **fields: Any) -> Trajectory:
    """Turns as given, then (unless submit=False) a final turn calling submit_answer(answer)."""
    records: list[TurnRecord] = []
    specs = list(turns)
    if submit and answer is not None:
        args = {"answer": answer} | ({"reasoning": reasoning} if reasoning else {})
        specs.append(turn(call("submit_answer", args, result=f"Answer submitted: {answer}", fmt=submit_fmt)))
    for i, spec in enumerate(specs):
        calls = spec["calls"]
        fmt = spec["fmt"] or (calls[0].format if calls else "text")
        records.append(TurnRecord(index=i, action=spec["message"] or "<tool_call>...</tool_call>", message=spec["message"],
                                  action_format=fmt, tool_calls=calls, parse_errors=spec["parse_errors"],
                                  observation="\n".join(c.result or "" for c in calls)))
    return Trajectory(task_id=task.id, domain=task.domain or "test", turns=records,
                      submitted_answer=answer if (submit and answer is not None) else None,
                      terminated=submit and answer is not None, truncated=truncated, first_observation=task.ticket, **fields)


def mc_task(correct: str = "D", **kw: Any) -> Task:
    return Task(ticket="Which deficiency causes rickets in children?", options=dict(MC_OPTIONS), correct_answer=correct,
                domain="medical_qa", **kw)


def patient_task(ticket: str = "Manage this patient.", **kw: Any) -> Task:
    kw.setdefault("patient_id", "P1")
    kw.setdefault("domain", "ward")
    return Task(ticket=ticket, **kw)


