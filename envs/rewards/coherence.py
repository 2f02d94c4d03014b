"""Coherence: a clear conclusion that agrees with the reasoning, without self-contradiction.

    coherence = 0.4 * conclusion + 0.4 * agreement + 0.2 * consistency     with a real attempt
    coherence = 0                                                          without one

A real attempt at an answer is `format.real_attempt` (an empty answer, no submission, a list of
every option, a copy of the task or, for a choice task, no single committed option is none):
agreeing with oneself about nothing earns nothing, so a non-answer cannot collect coherence credit.

* conclusion: 1 for a committed answer, halved by hedging language in the conclusion such as
  "not sure" or "cannot determine" (not for choice tasks, whose committed letter is the answer).
* agreement: 0 when the reasoning's last explicit conclusion differs from the submitted answer
  ("I conclude A" then submitting C; "ESI 2" in the reasoning, "ESI 3" submitted), else 1.
* consistency: 1 - 0.5 per contradiction between turns about the same fact (allergies present vs
  "no known allergies", pregnant vs not pregnant, "no interaction" vs "major interaction" for the
  same pair, "emergency" vs "not an emergency"), floored at 0.
"""

from __future__ import annotations

import re
from typing import Any

from envs.rewards.accuracy import esi_levels
from envs.rewards.choice import extract_choice
from envs.rewards.format import real_attempt
from envs.rewards.view import EpisodeView

CONCLUSION_W, AGREEMENT_W, CONSISTENCY_W = 0.4, 0.4, 0.2

_HEDGE = re.compile(
    r"\b(?:not sure|unsure|uncertain which|cannot determine|can't determine|unable to determine|"
    r"could be (?:either|any)|hard to say|impossible to (?:say|tell)|i don't know|i do not know|no way to know)\b",
    re.IGNORECASE,
)

_FACTS: list[tuple[str, re.Pattern[str], bool]] = [
    ("allergies", re.compile(r"\b(?:no known (?:drug )?allergies|nkda|no (?:drug )?allergies|not allergic to any)\b", re.I), False),
    ("allergies", re.compile(r"\b(?:is allergic to|has an? (?:\w+ )?allergy|allergic to \w+|documented (?:\w+ )?allergy)\b", re.I), True),
    ("pregnant", re.compile(r"\b(?:not pregnant|pregnancy test (?:is |was )?negative|negative (?:pregnancy|hcg)|hcg (?:is |was )?negative)\b", re.I), False),
    ("pregnant", re.compile(r"\b(?:(?:is|she's|patient is|currently) pregnant|pregnancy test (?:is |was )?positive|positive (?:pregnancy|hcg)|hcg (?:is |was )?positive)\b", re.I), True),
    ("emergency", re.compile(r"\b(?:not an emergency|non-?urgent|not urgent|no need (?:for|to) (?:escalat|urgent))\w*", re.I), False),
    ("emergency", re.compile(r"\b(?:this is an emergency|medical emergency|is emergent|requires emergent|life-threatening)\b", re.I), True),
]
_NO_INTERACTION = re.compile(r"\bno (?:significant |known |clinically significant |major )?(?:drug )?interactions?\b(?: between (\w+) and (\w+))?", re.I)
_INTERACTION = re.compile(r"\b(?:major|significant|serious|severe|contraindicated|dangerous) (?:drug )?interaction(?: between (\w+) and (\w+))?", re.I)


_FACT_WORDS = ("allerg", "nkda", "pregnan", "hcg", "emergen", "urgent", "interaction", "life-threatening")


def _facts(text: str) -> dict[str, bool]:
    found: dict[str, bool] = {}
    lower = text.lower()
    if not any(w in lower for w in _FACT_WORDS):
        return found
    for slot, pattern, polarity in _FACTS:
        if pattern.search(text):
            found[slot] = polarity if slot not in found or found[slot] == polarity else found[slot]
    for pattern, polarity in ((_NO_INTERACTION, False), (_INTERACTION, True)):
        for m in pattern.finditer(text):
            pair = "-".join(sorted(x.lower() for x in m.groups() if x)) or "*"
            found.setdefault(f"interaction:{pair}", polarity)
    return found


def contradictions(view: EpisodeView) -> list[str]:
    """Facts the agent asserted with opposite polarity in different turns."""
    seen: dict[str, tuple[bool, int]] = {}
    out: list[str] = []
    texts = list(view.turn_texts)
    if view.answer_text:
        texts.append((texts[-1][0] + 1 if texts else 0, view.answer_text))
    for turn, text in texts:
        for slot, polarity in _facts(text).items():
            if slot in seen and seen[slot][0] != polarity and seen[slot][1] != turn:
                out.append(f"{slot}: turn {seen[slot][1]} said {seen[slot][0]}, turn {turn} said {polarity}")
            seen[slot] = (polarity, turn)
    # "no interaction" with no pair named contradicts a later named major interaction and vice versa
    return out


def _stated_conclusions(view: EpisodeView) -> tuple[Any, Any]:
    """(last conclusion stated in the reasoning, the submitted one) for choice and ESI tasks."""
    task = view.task
    reasoning = [t for _, t in view.turn_texts if t]
    if task.answer_type == "choice":
        submitted = extract_choice(view.answer_text, task.options)
        stated = None
        for text in reasoning:
            letter = extract_choice(text, task.options, strict=True)
            if letter is not None:
                stated = letter
        return stated, submitted
    if task.answer_type in ("category", "numeric") and esi_levels(view.answer_text):
        submitted_levels = esi_levels(view.answer_text)
        stated_levels = None
        for text in reasoning:
            levels = esi_levels(text)
            if len(levels) == 1:
                stated_levels = levels
        return stated_levels, submitted_levels
    return None, None


def coherence_score(view: EpisodeView) -> tuple[float, dict[str, Any]]:
    attempted, why_not = real_attempt(view)
    if not attempted:
        return 0.0, {"conclusion": 0.0, "agreement": None, "consistency": None, "no_attempt": why_not}
    conclusion = 1.0
    if view.task.answer_type != "choice" and _HEDGE.search(view.final_text):
        conclusion = 0.5
    stated, submitted = _stated_conclusions(view)
    agreement = 0.0 if (stated is not None and submitted is not None and stated != submitted) else 1.0
    found = contradictions(view)
    consistency = max(0.0, 1.0 - 0.5 * len(found))
    score = CONCLUSION_W * conclusion + AGREEMENT_W * agreement + CONSISTENCY_W * consistency
    return score, {
        "conclusion": conclusion, "agreement": agreement, "consistency": consistency,
        "stated": sorted(stated) if isinstance(stated, set) else stated,
        "submitted": sorted(submitted) if isinstance(submitted, set) else submitted,
        "contradictions": found,
    }
