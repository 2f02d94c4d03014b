"""Multiple-choice answer extraction: the final *committed* option, or None.

The reference read "Vitamin D" as answer D and gave credit when the gold letter appeared
anywhere. Here a letter counts only where it is a committed answer:

1. the whole answer is a letter ("D", "(B)", "Option C.", "**A**");
2. an explicit commitment, the last one in the text wins: "Answer: D", "the answer is (B)",
   "final answer - C", "I choose B", "B is correct", "\\boxed{B}", "<answer>B</answer>", or a
   bare letter on the last line;
3. otherwise the text of exactly one option ("Pneumothorax due to pleural injury");
4. otherwise a single parenthesised letter "(C)" that is an option.

A hedge or a list ("A or C", "A, B, C, D", "either B or D") returns None, and so does every
option listed after an answer marker ("Answer: A) Vitamin A, B) Vitamin C, C) Iron, D) Vitamin D"
or one letter a line): a copy of the option list commits to nothing, it is not the first option.
A letter that is part of a word or a name ("Vitamin D", "Hepatitis B", "type A dissection",
"B cells") is never read as an option. An option's *text* given as the final answer after other
options were discussed ("A rotator cuff tear is unlikely ... Final answer: pneumothorax due to
pleural injury") is that option: the text after the last answer marker, or else the last sentence
when it names one option without negating it, decides.
"""

from __future__ import annotations

import re
from functools import lru_cache

from envs.rewards.text import negated, normalise_text

_DEFAULT_LETTERS = "ABCDEFGHIJ"

# Text that may follow a committed letter: end, punctuation, a connective, or a capitalised word
# (the option text: "Answer: B Pneumothorax"). A following lower-case word means the letter is
# an article or part of a name ("Answer: A patient ...", "answer is B cells").
_AFTER = (
    r"(?=\s*$|\s*[.,;:!?)\]}>*\"'`\-\u2013\u2014]|\s+(?:because|since|as|which|given|due|with|"
    r"here|based|per|for|from)\b|\s+[A-Z(\[])"
)
_HEDGE_AFTER = re.compile(
    r"^\s*(?:\)|\])?\s*(?:,|/|\bor\b|\band\b|&|\bvs\.?\b|\bversus\b)\s*(?:option\s+|choice\s+)?[(\[]?([A-J])[)\]]?(?![A-Za-z])"
)
_HEDGE_BEFORE = re.compile(r"(?:\beither\b|\bboth\b|\bbetween\b)\s*(?:option\s+|choice\s+)?[(\[]?\s*$", re.IGNORECASE)


def _commit_patterns(letters: str) -> list[re.Pattern[str]]:
    L = f"[{letters}]"
    verb = r"(?:\s+(?:is|was|would\s+be|will\s+be|should\s+be|must\s+be|=))?"
    sep = r"\s*(?:[:=\-\u2013\u2014]\s*)?"
    return [
        # "Answer: D", "final answer is (B)", "the correct answer would be option C", "answer - A"
        re.compile(
            r"(?i:\banswer" + verb + sep + r"(?:option\s+|choice\s+|letter\s+)?)"
            rf"[(\[]?\s*({L})\s*[)\]]?" + _AFTER
        ),
        # "correct option: B", "best choice is (C)", "my final response is D"
        re.compile(
            r"(?i:\b(?:final|correct|best|right|most\s+appropriate|most\s+likely|my)\s+(?:option|choice|response)"
            + verb + sep + r")"
            rf"[(\[]?\s*({L})\s*[)\]]?" + _AFTER
        ),
        # "I choose B", "I'd go with (C)", "I select option A", "we conclude B"
        re.compile(
            r"(?i:\b(?:i|we)(?:'d|\s+would|\s+will|'ll)?\s+(?:choose|chose|select|selected|pick|picked|go\s+with|"
            r"conclude|concluded|settle\s+on|submit|answer)\s*(?:that\s+)?(?:the\s+answer\s+is\s+)?"
            r"(?:option\s+|choice\s+|answer\s+)?)"
            rf"[(\[]?\s*({L})\s*[)\]]?" + _AFTER
        ),
        # "B is correct", "Option C is the best answer": the letter opens a sentence or follows "option"
        re.compile(
            rf"(?:^|(?<=[.!?:;\n]\s)|(?<=[.!?:;\n])|(?i:\boption\s+|\bchoice\s+))[(\[]?({L})[)\]]?\s+"
            r"(?i:is\s+(?:the\s+)?(?:correct|right|best|most\s+(?:likely|appropriate|accurate))|is\s+(?:the\s+)?answer)"
        ),
        # LaTeX box, XML-ish answer tags
        re.compile(rf"\\boxed\{{\s*(?:\\text\{{)?\s*[(\[]?({L})[)\]]?\s*\}}?\s*\}}"),
        re.compile(rf"(?i:<answer>)\s*[(\[]?\s*({L})\s*[)\]]?\s*(?:[.:\-]|</answer>|\s|$)"),
    ]


@lru_cache(maxsize=64)
def _compiled(letters: str) -> tuple[list[re.Pattern[str]], re.Pattern[str], re.Pattern[str]]:
    paren = re.compile(rf"(?<![A-Za-z0-9])[(\[]\s*([{letters}])\s*[)\]](?![A-Za-z0-9])")
    bare = re.compile(
        rf"^\s*(?:(?i:final\s+answer|answer|option|choice|letter)\s*[:\-=]?\s*)?[(\[]?\s*([{letters}])\s*[)\]]?\s*[.:)]?\s*$"
    )
    return _commit_patterns(letters), paren, bare


# An option letter written as a list item: "B)", "(B)", "B.", "B:", "B;", "B,", "B (text)", or a bare
# letter followed by another one or by the end ("A B C D"). Used only on the text *after* a
# commitment, to tell "Answer: A) ..., B) ..., C) ..., D) ..." (a copied option list) from an answer.
_LIST_ITEM = re.compile(
    r"(?<![A-Za-z0-9'])[(\[]?\s*([A-J])\s*(?:[)\]]|[.:;,](?=\s|$)|(?=\s*$)|(?=\s+\()|"
    r"(?=\s+(?:or|and)\b)|(?=\s+[(\[]?[A-J](?![A-Za-z0-9'])))"
)
# Where a final answer given as text starts: after the last of these markers.
_TEXT_MARKER = re.compile(
    r"(?i:\b(?:final\s+)?answer\b(?:\s+(?:is|was|would\s+be|will\s+be|should\s+be))?\s*[:=\-\u2013\u2014]?|"
    r"\b(?:most\s+likely|final|working)\s+diagnosis\b(?:\s+is)?\s*:?|"
    r"\b(?:i|we)(?:'d|\s+would|\s+will|'ll)?\s+(?:choose|chose|select|pick|go\s+with|conclude|concluded|settle\s+on)\b|"
    r"\bso\s+(?:it|this)\s+is\b|\btherefore\b|\bin\s+conclusion\b)"
)
_SENTENCE_END = re.compile(r"[.!?;\n]\s+|\n")


def _lists_every_option(tail: str, committed: str, letters: str) -> bool:
    """True when the text after a committed letter goes on to list the other options as items, so
    that together with the committed letter every option (at least three) is named: a copied
    option list, not an answer."""
    listed = {m.group(1) for m in _LIST_ITEM.finditer(tail[:600]) if m.group(1) in letters}
    named = listed | {committed}
    return len(letters) >= 3 and named >= set(letters) if len(letters) <= 6 else len(named) >= 4


def _trailing_bare_letters(clean: str, bare: re.Pattern[str]) -> set[str]:
    """Distinct letters on the trailing run of lines that are each a bare letter ("A\nB\nC\nD")."""
    found: set[str] = set()
    for line in reversed(clean.rstrip().split("\n")):
        match = bare.match(line) or (bare.match(line.upper()) if len(line.strip()) <= 12 else None)
        if not match:
            break
        found.add(match.group(1))
    return found


def _final_option_text(text: str, options: dict[str, str]) -> str | None:
    """The option whose text is given as the final answer when earlier text discusses others: the
    single option named after the last answer marker, else the single option named, not negated,
    in the last sentence."""
    markers = list(_TEXT_MARKER.finditer(text))
    if markers:
        found = _option_text_match(text[markers[-1].end():], options)
        if found is not None:
            return found
    whole = " " + normalise_text(text) + " "
    if all(f" {phrase} " in whole for _, phrase in _option_phrases(tuple(sorted(options.items())))):
        return None  # the question's option list, copied: no sentence of it is a commitment
    parts = _SENTENCE_END.split(text.strip())
    last = next((p for p in reversed(parts) if p.strip()), "")
    found = _option_text_match(last, options)
    if found is None:
        return None
    phrase = normalise_text(options[found])
    norm_last = normalise_text(last)
    position = norm_last.find(phrase)
    return None if position < 0 or negated(norm_last, position) else found


_LIST_ONLY = re.compile(r"^[\s(\[]*[A-J][)\]]?(?:\s*(?:,|/|\bor\b|\band\b|&)\s*[(\[]?[A-J][)\]]?)+[\s.]*$")
_STRIP = re.compile(r"\*\*|__|`")


@lru_cache(maxsize=4096)
def _option_phrases(items: tuple[tuple[str, str], ...]) -> tuple[tuple[str, str], ...]:
    """(letter, normalised option text), longest text first; empty texts dropped."""
    pairs = [(k, normalise_text(v)) for k, v in items]
    return tuple(sorted(((k, t) for k, t in pairs if t), key=lambda kt: -len(kt[1])))


def _option_text_match(text: str, options: dict[str, str]) -> str | None:
    """The single option whose text the answer states; None if none or several."""
    norm = " " + normalise_text(text) + " "
    if len(norm) < 3:
        return None
    found: list[tuple[str, str]] = []
    for letter, phrase in _option_phrases(tuple(sorted(options.items()))):
        if f" {phrase} " in norm:
            # an option contained in an already found longer one ("Vitamin D" in
            # "Vitamin D deficiency") is not a separate claim
            if not any(f" {phrase} " in f" {longer} " for _, longer in found):
                found.append((letter, phrase))
    if len(found) == 1:
        return found[0][0]
    return None


@lru_cache(maxsize=256)
def _letters(keys: tuple[str, ...]) -> str:
    return "".join(sorted(k for k in keys if len(k) == 1 and k.isalpha() and k.isupper()))


def extract_choice(text: str | None, options: dict[str, str] | list[str] | None = None, *,
                   strict: bool = False) -> str | None:
    """The option letter the text commits to, or None (no answer, a hedge, or a list).

    Args:
        text: The agent's answer (the `submit_answer` argument or its final message).
        options: The question's options `{"A": "text", ...}` (or just the letters); None means
            letters A-J with no option texts.
        strict: Only explicit commitments (steps 1-2), for reading reasoning text where options
            are discussed rather than chosen.

    Example:
        >>> opts = {"A": "Vitamin A", "B": "Vitamin C", "C": "Iron", "D": "Vitamin D"}
        >>> extract_choice("The answer is (B).", opts), extract_choice("Vitamin D", opts)
        ('B', 'D')
        >>> extract_choice("A or C", opts) is None, extract_choice("I suspect Hepatitis B", None) is None
        (True, True)
    """
    if not text or not isinstance(text, str):
        return None
    if isinstance(options, dict):
        letters = _letters(tuple(options))
        option_texts = options
    elif options:
        letters = _letters(tuple(options))
        option_texts = {}
    else:
        letters, option_texts = _DEFAULT_LETTERS, {}
    if not letters:
        return None
    clean = _STRIP.sub("", text).strip()
    if not clean:
        return None
    commits, paren, bare = _compiled(letters)

    # 1. the whole text is one letter (also lower case: "b", "(c)")
    whole = bare.match(clean) or (bare.match(clean.upper()) if len(clean) <= 12 else None)
    if whole:
        return whole.group(1)
    if _LIST_ONLY.match(clean.upper() if len(clean) <= 40 else clean):
        return None

    # 2. explicit commitments: the last one in the text wins; a hedged one means None
    last: tuple[int, str, int] | None = None
    for pattern in commits:
        for match in pattern.finditer(clean):
            if last is None or match.start(1) > last[0]:
                last = (match.start(1), match.group(1), match.end(1))
    lines = clean.rstrip().rsplit("\n", 1)
    if len(lines) == 2:  # a bare letter on the last line ("...reasoning...\nB") is a commitment
        tail = bare.match(lines[1]) or (bare.match(lines[1].upper()) if len(lines[1].strip()) <= 12 else None)
        if tail:
            if len(_trailing_bare_letters(clean, bare)) > 1:  # "Answer:\nA\nB\nC\nD": one letter a line
                return None
            offset = len(lines[0]) + 1
            last = (offset + tail.start(1), tail.group(1), offset + tail.end(1))
    if last is not None:
        start, letter, end = last
        if _HEDGE_AFTER.match(clean[end:end + 20]) or _HEDGE_BEFORE.search(clean[max(0, start - 20):start]):
            return None
        if _lists_every_option(clean[end:], letter, letters):
            return None
        return letter

    if strict:
        return None
    # 3. the text of exactly one option
    if option_texts:
        by_text = _option_text_match(clean, option_texts) or _final_option_text(clean, option_texts)
        if by_text is not None:
            return by_text

    # 4. one distinct parenthesised option letter, not part of a hedge
    found = {m.group(1) for m in paren.finditer(clean)}
    if len(found) == 1:
        match = paren.search(clean)
        assert match is not None
        if not _HEDGE_AFTER.match(clean[match.end():match.end() + 20]):
            return found.pop()
    return None
