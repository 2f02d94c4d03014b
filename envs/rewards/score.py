"""`score_episode`: the reward that training and evaluation both use.

    base  = sum_j w_j R_j / sum_j w_j      over the dimensions j that apply to the task
    total = clip(base - sum of severity 1-4 penalties, floor, 1)
    total = min(total, critical_cap)        if any severity-5 violation

Which dimensions apply:
* accuracy: the task has a gold answer; otherwise its outcome from `reward_basis` (DB hash
  match, expected-action coverage, or the assertion score); not at all when none exists.
* process: the task has expected actions or a rubric.
* safety, format, coherence: always.
* assertion: the task has NL assertions or a rubric (and at least one could be graded).
"""

from __future__ import annotations

from typing import Any, Iterable

from envs.core.task import Task
from envs.core.trajectory import Trajectory
from envs.rewards.accuracy import strip_answer_prefix, gold_answers
from envs.rewards.assertions import AssertionGrader
from envs.rewards.conventions import ToolConventions
from envs.rewards.dimensions import DIMENSIONS, GRADING_ORDER, Grading
from envs.rewards.similarity import embedding_failed, embedding_status, warm
from envs.rewards.text import clip01
from envs.rewards.types import RewardBreakdown, RewardWeights
from envs.rewards.view import EpisodeView


def score_episode(trajectory: Trajectory, task: Task, weights: RewardWeights | dict[str, Any] | None = None,
                  context: Any = None, *, grader: AssertionGrader | None = None,
                  conventions: ToolConventions | None = None) -> RewardBreakdown:
    """Score one finished episode on the 5D reward (+ assertions) with safety penalties.

    Args:
        trajectory: What the agent did (turns, tool calls, submitted answer).
        task: The task it was given (gold answer, expected actions, assertions, rubric).
        weights: `RewardWeights`, a dict of its fields, or None for the paper's defaults.
        context: The domain's `SafetyContext` (world-state facts); None uses the built-in lexicon.
        grader: Assertion grader; default: the LLM judge when configured by environment
            variables, else the rule-and-embedding grader.
        conventions: Tool-name conventions; default: `context.conventions` when the domain's
            context has one, else `DEFAULT_CONVENTIONS`.

    Example:
        >>> from envs.core.trajectory import Trajectory, TurnRecord, ToolCallRecord
        >>> task = Task(ticket="Which vitamin?", options={"A": "Vitamin A", "B": "Vitamin D"}, correct_answer="B")
        >>> call = ToolCallRecord(name="submit_answer", arguments={"answer": "B"}, format="hermes", submit=True)
        >>> traj = Trajectory(task_id=task.id, domain="medical_qa", submitted_answer="B",
        ...                   turns=[TurnRecord(index=0, action="...", action_format="hermes", tool_calls=[call])])
        >>> b = score_episode(traj, task)
        >>> b.accuracy, b.is_correct, round(b.total, 3)
        (1.0, True, 1.0)
    """
    w = RewardWeights.coerce(weights)
    if conventions is None and isinstance(getattr(context, "conventions", None), ToolConventions):
        conventions = context.conventions  # a domain's own tool names travel with its context
    grading = Grading(EpisodeView(trajectory, task, conventions), context=context, grader=grader)
    errors: list[str] = []
    details: dict[str, Any] = {"task_kind": grading.view.kind}
    for dimension in GRADING_ORDER:
        graded = grading.graded[dimension.name] = dimension.grade(grading)
        errors.extend(graded.errors)
        if graded.details is not None:
            details[dimension.name] = graded.details

    # A dimension enters the weighted sum when it is always reported (with weight 0 where it does not
    # apply) or when it applied.
    scored = {d.name: grading.graded[d.name] for d in DIMENSIONS if d.always_reported or grading.graded[d.name].applies}
    raw = {name: (w.weight(name) if g.applies else 0.0) for name, g in scored.items()}
    norm = sum(raw.values())
    if norm <= 0:  # every applicable dimension has weight 0: average them equally
        raw = {name: (1.0 if g.applies else 0.0) for name, g in scored.items()}
        norm = sum(raw.values())
    effective = {name: value / norm for name, value in raw.items()}
    base = sum(effective[name] * g.score for name, g in scored.items())

    violations = [v for d in GRADING_ORDER for v in grading.graded[d.name].violations]
    penalty = sum(w.severity_penalties.get(v.severity, 0.0) for v in violations if v.severity < 5)
    critical = any(v.severity == 5 for v in violations)
    total = min(1.0, max(w.floor, base - penalty))
    if critical:
        total = min(total, w.critical_cap)

    uses_embeddings = task.answer_type == "free_text" or grading.graded["assertion"].result is not None
    if uses_embeddings and embedding_failed():
        errors.append(f"embedding model unavailable ({embedding_status()}); graded by token overlap only")
    if uses_embeddings:
        details["embeddings"] = embedding_status()

    accuracy = grading.graded["accuracy"]
    return RewardBreakdown(
        **{name: clip01(g.score) for name, g in scored.items()},
        total=total, base_total=base, penalty=penalty, capped=critical,
        is_correct=bool(accuracy.applies and accuracy.score >= w.correct_threshold and not critical),
        violations=violations, grader_errors=errors, weights=effective, details=details,
    )


def score_episodes(items: Iterable[tuple], weights: RewardWeights | dict[str, Any] | None = None, context: Any = None,
                   **kwargs: Any) -> list[RewardBreakdown]:
    """`score_episode` over many episodes, encoding every free-text answer and gold in one batch first.

    `items` are (trajectory, task) or (trajectory, task, context) tuples; the batch matters only
    when the embedding model is used (free-text answers): about 3x faster than one by one on CPU.
    """
    rows = [tuple(item) for item in items]
    texts: list[str] = []
    for row in rows:
        trajectory, task = row[0], row[1]
        if task.answer_type == "free_text" and task.has_gold_answer:
            texts.append(strip_answer_prefix(EpisodeView(trajectory, task).answer_text))
            texts.extend(gold_answers(task))
    warm([t for t in texts if t])
    return [score_episode(row[0], row[1], weights, row[2] if len(row) > 2 else context, **kwargs) for row in rows]
