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
scores 0, except the final turn when its text is a conclusion (that is how a chat answer ends).

    format = 0.8 * mean(turn scores) + 0.2 * conclusion

`conclusion` is 1 when the final answer/message has more than 10 characters, or commits to the
structured value the task asks for (an option letter for choice, a number for numeric, any
non-empty value for exact and category answers such as "ESI 2" or a drug name).
"""

from __future__ import annotations

from envs.core.trajectory import ToolCallRecord, TurnRecord
from envs.rewards.accuracy import stated_number
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


def has_conclusion(view: EpisodeView) -> bool:
    text = view.final_text.strip()
    if len(text) > MIN_CONCLUSION_CHARS:
        return True
    task = view.task
    answer = view.answer_text
    if task.answer_type == "choice":
        return extract_choice(answer, task.options) is not None
    if task.answer_type == "numeric":
        return stated_number(answer, task.answer_unit) is not None
    if task.answer_type in ("category", "exact"):
        return bool(answer.strip())  # a short categorical or exact value is the conclusion asked for
    return False


def format_score(view: EpisodeView) -> tuple[float, dict]:
    turns = view.trajectory.turns
    if not turns:
        return 0.0, {"turns": [], "conclusion": False}
    conclusion = has_conclusion(view)
    scores = [turn_score(t, final=(i == len(turns) - 1), has_conclusion=conclusion) for i, t in enumerate(turns)]
    mean = sum(scores) / len(scores)
    return TURNS_W * mean + CONCLUSION_W * (1.0 if conclusion else 0.0), {
        "turn_scores": [round(s, 3) for s in scores], "conclusion": conclusion,
    }
