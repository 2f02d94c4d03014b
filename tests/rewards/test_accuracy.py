"""Accuracy by answer type: choice, exact, numeric (tolerance, units), category, free text."""

from __future__ import annotations

import math

import pytest

from envs.core.task import Task
from envs.rewards.accuracy import (
    answer_accuracy,
    default_tolerance,
    esi_levels,
    score_free_text,
    stated_number,
)
from envs.rewards.similarity import bleu1, overlap_score, rouge1_f
from tests.rewards.builders import mc_task


def acc(answer: str, task: Task) -> float:
    result = answer_accuracy(answer, task)
    assert result is not None
    return result.score


def test_choice_reads_vitamin_d_as_text_not_letter():
    task = mc_task("D")
    assert acc("Vitamin D", task) == 1.0
    # the reference read "Vitamin D" in any text as D; here a wrong committed letter is wrong
    assert acc("Answer: A. (Vitamin D would also be reasonable)", task) == 0.0
    assert acc("A, B, C, D", task) == 0.0


def test_exact_answers():
    task = Task(ticket="First-line drug for type 2 diabetes?", correct_answer="Metformin", answer_type="exact",
                answer_aliases=["Glucophage"])
    assert acc("metformin", task) == 1.0
    assert acc("Answer: Glucophage.", task) == 1.0
    assert acc("Start metformin 500 mg twice daily", task) == 1.0
    assert acc("metformin or insulin", task) == 0.0
    assert acc("insulin", task) == 0.0


@pytest.mark.parametrize("answer, expected", [
    ("63.4", 1.0), ("CrCl = 63.42 mL/min", 1.0), ("The clearance is 63.5 mL/min", 0.0),
    ("about 63", 0.0), ("", 0.0), ("Age 60, weight 70 kg: CrCl is 63.4 mL/min", 1.0),
])
def test_numeric_default_tolerance_is_half_the_last_digit(answer, expected):
    task = Task(ticket="Compute CrCl.", correct_answer="63.4", answer_type="numeric", answer_unit="mL/min")
    assert acc(answer, task) == expected


def test_numeric_stated_tolerance_and_unit_conversion():
    task = Task(ticket="Dose?", correct_answer="500", answer_type="numeric", answer_unit="mg", answer_tolerance=10)
    assert acc("0.5 g", task) == 1.0
    assert acc("505 mg", task) == 1.0
    assert acc("511 mg", task) == 0.0
    assert acc("500 mL", task) == 0.0  # incompatible unit
    assert acc("500000 mcg", task) == 1.0


def test_default_tolerance_and_stated_number():
    assert default_tolerance("63.4") == pytest.approx(0.05)
    assert default_tolerance("4") == pytest.approx(0.5)
    assert stated_number("The score is 4 (range 0-5)") == (4.0, None)
    assert stated_number("1,200 mg per day", "mg") == (1200.0, "mg")


@pytest.mark.parametrize("answer, expected", [
    ("ESI 2", 1.0), ("ESI level 2 - high risk", 1.0), ("2", 1.0), ("Triage level 2", 1.0),
    ("ESI 3", 0.0), ("ESI 2 or 3", 0.0), ("level 1", 0.0),
])
def test_category_esi(answer, expected):
    task = Task(ticket="Assign the ESI triage level.", correct_answer="2", answer_type="category", answer_unit="ESI")
    assert acc(answer, task) == expected


def test_category_severity_and_scored_systems():
    sev = Task(ticket="Severity of warfarin + ibuprofen?", correct_answer="major", answer_type="category")
    assert acc("This is a major interaction.", sev) == 1.0
    assert acc("Severe bleeding risk", sev) == 1.0  # alias severe -> major
    assert acc("moderate", sev) == 0.0
    assert acc("major or moderate", sev) == 0.0
    birads = Task(ticket="Classify.", correct_answer="BI-RADS 4", answer_type="category")
    assert acc("BI-RADS category 4: suspicious", birads) == 1.0
    assert acc("BIRADS 3", birads) == 0.0


def test_esi_levels_parser():
    assert esi_levels("ESI 1") == {1}
    assert esi_levels("level 2 vs level 3") == {2, 3}
    assert esi_levels("no level given") == set()


def test_overlap_metrics_concrete_values():
    pred, ref = ["a", "b", "c", "d"], ["a", "b"]
    assert rouge1_f(pred, ref) == pytest.approx(2 * 0.5 * 1.0 / 1.5)
    assert bleu1(pred, ref) == pytest.approx(0.5)
    assert bleu1(["a"], ["a", "b"]) == pytest.approx(math.exp(1 - 2))
    assert overlap_score("pneumothorax due to pleural injury", "Pneumothorax due to pleural injury") == pytest.approx(1.0)
    assert overlap_score("rotator cuff tear", "Pneumothorax due to pleural injury") == 0.0


def test_free_text_overlap_without_embeddings_and_copy_guard():
    task = Task(ticket="A man falls onto a fence pole above the clavicle. What is the most likely result of this injury?",
                correct_answer="Pneumothorax due to pleural injury", answer_type="free_text")
    good = score_free_text("A pneumothorax from pleural injury", task)
    assert good.score == pytest.approx(overlap_score("A pneumothorax from pleural injury", task.correct_answer))
    assert good.score > 0.7
    assert good.details["semantic"] is False
    copied = score_free_text(task.ticket + " " + task.ticket, task)
    assert copied.score == 0.0 and copied.details["copied_question"]


def test_no_gold_answer_gives_none():
    task = Task(ticket="Do the workup.", evaluation_criteria={"actions": [{"name": "order_lab"}]})
    assert answer_accuracy("anything", task) is None
