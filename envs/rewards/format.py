"""Format: were the actions well-formed tool calls, and does the episode end in a conclusion?

Per call, from `ToolCallRecord.format` (how the environment's parser read it):

=====================  =====  ==========================================================
format                 score  why
=====================  =====  ==========================================================
json, openai, hermes   1.0    a valid structured call with name and arguments
function               0.8    valid, but Python call syntax instead of the requested JSON
fenced                 0.8    JSON inside a code fence (paper: "JSON in code blocks")
=====================  =====  ==========================================================

A call the environment rejected as malformed (unknown tool, arguments that do not fit the
signature) scores 0.5, "partial structure"; a clinical tool error (patient not found) is not a
format problem. A turn scores the mean of its calls, capped at 0.5 when it also has parse
errors; a turn with parse errors and no call scores 0.5; a plain-text turn without any call
scores 0, except the final turn when it is the answer (that is how a chat answer ends).

    format = 0.8 * mean(turn scores) + 0.2     with a real attempt at an answer
    format = 0                                 without one

Format (and coherence) credit needs a *real attempt at an answer* (`real_attempt`): well-formed
calls that lead nowhere earn nothing, so an empty answer, an episode that never submits, or an
answer that lists every option cannot collect the format and coherence weights (cheap strategies
would otherwise beat a real attempt; `bench/reward_gaming.py`). A real attempt commits to the value
the task asks for, as its accuracy grader reads it:

* no answer at all (empty, whitespace, or a truncated episode without a submission): none;
* an answer that copies the task's text (`accuracy.copies_question`): none;
* choice: `extract_choice` finds one option and no line of the answer commits to another (a list of
  options, a hedge "A or C", "A\nAnswer: B\nThe answer is C" or no letter: none);
* numeric: a number is stated (`accuracy.stated_number`);
* category: exactly one value of the family when the gold belongs to one (one ESI level, one
  interaction severity, one BI-RADS category; "ESI 1, ESI 2, ESI 3" is none), else any value;
* exact: a non-empty value; free text and tasks without a gold answer: more than 10 characters.
"""

from __future__ import annotations

from envs.core.trajectory import ToolCallRecord, TurnRecord
from envs.rewards.accuracy import answer_accuracy, copies_question, gold_answers, stated_number, strip_answer_prefix
from envs.rewards.choice import extract_choice
from envs.rewards.view import EpisodeView

FORMAT_SCORES = {"json": 1.0, "openai": 1.0, "hermes": 1.0, "function": 0.8, "fenced": 0.8, "text": 0.0, "empty": 0.0}
PARTIAL = 0.5
TURNS_W, CONCLUSION_W = 0.8, 0.2
MIN_CONCLUSION_CHARS = 10
_STRUCTURAL_ERRORS = ("unknown tool", "tool '")  # Toolkit.call's messages for malformed calls


def structural_error(call: ToolCallRecord) -> bool:
    return call.error is not None and call.error.lower().startswith(_STRUCTURAL_ERRORS)


def call_score(call: ToolCallRecord) -> float:
    score = FORMAT_SCORES.get(call.format, 0.0)
    return min(score, PARTIAL) if structural_error(call) else score


def turn_score(turn: TurnRecord, *, final: bool, has_conclusion: bool) -> float:
    if turn.tool_calls:
        score = sum(call_score(c) for c in turn.tool_calls) / len(turn.tool_calls)
        return min(score, PARTIAL) if turn.parse_errors else score
    if turn.parse_errors:
        return PARTIAL
    if final and has_conclusion:
        return 1.0
    return 0.0


def real_attempt(view: EpisodeView) -> tuple[bool, str]:
    """(whether the episode ends in a real attempt at an answer, why not when it does not)."""
    task = view.task
    answer = view.answer_text
    stripped = strip_answer_prefix(answer)
    if not stripped:
        return False, "no answer"
    golds = gold_answers(task)
    if task.answer_type != "choice" and copies_question(stripped, task.ticket + " " + (task.raw_question or ""),
                                                        golds[0] if golds else ""):
        return False, "the answer copies the task"
    if task.answer_type == "choice":
        if extract_choice(answer, task.options) is None:
            return False, "no single option committed to"
        # "A / (B) / Answer: C / the answer is D" commits to every option in turn: the grader reads the
        # last, but it is no more an attempt than the list "A, B, C, D"
        committed = {extract_choice(line, task.options, strict=True) for line in answer.splitlines()} - {None}
        if len(committed) > 1:
            return False, f"commits to {len(committed)} different options"
        return True, ""
    if task.answer_type == "numeric":
        return (True, "") if stated_number(answer, task.answer_unit) is not None else (False, "no number stated")
    if task.answer_type == "category" and golds:
        result = answer_accuracy(answer, task)
        stated = result.details.get("stated") if result is not None else None
        if stated is not None and len(stated) != 1:
            family = result.details.get("family", "category")  # type: ignore[union-attr]
            return False, f"{len(stated)} {family} values stated, not one"
        return True, ""
    if task.answer_type in ("category", "exact"):
        return True, ""  # a short categorical or exact value ("ESI 2", a drug name) is what was asked for
    if len(view.final_text.strip()) > MIN_CONCLUSION_CHARS:
        return True, ""
    return False, f"a conclusion of at most {MIN_CONCLUSION_CHARS} characters"


def has_conclusion(view: EpisodeView) -> bool:
    """The episode ends in a real attempt at an answer (`real_attempt`)."""
    return real_attempt(view)[0]


def format_score(view: EpisodeView) -> tuple[float, dict]:
    turns = view.trajectory.turns
    if not turns:
        return 0.0, {"turns": [], "conclusion": False, "no_attempt": "no turns"}
    attempted, why_not = real_attempt(view)
    scores = [turn_score(t, final=(i == len(turns) - 1), has_conclusion=attempted) for i, t in enumerate(turns)]
    details = {"turn_scores": [round(s, 3) for s in scores], "conclusion": attempted}
    if not attempted:
        return 0.0, {**details, "no_attempt": why_not}
    return TURNS_W * (sum(scores) / len(scores)) + CONCLUSION_W, details
