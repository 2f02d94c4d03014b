"""Process quality: did the agent do the expected work, without padding it?

    base = 0.6 * coverage + 0.2 * diversity + 0.2 * thoroughness
    process = 0.3 * base + 0.7 * rubric        (when the task has a rubric)

* coverage: the fraction of `evaluation_criteria.actions` matched by a *successful* logged call
  with the same name whose `compare_args` (all expected arguments when None) are equal after
  normalising case, whitespace and number formatting; each logged call matches at most one
  expected action, so repeating a call cannot cover more.
* diversity: distinct call signatures (name + normalised arguments) / calls, submit excluded
  (0 with no calls); repeats lower it.
* thoroughness: distinct tools used successfully (submit and think excluded) / the number of
  distinct tools the expected actions use (3 when there are none), capped at 1.
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
from envs.rewards.view import EpisodeView

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


def diversity(view: EpisodeView) -> float:
    calls = view.work_calls
    if not calls:
        return 0.0
    return len({signature(c.name, c.args) for c in calls}) / len(calls)


def thoroughness(view: EpisodeView) -> float:
    used = {c.name.lower() for c in view.work_calls if c.call.ok and "think" not in c.families}
    expected = {a.name.lower() for a in view.task.evaluation_criteria.actions
                if not ({"submit", "think"} & view.conv.families(a.name))}
    target = len(expected) or DEFAULT_TOOL_TARGET
    return min(1.0, len(used) / target)


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
