"""Pathway definitions and the engine that runs one as an episode.

A pathway (chest pain, diabetic emergency, stroke code, sepsis bundle, post-operative
complication, paediatric fever) is a sequence of phases. Each phase names the active domain, the
actions it requires, NL assertions about the agent's conduct, a transition condition and an
optional time budget. The engine exposes the active domain's tools plus pathway control tools;
when a phase's transition condition holds, the next phase starts and its tools replace the old
ones. The same patient exists in every domain the pathway touches: the pathway carries one record
per domain, inserted through each domain's `add_patient` hook at reset.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Literal

from pydantic import BaseModel, ConfigDict, Field

from envs.core.common_tools import BaseDomainTools
from envs.core.domain import DomainEnvironment
from envs.core.task import ExpectedAction
from envs.core.tools import Toolkit, ToolDefinition, ToolError, ToolOutcome, ToolType, is_tool


class PathwayPhase(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    domain: str
    goal: str
    required_actions: list[ExpectedAction] = Field(default_factory=list)
    nl_assertions: list[str] = Field(default_factory=list)
    # The reference clinician's statement for the phase (what its assertions check); the phases'
    # statements joined are the gold submission's reasoning (Task.metadata["gold_reasoning"]).
    gold_reasoning: str = ""
    # "required_actions": the phase ends as soon as every required action has been performed;
    # "agent_declares": the agent ends it with complete_phase (it may leave actions undone).
    transition: Literal["required_actions", "agent_declares"] = "required_actions"
    time_pressure: bool = False
    max_calls: int | None = Field(default=None, ge=1)  # the phase's tool-call budget under time pressure


class Pathway(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str
    title: str
    # The published guideline(s) or label(s) the pathway's decisions follow (the task's provenance).
    guideline: str = ""
    presentation: str
    patient_id: str
    patients: dict[str, dict[str, Any]] = Field(default_factory=dict)  # domain -> record for add_patient
    phases: list[PathwayPhase] = Field(min_length=1)
    final_question: str
    final_answer: str
    answer_aliases: list[str] = Field(default_factory=list)
    emergency: str | None = None


def tool_signature(definition: ToolDefinition) -> str:
    """A one-line signature from the tool's schema, e.g.
    "order_lab(patient_id: string, test: string, priority: 'routine'|'urgent'|'stat' = 'routine')"."""
    params = definition.parameters.get("properties", {})
    required = set(definition.parameters.get("required", []))
    parts = []
    for name, spec in params.items():
        kind = "|".join(repr(v) for v in spec["enum"]) if "enum" in spec else definition.arg_types.get(name, "any")
        parts.append(f"{name}: {kind}" if name in required else f"{name}: {kind} = {spec.get('default')!r}")
    return f"{definition.name}({', '.join(parts)})"


def action_matches(expected: ExpectedAction, name: str, arguments: dict[str, Any]) -> bool:
    """The reward's matching rule (name plus normalised compare_args), so phases and the process
    score agree on what counts as done."""
    from envs.rewards.process import call_matches

    return call_matches(expected, name, arguments)


@dataclass
class PhaseLog:
    calls: list[tuple[str, dict[str, Any], bool]] = field(default_factory=list)
    matched: set[int] = field(default_factory=set)  # indices of required actions already performed
    completed: bool = False
    over_budget: bool = False


class PathwayControlTools(BaseDomainTools):
    """Tools available in every phase: status, complete_phase, think, submit_answer."""

    def __init__(self, engine: "PathwayEngine") -> None:
        super().__init__(None)
        self.engine = engine

    @is_tool(ToolType.READ)
    def get_pathway_status(self) -> dict:
        """Show the pathway's phases, the active phase, its goal and what it still requires."""
        return self.engine.status()

    @is_tool(ToolType.GENERIC)
    def complete_phase(self, summary: str) -> dict:
        """Finish the active phase and move to the next one.

        Args:
            summary: What was found and decided in this phase.
        """
        return self.engine.advance(declared=True)


class PathwayEngine(Toolkit):
    """A toolkit whose tools are the active phase's domain tools plus the control tools."""

    def __init__(self, pathway: Pathway, domain_envs: dict[str, DomainEnvironment]) -> None:
        missing = [p.domain for p in pathway.phases if p.domain not in domain_envs]
        if missing:
            raise ValueError(f"pathway {pathway.id!r}: no environment for domain(s) {missing}")
        self.pathway = pathway
        self.domain_envs = domain_envs
        self.control = PathwayControlTools(self)
        self.phase_index = 0
        self.logs = [PhaseLog() for _ in pathway.phases]

    # -- toolkit interface -----------------------------------------------------------------
    @property
    def phase(self) -> PathwayPhase:
        return self.pathway.phases[min(self.phase_index, len(self.pathway.phases) - 1)]

    @property
    def finished(self) -> bool:
        return self.phase_index >= len(self.pathway.phases)

    @property
    def db(self) -> Any:
        return self.domain_envs[self.phase.domain].toolkit.db

    @db.setter
    def db(self, value: Any) -> None:  # the engine's own state is not a database
        pass

    @property
    def definitions(self) -> dict[str, ToolDefinition]:  # type: ignore[override]
        merged = dict(self.control.definitions)
        if not self.finished:
            for name, definition in self.domain_envs[self.phase.domain].toolkit.definitions.items():
                merged.setdefault(name, definition)
        return merged

    def bound(self, name: str) -> tuple[ToolDefinition, Callable]:
        if name in self.control.definitions:
            return self.control.bound(name)
        return self.domain_envs[self.phase.domain].toolkit.bound(name)

    def call(self, name: str, arguments: Any) -> ToolOutcome:
        if name in self.control.definitions or self.finished:
            return self.control.call(name, arguments)
        if name not in self.definitions:
            return ToolOutcome(name=str(name), arguments=arguments if isinstance(arguments, dict) else {},
                               error=self.unknown_tool_message(name) + f" (phase {self.phase.name!r} uses the "
                               f"{self.phase.domain} tools)", error_kind="unknown_tool")
        phase_index = self.phase_index
        outcome = self.domain_envs[self.phase.domain].toolkit.call(name, arguments)
        log = self.logs[phase_index]
        log.calls.append((name, outcome.arguments, outcome.ok))
        if outcome.ok:  # match only the new call: the log itself can grow long
            for index, required in enumerate(self.phase.required_actions):
                if index not in log.matched and action_matches(required, name, outcome.arguments):
                    log.matched.add(index)
        if self.phase.max_calls and len(log.calls) > self.phase.max_calls:
            log.over_budget = True
        if outcome.ok and self.phase.transition == "required_actions" and not self.missing_actions():
            transition = self.advance(declared=False)
            outcome.result = {"result": outcome.result, "pathway": transition}
        return outcome

    # -- pathway logic ----------------------------------------------------------------------
    def missing_actions(self, index: int | None = None) -> list[ExpectedAction]:
        index = self.phase_index if index is None else index
        phase, log = self.pathway.phases[index], self.logs[index]
        return [a for i, a in enumerate(phase.required_actions) if i not in log.matched]

    def advance(self, declared: bool) -> dict:
        if self.finished:
            raise ToolError("every phase is already complete; submit your final answer")
        done = self.phase
        self.logs[self.phase_index].completed = True
        self.phase_index += 1
        if self.finished:
            return {"completed_phase": done.name, "next": None,
                    "message": f"All phases complete. {self.pathway.final_question} Call submit_answer."}
        nxt = self.phase
        return {"completed_phase": done.name, "next_phase": nxt.name, "domain": nxt.domain, "goal": nxt.goal,
                "time_pressure": nxt.time_pressure, "max_calls": nxt.max_calls,
                "tools": sorted(self.domain_envs[nxt.domain].toolkit.tool_names),
                # The system prompt listed the first phase's tools only: give the new ones' signatures.
                "tool_signatures": self.phase_tool_signatures()}

    def phase_tool_signatures(self) -> dict[str, str]:
        """Signature -> description of the active domain's tools (the control tools are always listed)."""
        if self.finished:
            return {}
        own = self.control.definitions
        return {tool_signature(d): d.description
                for name, d in sorted(self.domain_envs[self.phase.domain].toolkit.definitions.items())
                if name not in own}

    def status(self) -> dict:
        return {
            "pathway": self.pathway.title,
            "phases": [{"name": p.name, "domain": p.domain, "completed": self.logs[i].completed}
                       for i, p in enumerate(self.pathway.phases)],
            "active_phase": None if self.finished else self.phase.name,
            "goal": None if self.finished else self.phase.goal,
            "time_pressure": None if self.finished else self.phase.time_pressure,
            "calls_left": (None if self.finished or not self.phase.max_calls else
                           max(0, self.phase.max_calls - len(self.logs[self.phase_index].calls))),
            "still_required": [] if self.finished else [a.name for a in self.missing_actions()],
            "tools": [] if self.finished else sorted(self.phase_tool_signatures()),
        }

    def phase_scores(self) -> list[dict[str, Any]]:
        """Per phase: coverage of required actions, completion and time budget."""
        scores = []
        for index, phase in enumerate(self.pathway.phases):
            required = len(phase.required_actions)
            coverage = 1.0 if required == 0 else 1.0 - len(self.missing_actions(index)) / required
            score = coverage * (1.0 if self.logs[index].completed else 0.5)
            if self.logs[index].over_budget:
                score *= 0.5  # time pressure: the phase took more calls than its budget
            scores.append({"phase": phase.name, "domain": phase.domain, "coverage": coverage,
                           "completed": self.logs[index].completed, "over_budget": self.logs[index].over_budget,
                           "score": score})
        return scores
