"""Accuracy: the committed answer against the gold (envs/rewards/accuracy.py); for a task without a
gold answer, its outcome from `reward_basis` (the final DB hash, expected-action coverage, or the
assertion score). Does not apply when the task has none of these."""

from __future__ import annotations

from envs.rewards.accuracy import answer_accuracy
from envs.rewards.dimensions.base import Dimension, Graded, Grading


def _outcome_without_gold(grading: Grading) -> tuple[float | None, str]:
    """Accuracy for a task without a gold answer, from its reward basis."""
    crit = grading.task.evaluation_criteria
    coverage = grading.graded["process"].result.coverage
    assertion = grading.graded["assertion"]
    parts: list[float] = []
    sources: list[str] = []
    if "DB" in crit.reward_basis and crit.expected_db_hash:
        parts.append(1.0 if grading.view.trajectory.db_hash_final == crit.expected_db_hash else 0.0)
        sources.append("db")
    if coverage is not None and ("ACTION" in crit.reward_basis or not parts):
        parts.append(coverage)
        sources.append("actions")
    if not parts and assertion.applies:
        parts.append(assertion.score)
        sources.append("assertions")
    if not parts:
        return None, "none"
    return sum(parts) / len(parts), "+".join(sources)


def grade(grading: Grading) -> Graded:
    result = answer_accuracy(grading.view.answer_text, grading.task)
    if result is not None:
        return Graded(score=result.score, details={"source": result.source, **result.details},
                      errors=list(result.errors), result=result)
    value, source = _outcome_without_gold(grading)
    return Graded(score=value or 0.0, applies=value is not None, details={"source": source})


DIMENSION = Dimension(name="accuracy", default_weight=0.25, position=0, grade=grade, after=("process", "assertion"),
                      summary="the committed answer against the gold (or the task's outcome)")
