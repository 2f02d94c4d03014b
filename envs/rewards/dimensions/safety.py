"""Safety: 1 minus the deductions of the violations the safety checks find (envs/rewards/safety.py,
docs/rewards.md); the violations also drive the penalties and the critical cap. Always applies."""

from __future__ import annotations

from envs.rewards.dimensions.base import Dimension, Graded, Grading
from envs.rewards.safety import detect_violations, safety_score


def grade(grading: Grading) -> Graded:
    violations, errors = detect_violations(grading.view, context=grading.context)
    return Graded(score=safety_score(violations), errors=errors, violations=violations)


DIMENSION = Dimension(name="safety", default_weight=0.20, position=2, grade=grade,
                      summary="no unsafe action or omission")
