"""The guideline-written safety set: dangerous trajectories the detector must catch, safe ones it
must leave alone.

`tests/fixtures/safety/trajectories.json` holds the cases, each citing the guideline or US label
it follows. A case runs on a ward patient P1 whose allergies, medications and conditions are the
case's `patient`, through a `StaticSafetyContext` (the reward's built-in lexicon fills the gaps),
after a chart review; `calls` are the agent's tool calls and `answer` its submitted answer. A
dangerous case is detected when every pattern in `expect` is reported; a safe case is a false
alarm when any violation is reported. `bench/safety_detection.py` prints the same rates.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

import pytest
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from envs.core.task import Task
from envs.core.trajectory import Trajectory
from envs.rewards import PATTERNS, StaticSafetyContext, detect_violations
from tests.rewards.builders import call, episode, turn

SET_FILE = Path(__file__).resolve().parents[1] / "fixtures" / "safety" / "trajectories.json"
CHART = {"name": "get_patient_info", "arguments": {"patient_id": "P1"}, "result": '{"id": "P1"}'}


class CaseCall(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1)
    arguments: dict[str, Any] = Field(default_factory=dict)
    result: str = "ok"


class CasePatient(BaseModel):
    model_config = ConfigDict(extra="forbid")
    allergies: list[str] = Field(default_factory=list)
    medications: list[str] = Field(default_factory=list)
    conditions: list[str] = Field(default_factory=list)


class SafetyCase(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str = Field(min_length=1)
    kind: Literal["dangerous", "safe"]
    source: str = Field(min_length=10, description="the guideline or label section the case follows")
    ticket: str = Field(min_length=1)
    patient: CasePatient = Field(default_factory=CasePatient)
    calls: list[CaseCall] = Field(default_factory=list)
    answer: str
    expect: list[str] = Field(default_factory=list)
    emergency: str | None = None
    task: dict[str, Any] = Field(default_factory=dict)

    @field_validator("expect")
    @classmethod
    def _known_patterns(cls, value: list[str]) -> list[str]:
        unknown = [p for p in value if p not in PATTERNS]
        if unknown:
            raise ValueError(f"unknown safety pattern id(s) {unknown}")
        return value

    @model_validator(mode="after")
    def _expect_matches_kind(self) -> "SafetyCase":
        if self.kind == "dangerous" and not self.expect:
            raise ValueError("a dangerous case must name the pattern(s) it expects in 'expect'")
        if self.kind == "safe" and self.expect:
            raise ValueError("a safe case expects no violation: leave 'expect' empty")
        return self


class SafetyCaseError(ValueError):
    """A malformed case file; the message names the file, the case and the field."""


def load_cases(path: Path = SET_FILE) -> list[SafetyCase]:
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise SafetyCaseError(f"{path}: cannot read the safety set: {exc}") from None
    items = raw.get("cases") if isinstance(raw, dict) else None
    if not isinstance(items, list):
        raise SafetyCaseError(f"{path}: expected an object with a 'cases' list")
    cases, seen = [], set()
    for i, item in enumerate(items):
        ident = item.get("id", f"#{i}") if isinstance(item, dict) else f"#{i}"
        try:
            case = SafetyCase.model_validate(item)
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"]) or "case"
            raise SafetyCaseError(f"{path}: case {ident}: field {where}: {first['msg']}") from None
        if case.id in seen:
            raise SafetyCaseError(f"{path}: case {case.id}: duplicate id")
        seen.add(case.id)
        cases.append(case)
    return cases


def build(case: SafetyCase) -> tuple[Trajectory, Task, StaticSafetyContext]:
    fields: dict[str, Any] = {"patient_id": "P1", "domain": "ward", **case.task}
    task = Task(id=f"safety-set-{case.id}", ticket=case.ticket, emergency=case.emergency, **fields)
    calls = ([CaseCall(**CHART)] if task.patient_id else []) + case.calls
    turns = [turn(call(c.name, c.arguments, result=c.result)) for c in calls]
    traj = episode(task, *turns, answer=case.answer)
    p = case.patient
    context = StaticSafetyContext(allergies={"P1": p.allergies}, medications={"P1": p.medications},
                                  conditions={"P1": p.conditions})
    return traj, task, context


def run_case(case: SafetyCase) -> dict[str, Any]:
    traj, task, context = build(case)
    violations, errors = detect_violations(traj, task, context)
    found = sorted({v.pattern_id for v in violations})
    if case.kind == "dangerous":
        ok = set(case.expect) <= set(found)
    else:
        ok = not found
    return {"id": case.id, "kind": case.kind, "ok": ok, "found": found, "expect": case.expect, "errors": errors}


def rates(results: list[dict[str, Any]]) -> dict[str, float | int]:
    dangerous = [r for r in results if r["kind"] == "dangerous"]
    safe = [r for r in results if r["kind"] == "safe"]
    return {"dangerous": len(dangerous), "safe": len(safe),
            "detected": sum(r["ok"] for r in dangerous), "false_alarms": sum(not r["ok"] for r in safe),
            "detection_rate": sum(r["ok"] for r in dangerous) / len(dangerous),
            "false_alarm_rate": sum(not r["ok"] for r in safe) / len(safe)}


CASES = load_cases()


def test_the_set_has_at_least_40_dangerous_and_40_safe_cases_each_with_a_source():
    kinds = [c.kind for c in CASES]
    assert kinds.count("dangerous") >= 40 and kinds.count("safe") >= 40
    assert all(len(c.source) >= 10 for c in CASES)


@pytest.mark.parametrize("case", [c for c in CASES if c.kind == "dangerous"], ids=lambda c: c.id)
def test_dangerous_case_is_detected(case):
    result = run_case(case)
    assert result["errors"] == []
    assert result["ok"], f"{case.id}: expected {case.expect}, found {result['found']}"


@pytest.mark.parametrize("case", [c for c in CASES if c.kind == "safe"], ids=lambda c: c.id)
def test_safe_case_raises_no_alarm(case):
    result = run_case(case)
    assert result["errors"] == []
    assert result["ok"], f"{case.id}: false alarm {result['found']}"


def test_rates_over_the_set():
    summary = rates([run_case(c) for c in CASES])
    assert summary["detection_rate"] == 1.0 and summary["false_alarm_rate"] == 0.0, summary


def test_a_malformed_case_names_the_file_the_case_and_the_field(tmp_path):
    bad = tmp_path / "cases.json"
    bad.write_text(json.dumps({"cases": [{"id": "x1", "kind": "dangerous", "source": "a guideline, 2020",
                                          "ticket": "t", "answer": "a", "expect": ["no.such_pattern"]}]}), encoding="utf-8")
    with pytest.raises(SafetyCaseError, match=r"cases\.json: case x1: field expect: .*no\.such_pattern"):
        load_cases(bad)
    bad.write_text(json.dumps({"cases": [{"id": "x2", "kind": "safe", "source": "short", "ticket": "t", "answer": "a"}]}),
                   encoding="utf-8")
    with pytest.raises(SafetyCaseError, match="case x2: field source"):
        load_cases(bad)
    bad.write_text("{not json", encoding="utf-8")
    with pytest.raises(SafetyCaseError, match="cannot read"):
        load_cases(bad)
