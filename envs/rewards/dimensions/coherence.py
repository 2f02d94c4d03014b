"""Coherence: no contradiction between what the agent found, stated and submitted
(envs/rewards/coherence.py). Always applies."""

from __future__ import annotations

from envs.rewards.coherence import coherence_score
from envs.rewards.dimensions.base import Dimension, Graded, Grading


def grade(grading: Grading) -> Graded:
    score, details = coherence_score(grading.view)
    return Graded(score=score, details=details)


DIMENSION = Dimension(name="coherence", default_weight=0.10, position=4, grade=grade,
                      summary="no contradiction between findings, statements and the answer")
