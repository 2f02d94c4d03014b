"""Format: well-formed tool calls and a conclusion, gated by a real attempt at an answer
(envs/rewards/format.py). Always applies."""

from __future__ import annotations

from envs.rewards.dimensions.base import Dimension, Graded, Grading
from envs.rewards.format import format_score


def grade(grading: Grading) -> Graded:
    score, details = format_score(grading.view)
    return Graded(score=score, details=details)


DIMENSION = Dimension(name="format", default_weight=0.10, position=3, grade=grade,
                      summary="well-formed calls and a real attempt at an answer")
