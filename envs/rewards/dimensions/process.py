"""Process: coverage, diversity and thoroughness of the calls the task needs, and the rubric's share
(envs/rewards/process.py). Applies when the task has expected actions or a rubric."""

from __future__ import annotations

from envs.rewards.dimensions.base import Dimension, Graded, Grading
from envs.rewards.process import process_score


def grade(grading: Grading) -> Graded:
    outcome = grading.graded["assertion"].result
    result = process_score(grading.view, outcome.rubric if outcome is not None else None)
    return Graded(score=result.score, applies=result.applicable, details=result.details(), result=result)


DIMENSION = Dimension(name="process", default_weight=0.20, position=1, grade=grade, after=("assertion",),
                      summary="did the agent do the work the task needs")
