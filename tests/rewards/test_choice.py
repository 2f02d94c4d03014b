"""extract_choice: the final committed option, never a letter inside a word or a name."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.rewards import extract_choice
from tests.rewards.builders import MC_OPTIONS

OPTS = MC_OPTIONS  # A Vitamin A, B Vitamin C, C Iron, D Vitamin D


@pytest.mark.parametrize("text, expected", [
    ("D", "D"), ("(B)", "B"), ("b", "B"), ("Option C.", "C"), ("**A**", "A"),
    ("Answer: D", "D"), ("Answer:D", "D"), ("the answer is (B)", "B"), ("Final answer - C", "C"),
    ("**Answer: C**", "C"), ("I choose B because ascorbic acid...", "B"), ("B is correct.", "B"),
    ("Option C is the best answer.", "C"), ("\\boxed{B}", "B"), ("<answer>B</answer>", "B"),
    ("I first thought A, but the final answer is C.", "C"),
    ("Vitamin D", "D"), ("The answer is Vitamin D", "D"), ("Rickets is caused by a lack of vitamin d.", "D"),
    ("Final answer: B. Vitamin C", "B"), ("The patient has type A dissection; answer is (C)", "C"),
])
def test_committed_answers(text, expected):
    assert extract_choice(text, OPTS) == expected


@pytest.mark.parametrize("text", [
    "A or C", "A, B, C, D", "A and B", "Answer: A or C", "either B or D", "the answer is (B) or (C)",
    "Both A and C are plausible", "Hepatitis B", "type A dissection", "I suspect Hepatitis B infection",
    "Answer: A patient with rickets needs...", "The answer is B cells", "Option A is wrong. Option C: unclear",
    "Hepatitis B is the most likely diagnosis", "", "   ", "Vitamin A or Vitamin D",
    "Which deficiency causes rickets? A. Vitamin A B. Vitamin C C. Iron D. Vitamin D",
])
def test_hedges_lists_and_names_are_not_answers(text):
    assert extract_choice(text, OPTS) is None


def test_option_text_answers_need_the_options():
    assert extract_choice("Hepatitis B", {"A": "Hepatitis A", "B": "Hepatitis B"}) == "B"
    assert extract_choice("The answer is B cells", {"A": "T cells", "B": "B cells"}) == "B"
    assert extract_choice("I suspect Hepatitis B", None) is None


def test_letters_outside_the_options_are_ignored():
    assert extract_choice("Answer: E", OPTS) is None
    assert extract_choice("Answer: E", None) == "E"


def test_strict_mode_reads_only_explicit_commitments():
    assert extract_choice("Vitamin D fits best", OPTS, strict=True) is None
    assert extract_choice("So the answer is D", OPTS, strict=True) == "D"


_NAME_WORDS = ["Vitamin", "Hepatitis", "type", "Type", "group", "Group", "factor", "Factor", "protein", "class", "hepatitis"]


@settings(max_examples=200, deadline=None)
@given(word=st.sampled_from(_NAME_WORDS), letter=st.sampled_from("ABCD"),
       prefix=st.sampled_from(["", "I think it is ", "Consider ", "The patient likely has ", "Labs suggest "]),
       suffix=st.sampled_from(["", " deficiency", " infection", ".", " with complications"]))
def test_property_letters_in_names_are_never_answers(word, letter, prefix, suffix):
    # options whose texts do not contain the phrase, so only a (wrong) letter reading could answer
    options = {"A": "Rickets", "B": "Scurvy", "C": "Pellagra", "D": "Beriberi"}
    assert extract_choice(f"{prefix}{word} {letter}{suffix}", options) is None


@settings(max_examples=100, deadline=None)
@given(letter=st.sampled_from("ABCD"), form=st.sampled_from(["Answer: {}", "The answer is ({})", "Final answer: {}.", "{}"]),
       lead=st.sampled_from(["", "Reasoning about vitamin D and Hepatitis B.\n", "Type A is unlikely.\n"]))
def test_property_committed_letter_is_found(letter, form, lead):
    assert extract_choice(lead + form.format(letter), OPTS) == letter


@settings(max_examples=100, deadline=None)
@given(letters=st.lists(st.sampled_from("ABCD"), min_size=2, max_size=4, unique=True),
       sep=st.sampled_from([", ", " or ", " and ", "/"]))
def test_property_lists_are_never_answers(letters, sep):
    assert extract_choice(sep.join(letters), OPTS) is None
    assert extract_choice("Answer: " + sep.join(letters), OPTS) is None
