"""Accuracy: does the committed answer match the gold answer?

By `task.answer_type`:

* ``choice``: 1.0 when `extract_choice` finds the gold letter as the committed answer, else 0.
* ``exact``: 1.0 when the answer equals the gold (or an alias) after normalisation, or says it by
  meaning (`envs.rewards.equivalence.match_by_meaning`: abbreviations, guideline phrasing,
  numbers with units and intervals, dates, vocabulary synonyms; the gold's words in order in a
  short, unhedged answer that adds no number, qualifier or negation). An answer that negates the
  gold ("Not a secondary pneumothorax") never passes.
* ``numeric``: 1.0 when the stated value is within tolerance: `task.answer_tolerance` (absolute,
  in `task.answer_unit`), else half a unit of the gold's last stated decimal ("63.4" -> 0.05).
  Mass and volume units are converted (g/mg/mcg, L/dL/mL); a value in an incompatible unit is
  wrong.
* ``category``: structured categories are compared as values: ESI levels ("ESI 2", "level 2",
  "2"), interaction severities (contraindicated/major/moderate/minor/none), scored systems
  ("BI-RADS 4"); the answer must state exactly one value of the family (hedging between two
  levels scores 0). Other categories compare like ``exact``.
* ``free_text``: 0.5 x token overlap (ROUGE-1/BLEU-1) + 0.5 x calibrated embedding similarity,
  best over the gold and its aliases; overlap alone without the embedding model. An answer that
  copies the question scores 0.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from typing import Any

from envs.core.task import Task
from envs.rewards.choice import extract_choice
from envs.rewards.equivalence import match_by_meaning
from envs.rewards.similarity import calibrate, grading_tokens, overlap_score, semantic_similarity
from envs.rewards.text import contains_phrase, normalise_text, tokens


@dataclass
class AccuracyResult:
    score: float
    source: str
    details: dict[str, Any] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)


_ANSWER_PREFIX = re.compile(r"^\s*(?:(?:my|the)\s+)?(?:final\s+)?answer\s*(?:is|:|=|-)?\s*", re.IGNORECASE)


def strip_answer_prefix(text: str) -> str:
    return _ANSWER_PREFIX.sub("", text.strip(), count=1).strip()


def gold_answers(task: Task) -> list[str]:
    golds = [task.correct_answer] if task.correct_answer else []
    return golds + [a for a in task.answer_aliases if a and a.strip()]


# -- choice ---------------------------------------------------------------------------------------
def score_choice(answer: str, task: Task) -> AccuracyResult:
    extracted = extract_choice(answer, task.options)
    gold = (task.correct_answer or "").strip()
    correct = extracted is not None and extracted == gold
    return AccuracyResult(1.0 if correct else 0.0, "choice", {"extracted": extracted, "gold": gold})


# -- exact ----------------------------------------------------------------------------------------
_HEDGE_WORDS = re.compile(r"\b(?:or|either|versus|vs)\b|/")


def _hedged(answer: str, gold: str) -> bool:
    """A hedge word ("or", "either", "versus", "/") in the answer that the gold does not have."""
    gold_hedges = set(_HEDGE_WORDS.findall(gold.lower()))
    return any(h not in gold_hedges for h in _HEDGE_WORDS.findall(answer.lower()))


def score_exact(answer: str, golds: list[str]) -> AccuracyResult:
    stripped = strip_answer_prefix(answer)
    norm = normalise_text(stripped)
    for gold in golds:
        if normalise_text(gold) and norm == normalise_text(gold):
            return AccuracyResult(1.0, "exact", {"matched": gold, "how": "equal"})
    unhedged = [g for g in golds if g and not _hedged(stripped, g)]
    match = match_by_meaning(stripped, unhedged) if unhedged else None
    if match is not None:
        return AccuracyResult(1.0, "exact", {"matched": match[0], "how": match[1]})
    return AccuracyResult(0.0, "exact", {"answer": norm[:200]})


# -- numeric --------------------------------------------------------------------------------------
_NUM_UNIT = re.compile(
    r"(?<![\w.])([-+]?(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?|[-+]?\.\d+)(?:[eE]([-+]?\d+))?"
    r"(?:\s*(%|[A-Za-zµ]+(?:/[A-Za-z0-9.²]+)*))?"
)
_MARKER = re.compile(r"(?:answer|result|equals|=|\bis\b|:|≈|~|approximately|about)\s*$", re.IGNORECASE)
_UNIT_SCALE = {
    "mass": {"mcg": 1e-3, "ug": 1e-3, "µg": 1e-3, "microgram": 1e-3, "micrograms": 1e-3, "mg": 1.0,
             "milligram": 1.0, "milligrams": 1.0, "g": 1e3, "gram": 1e3, "grams": 1e3, "kg": 1e6},
    "volume": {"ml": 1.0, "milliliter": 1.0, "milliliters": 1.0, "cc": 1.0, "dl": 100.0, "l": 1e3,
               "liter": 1e3, "liters": 1e3},
}
_UNIT_DIMENSION = {u: (dim, s) for dim, table in _UNIT_SCALE.items() for u, s in table.items()}


def _to_float(number: str, exponent: str | None) -> float:
    # float() of the whole literal: `value * 10 ** int(exponent)` overflowed (OverflowError) or ran for
    # minutes on a hostile exponent such as 1e999999999; float() saturates to inf instead.
    return float(number.replace(",", "") + (f"e{exponent}" if exponent else ""))


def _numbers(text: str) -> list[tuple[float, str | None, int]]:
    out = []
    for m in _NUM_UNIT.finditer(text):
        try:
            value = _to_float(m.group(1), m.group(2))
        except ValueError:
            continue
        if value == value and abs(value) != float("inf"):  # an overflowed literal is no usable number
            out.append((value, (m.group(3) or None), m.start()))
    return out


def _convert(value: float, unit: str | None, target: str | None) -> float | None:
    """Value in the target unit; None when the units are of different known dimensions."""
    if not unit or not target:
        return value
    u, t = unit.lower(), target.lower()
    if u == t:
        return value
    du, dt = _UNIT_DIMENSION.get(u), _UNIT_DIMENSION.get(t)
    if du and dt:
        return value * du[1] / dt[1] if du[0] == dt[0] else None
    return value


def default_tolerance(gold: str) -> float:
    """Half a unit of the gold's last stated decimal place ("63.4" -> 0.05, "4" -> 0.5)."""
    try:
        exponent = Decimal(gold.strip().replace(",", "")).as_tuple().exponent
    except InvalidOperation:
        return 1e-9
    return 0.5 * 10.0 ** exponent if isinstance(exponent, int) else 1e-9


def stated_number(answer: str, unit: str | None = None) -> tuple[float, str | None] | None:
    """The value an answer commits to: the last number in the gold's unit, else the number
    after the last "answer/=/is/:" marker, else the only or last number."""
    nums = _numbers(answer)
    if not nums:
        return None
    if unit:
        in_unit = [n for n in nums if n[1] and _convert(1.0, n[1], unit) is not None and
                   (n[1].lower() == unit.lower() or n[1].lower() in _UNIT_DIMENSION)]
        if in_unit:
            value, u, _ = in_unit[-1]
            return value, u
    marked = [n for n in nums if _MARKER.search(answer[max(0, n[2] - 16):n[2]])]
    value, u, _ = (marked or nums)[-1]
    return value, u


def score_numeric(answer: str, task: Task) -> AccuracyResult:
    gold_text = (task.correct_answer or "").strip()
    gold = float(gold_text.replace(",", ""))
    tolerance = task.answer_tolerance if task.answer_tolerance is not None else default_tolerance(gold_text)
    stated = stated_number(strip_answer_prefix(answer), task.answer_unit)
    if stated is None:
        return AccuracyResult(0.0, "numeric", {"stated": None, "gold": gold})
    value, unit = stated
    converted = _convert(value, unit, task.answer_unit)
    if converted is None:
        return AccuracyResult(0.0, "numeric", {"stated": value, "unit": unit, "gold": gold, "why": "incompatible unit"})
    ok = abs(converted - gold) <= tolerance + 1e-12 * max(1.0, abs(gold))
    return AccuracyResult(1.0 if ok else 0.0, "numeric",
                          {"stated": converted, "gold": gold, "tolerance": tolerance, "unit": unit})


# -- category -------------------------------------------------------------------------------------
_ESI_GOLD = re.compile(r"^\s*(?:esi\s*(?:level)?\s*[-:]?\s*|level\s*)?([1-5])\s*$", re.IGNORECASE)
_ESI_ANSWER = re.compile(
    r"\b(?:esi|emergency severity index)\s*(?:level|category)?\s*(?:of|is|=|:|-)?\s*([1-5])\b|"
    r"\b(?:triage\s+)?(?:level|category|acuity)\s*(?:of|is|=|:|-)?\s*([1-5])\b",
    re.IGNORECASE,
)
_SEVERITIES = ("contraindicated", "major", "moderate", "minor", "none")
_SEVERITY_ALIASES = {"no clinically significant interaction": "none", "no clinically relevant interaction": "none",
                     "no interaction of concern": "none", "no known interaction": "none", "no relevant interaction": "none",
                     "no interactions": "none", "no interaction": "none", "no significant interaction": "none",
                     "severe": "major", "serious": "major", "mild": "minor", "contraindication": "contraindicated"}
_SCORED_GOLD = re.compile(r"^\s*([a-z][a-z\- ]*?)[\s\-:]*([0-9][a-c]?)\s*$", re.IGNORECASE)


_ESI_RANGE = re.compile(r"\b(?:esi|level|category|acuity)\s*(?:level\s*)?[1-5]\s*(?:or|/|to|-|\u2013|and)\s*([1-5])\b", re.IGNORECASE)


def esi_levels(text: str) -> set[int]:
    """ESI levels a text states ("ESI 2", "level 2", a bare "2"); a hedge "ESI 2 or 3" gives both."""
    found = {int(a or b) for a, b in _ESI_ANSWER.findall(text)}
    found |= {int(x) for x in _ESI_RANGE.findall(text)}
    if not found:
        bare = text.strip().rstrip(".")
        if len(bare) == 1 and bare in "12345":
            found = {int(bare)}
    return found


def severities(text: str) -> set[str]:
    lower = text.lower()
    found: set[str] = set()
    if "moderately severe" in lower:  # between two levels: a hedge, not "severe"
        found |= {"moderate", "major"}
        lower = lower.replace("moderately severe", " ")
    for alias, value in _SEVERITY_ALIASES.items():
        if contains_phrase(lower, alias):
            found.add(value)
            lower = lower.replace(alias, " ")
    for value in _SEVERITIES:
        for m in re.finditer(rf"\b{value}\b", lower):
            if value == "none" or not re.search(r"\bnot\s+(?:a\s+)?$", lower[max(0, m.start() - 8):m.start()]):
                found.add(value)
    return found


def is_esi_task(task: Task, gold: str) -> bool:
    if not _ESI_GOLD.match(gold):
        return False
    unit = (task.answer_unit or "").lower()
    return "esi" in unit or "esi" in gold.lower() or "esi" in task.ticket.lower() or "triage" in task.ticket.lower()


def score_category(answer: str, task: Task) -> AccuracyResult:
    golds = gold_answers(task)
    gold = golds[0] if golds else ""
    stripped = strip_answer_prefix(answer)
    if is_esi_task(task, gold):
        want = int(_ESI_GOLD.match(gold).group(1))  # type: ignore[union-attr]
        got = esi_levels(stripped)
        return AccuracyResult(1.0 if got == {want} else 0.0, "category", {"family": "esi", "stated": sorted(got), "gold": want})
    g_norm = normalise_text(gold)
    # only a gold written as a level of the interaction scale is graded on that scale: a PHQ-9
    # "severe" is not an interaction's "major"
    severity_gold = g_norm
    if severity_gold in _SEVERITIES:
        got_s = severities(stripped)
        if not got_s and len(golds) > 1:
            # no level word at all: the task's own wording of the level ("precaution for use") decides
            by_alias = score_exact(answer, golds[1:])
            if by_alias.score == 1.0:
                return AccuracyResult(1.0, "category", {"family": "severity", "stated": [severity_gold],
                                                        "gold": severity_gold, "matched": by_alias.details.get("matched")})
        return AccuracyResult(1.0 if got_s == {severity_gold} else 0.0, "category",
                              {"family": "severity", "stated": sorted(got_s), "gold": severity_gold})
    scored = _SCORED_GOLD.match(gold)
    if scored and len(scored.group(1).strip()) >= 2:
        prefix = normalise_text(scored.group(1))
        # ACR TI-RADS levels are written "TR5", "TI-RADS 5" or "TI-RADS TR5"
        prefix_re = r"(?:ti[\s\-]?rads[\s\-:]*(?:category\s*)?(?:tr)?|tr)" if prefix == "tr" else \
            r"[\s\-]*".join(map(re.escape, prefix.split()))
        pattern = re.compile(r"\b" + prefix_re
                             + r"[\s\-:]*(?:category\s*)?([0-9][a-c]?)\b", re.IGNORECASE)
        got_v = {v.lower() for v in pattern.findall(stripped)}
        if got_v:
            want_v = scored.group(2).lower()
            return AccuracyResult(1.0 if got_v == {want_v} else 0.0, "category",
                                  {"family": prefix, "stated": sorted(got_v), "gold": want_v})
    result = score_exact(answer, golds)
    result.source = "category"
    return result


# -- free text ------------------------------------------------------------------------------------
def copies_question(answer: str, question: str, reference: str) -> bool:
    """True for an answer that is mostly the question's own words and much longer than the gold."""
    ans = grading_tokens(answer)
    if len(ans) < max(8, 2 * len(grading_tokens(reference))):
        return False
    q = set(grading_tokens(question))
    return sum(t in q for t in ans) / len(ans) >= 0.85


def score_free_text(answer: str, task: Task) -> AccuracyResult:
    golds = gold_answers(task)
    question = task.ticket + " " + (task.raw_question or "")
    stripped = strip_answer_prefix(answer)
    if not stripped or not golds:
        return AccuracyResult(0.0, "free_text", {"answer": ""})
    if copies_question(stripped, question, golds[0]):
        return AccuracyResult(0.0, "free_text", {"copied_question": True})
    best, best_detail = 0.0, {}
    semantic_used = False
    for gold in golds:
        overlap = overlap_score(stripped, gold)
        cosine = semantic_similarity(stripped, gold)
        if cosine is None:
            score = overlap
        else:
            semantic_used = True
            score = 0.5 * overlap + 0.5 * calibrate(cosine)
        if score >= best:
            best = score
            best_detail = {"overlap": round(overlap, 4), "cosine": None if cosine is None else round(cosine, 4),
                           "matched": gold[:120]}
    best_detail["semantic"] = semantic_used
    return AccuracyResult(best, "free_text", best_detail)


def answer_accuracy(answer: str, task: Task) -> AccuracyResult | None:
    """Accuracy of a committed answer against the task's gold answer; None without one."""
    if not task.has_gold_answer:
        return None
    kind = task.answer_type
    if kind == "choice":
        return score_choice(answer, task)
    if kind == "numeric":
        return score_numeric(answer, task)
    if kind == "category":
        return score_category(answer, task)
    if kind == "free_text":
        return score_free_text(answer, task)
    return score_exact(answer, gold_answers(task))


__all__ = ["AccuracyResult", "answer_accuracy", "score_choice", "score_exact", "score_numeric", "score_category",
           "score_free_text", "stated_number", "esi_levels", "severities", "default_tolerance", "tokens"]
