"""Answer extraction: every option listed after an answer marker is no answer,
and an option's text given as the final answer after other options were discussed is that option."""

from __future__ import annotations

import pytest

from envs.core.task import Task
from envs.rewards import extract_choice, score_episode
from tests.rewards.builders import MC_OPTIONS, episode

OPTS = MC_OPTIONS  # A Vitamin A, B Vitamin C, C Iron, D Vitamin D
WOUND = {"A": "Rotator cuff tear", "B": "Pneumothorax due to pleural injury", "C": "Trapezius paresis",
         "D": "Traumatic carotid aneurysm", "E": "Brachial plexus injury"}


@pytest.mark.parametrize("text", [
    "Answer: A) Vitamin A, B) Vitamin C, C) Iron, D) Vitamin D",
    "Answer:\nA. Vitamin A\nB. Vitamin C\nC. Iron\nD. Vitamin D",
    "Answer: A. Vitamin A B. Vitamin C C. Iron D. Vitamin D",
    "The answer is A (Vitamin A), B (Vitamin C), C (Iron) or D (Vitamin D)",
    "Answer: (A) (B) (C) (D)",
    "Answer: A B C D",
    "Final answer: A; B; C; D",
    "Answer:\nA\nB\nC\nD",
    "Answer: Vitamin A, Vitamin C, Iron, Vitamin D",
    "**Answer:** A) Vitamin A\nB) Vitamin C\nC) Iron\nD) Vitamin D",
])
def test_every_option_listed_after_an_answer_marker_is_no_answer(text):
    # a reader taking the first letter after the marker would credit A
    assert extract_choice(text, OPTS) is None


@pytest.mark.parametrize("text, expected", [
    # one committed letter followed by its own option text is still an answer
    ("Answer: B) Vitamin C", "B"),
    ("Answer: B. Vitamin C, since A, Iron and D do not prevent scurvy", "B"),
    ("Answer: D\nReason: rickets", "D"),
    ("Reasoning about A and C first.\nD", "D"),
])
def test_a_single_committed_letter_is_still_an_answer(text, expected):
    assert extract_choice(text, OPTS) == expected


@pytest.mark.parametrize("text, expected", [
    ("Option A (rotator cuff tear) is unlikely and C (trapezius paresis) does not fit. "
     "The answer is pneumothorax due to pleural injury.", "B"),
    ("Rotator cuff tear and trapezius paresis are unlikely. Final answer: Pneumothorax due to pleural injury", "B"),
    ("I considered A, then C. Traumatic carotid aneurysm is rare. My final answer: Pneumothorax due to pleural injury.", "B"),
    ("A rotator cuff tear would not cause dyspnoea; so it is a pneumothorax due to pleural injury.", "B"),
    ("Brachial plexus injury fits the weakness, but the absent breath sounds point elsewhere. "
     "Most likely diagnosis: traumatic carotid aneurysm", "D"),
])
def test_option_text_as_the_final_answer_after_other_options_is_that_option(text, expected):
    # more than one option text appears in the whole answer; the final answer's text decides
    assert extract_choice(text, WOUND) == expected


@pytest.mark.parametrize("text", [
    # the last sentence negates the only option it names: no commitment
    "Rotator cuff tear is possible. It is not a pneumothorax due to pleural injury.",
    # after the marker two options are named: a hedge
    "Final answer: rotator cuff tear or trapezius paresis",
    # several options discussed, none given as the answer
    "Rotator cuff tear and trapezius paresis are both possible here.",
])
def test_option_texts_without_a_final_commitment_are_no_answer(text):
    assert extract_choice(text, WOUND) is None


def test_the_reward_follows_the_extraction():
    task = Task(id="t-wound", ticket="Penetrating wound above the clavicle: most likely complication?",
                options=dict(WOUND), correct_answer="B", answer_type="choice")
    listed = score_episode(episode(task, answer="Answer: A) Rotator cuff tear, B) Pneumothorax due to pleural "
                                                "injury, C) Trapezius paresis, D) Traumatic carotid aneurysm, "
                                                "E) Brachial plexus injury"), task)
    stated = score_episode(episode(task, answer="Not a rotator cuff tear. Final answer: pneumothorax due to "
                                                "pleural injury"), task)
    # a list of every option earns nothing; the option's text after a discussion earns full accuracy
    assert (listed.accuracy, stated.accuracy) == (0.0, 1.0)
    assert listed.details["accuracy"]["extracted"] is None and stated.details["accuracy"]["extracted"] == "B"
