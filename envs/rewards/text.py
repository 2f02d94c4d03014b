"""Text helpers shared by the reward dimensions: normalisation, tokens, numbers, negation."""

from __future__ import annotations

import math
import re
import unicodedata
from functools import lru_cache
from typing import Any

_NON_ALNUM = re.compile(r"[^0-9a-z]+")
_TOKEN = re.compile(r"[a-z0-9]+(?:\.[0-9]+)?")
_SENTENCE_SPLIT = re.compile(r"(?<=[.!?;])\s+|\n+")

STOPWORDS = frozenset(
    "a an the of to in on for with and or but is are was were be been being at by from as that this "
    "these those it its into than then there their they them he she his her him we our you your i "
    "me my do does did so if not no nor can could should would will may might must has have had "
    "which who whom what when where why how all any both each few more most other some such only "
    "own same too very just also about over under again further once per via".split()
)


def normalise_text(text: str) -> str:
    """Lower case, NFKC, every run of non-alphanumerics one space."""
    text = unicodedata.normalize("NFKC", text).lower()
    return _NON_ALNUM.sub(" ", text).strip()


def tokens(text: str) -> list[str]:
    """Lower-case word/number tokens ("0.5" stays one token)."""
    return _TOKEN.findall(text.lower())


def stem(word: str) -> str:
    """A tiny suffix stripper so that recommend/recommends/recommended compare equal."""
    for suffix in ("ations", "ation", "ings", "ing", "edly", "ed", "ies", "es", "s", "ly"):
        if len(word) > len(suffix) + 3 and word.endswith(suffix):
            return word[: -len(suffix)] + ("y" if suffix == "ies" else "")
    return word


def stemmed_tokens(text: str) -> list[str]:
    """Content tokens, lightly stemmed: what keyword graders compare."""
    return [stem(t) for t in tokens(text) if t not in STOPWORDS]


def sentences(text: str) -> list[str]:
    return [s for s in _SENTENCE_SPLIT.split(text) if s.strip()]


# -- numbers -------------------------------------------------------------------------------------
def as_number(value: Any) -> float | None:
    """A float for numbers and numeric strings ("1,000", " 5e2 ", "500.0"), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        try:
            number = float(value)
        except OverflowError:  # an integer beyond float range (e.g. 400 digits) is no usable number
            return None
        return number if math.isfinite(number) else None
    if isinstance(value, str):
        text = value.strip().replace(",", "")
        if not text or len(text) > 40:
            return None
        try:
            number = float(text)
        except ValueError:
            return None
        return number if math.isfinite(number) else None
    return None


_MAX_NORM_DEPTH = 64  # deeper arguments all compare equal to one marker instead of overflowing the stack


def norm_value(value: Any, _depth: int = 0) -> Any:
    """Canonical form for comparing tool arguments: case, whitespace and number formatting
    ("500", 500, "500.0", "5e2" are equal) do not matter; lists compare as multisets."""
    if _depth > _MAX_NORM_DEPTH:
        return ("o", "<nested too deep>")
    number = as_number(value)
    if number is not None:
        return ("n", round(number, 9))
    if isinstance(value, str):
        text = " ".join(unicodedata.normalize("NFKC", value).lower().split())
        return ("s", text)
    if isinstance(value, (list, tuple, set)):
        return ("l", tuple(sorted((norm_value(v, _depth + 1) for v in value), key=repr)))
    if isinstance(value, dict):
        return ("d", tuple(sorted((str(k).lower(), norm_value(v, _depth + 1)) for k, v in value.items())))
    if value is None:
        return ("none",)
    try:
        return ("o", repr(value))
    except ValueError:  # repr of an int over 4,300 digits raises
        return ("o", f"<{type(value).__name__}>")


def signature(name: str, arguments: dict[str, Any]) -> tuple:
    """A tool call's identity for counting repeats: its name and normalised arguments."""
    return (name.lower(), norm_value(arguments))


# -- negation ------------------------------------------------------------------------------------
_NEGATION = re.compile(
    r"\b(?:no|not|never|without|avoid|avoiding|avoided|don't|do not|does not|doesn't|did not|didn't|"
    r"no need|unnecessary|rather than|instead of|rule out|ruled out|rules out|denies|denied|"
    r"negative for|no longer|stop|stopped|discontinue|discontinued|hold|withhold|contraindicated|"
    r"allergic|allergy|allergies|unless|nor|refrain|decline|declined|defer|cannot|can't|shouldn't|"
    r"should not|must not|won't|will not)\b"
)
_HISTORY = re.compile(r"\b(?:history of|h/o|hx of|prior|previous|previously|family history|past)\b")
_BOUNDARY = re.compile(r"[.!?;\n]|\bbut\b|\bhowever\b")


def negated(text: str, start: int, window: int = 60, *, history: bool = False) -> bool:
    """True when a negation/avoidance cue precedes position `start` in the same clause
    (with `history=True`, also "history of", "prior", "previous": a past, not a current, event)."""
    left = text[max(0, start - window):start]
    cut = None
    for cut in _BOUNDARY.finditer(left):
        pass
    if cut is not None:
        left = left[cut.end():]
    left = left.lower()
    return _NEGATION.search(left) is not None or (history and _HISTORY.search(left) is not None)


def has_negation(sentence: str) -> bool:
    """True when a sentence contains any negation/avoidance cue."""
    return _NEGATION.search(sentence.lower()) is not None


@lru_cache(maxsize=4096)
def word_regex(phrase: str) -> re.Pattern[str]:
    """A case-insensitive whole-word regex for a phrase (cached)."""
    return re.compile(r"(?<![a-z0-9])" + re.escape(phrase.lower()) + r"(?![a-z0-9])")


def contains_phrase(text_lower: str, phrase: str) -> bool:
    return bool(phrase) and word_regex(phrase.lower()).search(text_lower) is not None


def clip01(value: float) -> float:
    return 0.0 if value < 0 else 1.0 if value > 1 else float(value)


def short(text: str, limit: int = 160) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


# -- negation scope --------------------------------------------------------------------------------
# Cues that take an object ("no routine follow-up", "avoid ibuprofen", "rather than ibuprofen"):
# followed by that object, they negate it and what follows up to the end of their clause, not the
# sentence's other clauses ("Assessment category: no routine follow-up" still states the category).
# Every other cue, or one of these with no object after it ("ibuprofen should be avoided", "avoid
# with warfarin"), negates its whole sentence: "not" ("ibuprofen is not appropriate", "ibuprofen:
# not recommended"), "must not", "contraindicated", "allergic" negate the subject before them.
_OBJECT_CUES = frozenset(
    "no without avoid avoiding stop discontinue hold withhold decline declined defer denies denied "
    "discontinued stopped".split()
) | {"rather than", "instead of", "rule out", "ruled out", "rules out", "negative for"}
_HARD_SPLIT = re.compile(r"(?<=[.!?;])\s+|\n+")
_CLAUSE_END = re.compile(r"[.!?;:,()\[\]\n]|\b(?:but|however|although|whereas|except)\b")
_DETERMINERS = frozenset("a an the any further more other all such".split())


def _object_follows(low: str, start: int, end: int) -> bool:
    words = [w for w in tokens(low[start:end]) if w not in _DETERMINERS]
    return bool(words) and words[0] not in STOPWORDS


def unnegated(text: str) -> str:
    """What `text` states without negation: each sentence without a cue as it is, a sentence whose
    cues all take an object ("no", "avoid", "without", "rather than", ...) with each negated object
    cut out up to the end of its clause, and nothing of a sentence with any other cue ("not",
    "contraindicated", "must not"), which negates its subject too. "" when nothing is left.

    "Category: no routine follow-up." -> "Category:"; "Give paracetamol rather than ibuprofen." ->
    "Give paracetamol"; "Avoid ibuprofen." -> ""; "Ibuprofen: not recommended." -> "".
    """
    if not has_negation(text):
        return text
    kept: list[str] = []
    for sentence in _HARD_SPLIT.split(text):
        low = sentence.lower()
        if len(low) != len(sentence):  # a character whose lower case is longer: positions would drift
            sentence = low
        cuts: list[tuple[int, int]] = []
        for cue in _NEGATION.finditer(low):
            stop = _CLAUSE_END.search(low, cue.end())
            end = stop.start() if stop else len(low)
            if cue.group(0) not in _OBJECT_CUES or not _object_follows(low, cue.end(), end):
                cuts = [(0, len(low))]
                break
            cuts.append((cue.start(), end))
        rest, at = [], 0
        for start, end in cuts:
            if start > at:
                rest.append(sentence[at:start])
            at = max(at, end)
        rest.append(sentence[at:])
        remnant = " ".join(" ".join(rest).split())
        if tokens(remnant):
            kept.append(remnant)
    return " ".join(kept)
