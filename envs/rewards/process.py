"""Process quality: did the agent do the work the task needs, without padding it?

    base = 0.6 * coverage + 0.2 * diversity + 0.2 * thoroughness
    process = 0.3 * base + 0.7 * rubric        (when the task has a rubric)

Only *needed* calls earn anything. A call is needed when it succeeded and is either
  * a call of a tool the task's expected actions use (`evaluation_criteria.actions`, submit and think
    excluded), or
  * a call of a READ tool (`ToolCallRecord.tool_type == "read"`) about the task: one of its text
    argument values (or lists of text) equals, after normalisation, one of an expected action (the
    same patient id, drug, lab, code...), so looking the patient up with a second chart tool counts
    while calling every tool of the domain with junk arguments does not. Numbers and flags are not
    compared: a junk call passing 1 or true would match a count or a flag. A task without expected actions has nothing to
    judge relevance by: every successful READ call is needed.
Failed calls, `think` calls, other tools' calls and repeats earn nothing.

* coverage: the fraction of expected actions matched by a *successful* logged call with the same name
  whose `compare_args` (all expected arguments when None) are equal after normalising case,
  whitespace and number formatting; each logged call matches at most one expected action, so
  repeating a call cannot cover more.
* diversity: distinct needed call signatures (name + normalised arguments) / calls, submit and think
  excluded from both (0 with no calls): every failed, irrelevant or repeated call lowers it.
* thoroughness: distinct tools among the needed calls / the number of distinct tools the expected
  actions use (3 when there are none), capped at 1.
* rubric: see `envs/rewards/assertions.py` (`grade_rubric`).

Without expected actions, coverage's weight is shared by diversity and thoroughness
(base = 0.5 * diversity + 0.5 * thoroughness). The dimension applies when the task has expected
actions or a rubric; otherwise it is reported but carries no weight.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from envs.core.task import ExpectedAction
from envs.rewards.text import norm_value, signature
from envs.rewards.view import CallRef, EpisodeView

COVERAGE_W, DIVERSITY_W, THOROUGHNESS_W = 0.6, 0.2, 0.2
RUBRIC_SHARE = 0.7
DEFAULT_TOOL_TARGET = 3


@dataclass
class ProcessResult:
    score: float
    applicable: bool
    coverage: float | None
    diversity: float
    thoroughness: float
    rubric: float | None
    matched: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)

    def details(self) -> dict[str, Any]:
        return {
            "coverage": self.coverage, "diversity": round(self.diversity, 4),
            "thoroughness": round(self.thoroughness, 4), "rubric": self.rubric,
            "matched_actions": self.matched, "missing_actions": self.missing,
        }


def _action_label(action: ExpectedAction, index: int) -> str:
    return action.action_id or f"{action.name}#{index}"


def call_matches(expected: ExpectedAction, name: str, arguments: dict[str, Any]) -> bool:
    """Same tool name (case-insensitive) and equal compared arguments after normalisation."""
    if name.lower() != expected.name.lower():
        return False
    for key, want in expected.compared_arguments.items():
        if norm_value(arguments.get(key)) != norm_value(want):
            return False
    return True


def action_coverage(view: EpisodeView) -> tuple[float | None, list[str], list[str]]:
    """(coverage, matched action labels, missing labels); coverage is None without expected actions."""
    expected = view.task.evaluation_criteria.actions
    if not expected:
        return None, [], []
    used: set[int] = set()
    matched, missing = [], []
    ok_calls = [c for c in view.calls if c.call.ok]
    for index, action in enumerate(expected):
        hit = None
        for ref in ok_calls:
            if ref.order not in used and call_matches(action, ref.name, ref.args):
                hit = ref.order
                break
        label = _action_label(action, index)
        if hit is None:
            missing.append(label)
        else:
            used.add(hit)
            matched.append(label)
    return len(matched) / len(expected), matched, missing


def expected_tools(view: EpisodeView) -> set[str]:
    """Tools (lower case) the expected actions use, submit and think excluded."""
    return {a.name.lower() for a in view.task.evaluation_criteria.actions
            if not ({"submit", "think"} & view.conv.families(a.name))}


def _entity(value: Any) -> bool:
    """A text value, or a list of them, that names something (a patient id, a drug, a lab, a code).
    Numbers and flags do not: a junk call passing 1 or true would otherwise match a count or a flag."""
    if isinstance(value, str):
        return bool(value.strip())
    return isinstance(value, list) and bool(value) and all(isinstance(v, str) for v in value)


def _task_values(view: EpisodeView) -> set[Any]:
    """Normalised text argument values of the expected actions: what the task is about."""
    return {norm_value(value) for action in view.task.evaluation_criteria.actions
            for value in action.arguments.values() if _entity(value)}


def _is_read(call: CallRef) -> bool:
    return (call.call.tool_type or "").lower() in ("read", "tooltype.read")


def counted_calls(view: EpisodeView) -> tuple[list[CallRef], list[CallRef]]:
    """(the calls diversity divides by: every call but submit and think, the needed calls among them)."""
    calls = [c for c in view.work_calls if "think" not in c.families]
    tools = expected_tools(view)
    values = _task_values(view) if view.task.evaluation_criteria.actions else None
    needed = []
    for ref in calls:
        if not ref.call.ok:
            continue
        if ref.name.lower() in tools:
            needed.append(ref)
        elif _is_read(ref) and (values is None or any(norm_value(v) in values for v in ref.args.values()
                                                      if _entity(v))):
            needed.append(ref)
    return calls, needed


def diversity(view: EpisodeView) -> float:
    calls, needed = counted_calls(view)
    if not calls:
        return 0.0
    return len({signature(c.name, c.args) for c in needed}) / len(calls)


def thoroughness(view: EpisodeView) -> float:
    _, needed = counted_calls(view)
    target = len(expected_tools(view)) or DEFAULT_TOOL_TARGET
    return min(1.0, len({c.name.lower() for c in needed}) / target)


def process_score(view: EpisodeView, rubric: float | None = None) -> ProcessResult:
    coverage, matched, missing = action_coverage(view)
    div, thor = diversity(view), thoroughness(view)
    if coverage is None:
        base = 0.5 * div + 0.5 * thor
    else:
        base = COVERAGE_W * coverage + DIVERSITY_W * div + THOROUGHNESS_W * thor
    score = base if rubric is None else (1 - RUBRIC_SHARE) * base + RUBRIC_SHARE * rubric
    crit = view.task.evaluation_criteria
    applicable = bool(crit.actions) or bool(crit.rubric)
    return ProcessResult(score, applicable, coverage, div, thor, rubric, matched, missing)
