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
from envs.rewards.accuracy import strip_answer_prefix, answer_accuracy, gold_answers
from envs.rewards.assertions import AssertionGrader, grade_assertions
from envs.rewards.coherence import coherence_score
from envs.rewards.conventions import ToolConventions
from envs.rewards.format import format_score
from envs.rewards.process import process_score
from envs.rewards.safety import detect_violations, safety_score
from envs.rewards.similarity import embedding_failed, embedding_status, warm
from envs.rewards.text import clip01
from envs.rewards.types import RewardBreakdown, RewardWeights
from envs.rewards.view import EpisodeView


def _outcome_without_gold(view: EpisodeView, coverage: float | None, assertion: float | None) -> tuple[float | None, str]:
    """Accuracy for a task without a gold answer, from its reward basis."""
    crit = view.task.evaluation_criteria
    parts: list[float] = []
    sources: list[str] = []
    if "DB" in crit.reward_basis and crit.expected_db_hash:
        parts.append(1.0 if view.trajectory.db_hash_final == crit.expected_db_hash else 0.0)
        sources.append("db")
    if coverage is not None and ("ACTION" in crit.reward_basis or not parts):
        parts.append(coverage)
        sources.append("actions")
    if not parts and assertion is not None:
        parts.append(assertion)
        sources.append("assertions")
    if not parts:
        return None, "none"
    return sum(parts) / len(parts), "+".join(sources)


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
    view = EpisodeView(trajectory, task, conventions)
    crit = task.evaluation_criteria
    errors: list[str] = []
    details: dict[str, Any] = {"task_kind": view.kind}

    outcome = grade_assertions(view, grader) if (crit.nl_assertions or crit.rubric) else None
    if outcome is not None:
        errors.extend(outcome.errors)
        details["assertion"] = outcome.details()
    assertion = outcome.score if outcome is not None else None

    proc = process_score(view, outcome.rubric if outcome is not None else None)
    details["process"] = proc.details()

    acc = answer_accuracy(view.answer_text, task)
    if acc is not None:
        accuracy, acc_applies = acc.score, True
        details["accuracy"] = {"source": acc.source, **acc.details}
        errors.extend(acc.errors)
    else:
        value, source = _outcome_without_gold(view, proc.coverage, assertion)
        accuracy, acc_applies = (value or 0.0), value is not None
        details["accuracy"] = {"source": source}

    violations, safety_errors = detect_violations(view, context=context)
    errors.extend(safety_errors)
    safety = safety_score(violations)

    fmt, fmt_details = format_score(view)
    coh, coh_details = coherence_score(view)
    details["format"] = fmt_details
    details["coherence"] = coh_details

    scores = {"accuracy": accuracy, "process": proc.score, "safety": safety, "format": fmt, "coherence": coh}
    applies = {"accuracy": acc_applies, "process": proc.applicable, "safety": True, "format": True, "coherence": True}
    if assertion is not None:
        scores["assertion"], applies["assertion"] = assertion, True
    raw = {k: (w.weight(k) if applies.get(k) else 0.0) for k in scores}
    norm = sum(raw.values())
    if norm <= 0:  # every applicable dimension has weight 0: average them equally
        raw = {k: (1.0 if applies.get(k) else 0.0) for k in scores}
        norm = sum(raw.values())
    effective = {k: v / norm for k, v in raw.items()}
    base = sum(effective[k] * scores[k] for k in scores)

    penalty = sum(w.severity_penalties.get(v.severity, 0.0) for v in violations if v.severity < 5)
    critical = any(v.severity == 5 for v in violations)
    total = min(1.0, max(w.floor, base - penalty))
    if critical:
        total = min(total, w.critical_cap)

    if (task.answer_type == "free_text" or outcome is not None) and embedding_failed():
        errors.append(f"embedding model unavailable ({embedding_status()}); graded by token overlap only")
    if task.answer_type == "free_text" or outcome is not None:
        details["embeddings"] = embedding_status()

    return RewardBreakdown(
        accuracy=clip01(accuracy), process=clip01(proc.score), safety=safety, format=clip01(fmt),
        coherence=clip01(coh), assertion=None if assertion is None else clip01(assertion),
        total=total, base_total=base, penalty=penalty, capped=critical,
        is_correct=bool(acc_applies and accuracy >= w.correct_threshold and not critical),
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
