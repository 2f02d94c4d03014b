"""Assertion: the task's natural-language assertions and rubric, graded by the assertion grader
(envs/rewards/assertions.py). Applies only to tasks that have them (and when at least one could be
graded); reported as None otherwise."""

from __future__ import annotations

from envs.rewards.assertions import grade_assertions
from envs.rewards.dimensions.base import Dimension, Graded, Grading


def grade(grading: Grading) -> Graded:
    criteria = grading.task.evaluation_criteria
    if not (criteria.nl_assertions or criteria.rubric):
        return Graded(score=0.0, applies=False)
    outcome = grade_assertions(grading.view, grading.grader)
    return Graded(score=outcome.score if outcome.score is not None else 0.0, applies=outcome.score is not None,
                  details=outcome.details(), errors=list(outcome.errors), result=outcome)


DIMENSION = Dimension(name="assertion", default_weight=0.15, position=5, grade=grade, always_reported=False,
                      summary="the task's NL assertions and rubric")
