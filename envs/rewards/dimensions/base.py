"""What a reward dimension is: a name, a default weight and how it grades an episode.

`score_episode` grades every registered dimension (`envs.rewards.dimensions.DIMENSIONS`) through
one `Grading` per episode; `RewardWeights`, `RewardBreakdown`, `components()` and the verl keys
are built from the same list, so a dimension is declared once, in its own module.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from envs.core.task import Task
    from envs.rewards.assertions import AssertionGrader
    from envs.rewards.view import EpisodeView
    from envs.rewards.violation import Violation


@dataclass
class Graded:
    """One dimension's verdict on one episode.

    Attributes:
        score: The dimension's score in [0, 1].
        applies: False when the task gives the dimension nothing to grade against: its weight is
            left out of the normalisation (and an optional dimension is reported as None).
        details: Sub-scores for `RewardBreakdown.details[<name>]` (None: no entry).
        errors: Grading failures (reported in `grader_errors`, never scored as 0).
        violations: Safety violations found (penalties and the critical cap read them).
        result: The grader's own result object, for dimensions graded after this one.
    """

    score: float
    applies: bool = True
    details: dict[str, Any] | None = None
    errors: list[str] = field(default_factory=list)
    violations: list["Violation"] = field(default_factory=list)
    result: Any = None


@dataclass
class Grading:
    """The episode being scored, and the verdicts of the dimensions graded so far."""

    view: "EpisodeView"
    context: Any = None
    grader: "AssertionGrader | None" = None
    graded: dict[str, Graded] = field(default_factory=dict)

    @property
    def task(self) -> "Task":
        return self.view.task


def scored_by(score: Callable[["EpisodeView"], tuple[float, dict[str, Any]]]) -> Callable[[Grading], Graded]:
    """A `grade` for a dimension that always applies and reads only the episode:
    `score(view) -> (score, details)`."""

    def grade(grading: Grading) -> Graded:
        value, details = score(grading.view)
        return Graded(score=value, details=details)

    return grade


@dataclass(frozen=True)
class Dimension:
    """A reward dimension.

    Attributes:
        name: Its key in weights, the breakdown, `components()` and logs (a Python identifier).
        default_weight: Its weight in `RewardWeights()` (paper section 3).
        position: Its place in report order (breakdowns, components, tables).
        grade: Grades one episode; reads `grading.graded[d]` only for the names in `after`.
        after: Dimensions whose verdicts `grade` reads (graded first).
        always_reported: True: a float in every breakdown, `components()` and the verl keys (0 with
            no weight when it does not apply). False: None in the breakdown and absent from
            `components()` when it does not apply.
        summary: One line for docs and error messages.
    """

    name: str
    default_weight: float
    position: int
    grade: Callable[[Grading], Graded]
    after: tuple[str, ...] = ()
    always_reported: bool = True
    summary: str = ""
