"""Process, format and coherence dimensions on hand-built trajectories."""

from __future__ import annotations

import pytest

from envs.core.task import Task
from envs.rewards.coherence import coherence_score
from envs.rewards.format import format_score
from envs.rewards.process import action_coverage, process_score
from envs.rewards.view import EpisodeView
from tests.rewards.builders import call, episode, mc_task, turn


def drug_task(**kw) -> Task:
    return Task(
        ticket="Check the interaction between warfarin and ibuprofen for patient P7.",
        evaluation_criteria={"actions": [
            {"name": "check_interaction", "arguments": {"drug_a": "Warfarin", "drug_b": "ibuprofen"},
             "compare_args": ["drug_a", "drug_b"]},
            {"name": "get_patient_details", "arguments": {"patient_id": "P7", "verbose": True}, "compare_args": ["patient_id"]},
            {"name": "calculate_dose", "arguments": {"dose_mg": 500}},
        ]},
        correct_answer="major", answer_type="category", **kw)


def view(task, *turns, **kw) -> EpisodeView:
    return EpisodeView(episode(task, *turns, **kw), task)


# -- process ---------------------------------------------------------------------------------------
def test_coverage_normalises_case_whitespace_and_numbers():
    task = drug_task()
    v = view(task,
             turn(call("check_interaction", {"drug_a": "  WARFARIN ", "drug_b": "Ibuprofen", "extra": 1})),
             turn(call("get_patient_details", {"patient_id": "p7"})),
             turn(call("calculate_dose", {"dose_mg": "500.0"})),
             answer="major")
    coverage, matched, missing = action_coverage(v)
    assert coverage == 1.0 and missing == []


def test_coverage_ignores_failed_and_mismatched_calls():
    task = drug_task()
    v = view(task,
             turn(call("check_interaction", {"drug_a": "warfarin", "drug_b": "aspirin"})),
             turn(call("get_patient_details", {"patient_id": "P7"}, error="get_patient_details: boom")),
             turn(call("calculate_dose", {"dose_mg": 500.5})),
             answer="major")
    assert action_coverage(v)[0] == 0.0


def test_repeating_a_call_never_raises_the_process_score():
    task = drug_task()
    once = view(task, turn(call("check_interaction", {"drug_a": "warfarin", "drug_b": "ibuprofen"})), answer="major")
    thrice = view(task, *[turn(call("check_interaction", {"drug_a": "warfarin", "drug_b": "ibuprofen"}))] * 3, answer="major")
    p1, p3 = process_score(once), process_score(thrice)
    # coverage 1/3, diversity 1, thoroughness 1/3  -> 0.6/3 + 0.2 + 0.2/3
    assert p1.score == pytest.approx(0.6 / 3 + 0.2 * 1.0 + 0.2 / 3)
    assert p3.coverage == p1.coverage and p3.thoroughness == p1.thoroughness
    assert p3.diversity == pytest.approx(1 / 3)
    assert p3.score < p1.score


def test_rubric_takes_seventy_percent():
    task = Task(ticket="Manage.", correct_answer="x", answer_type="exact", evaluation_criteria={
        "actions": [{"name": "order_lab", "arguments": {"test": "inr"}}],
        "rubric": [{"criterion": "Calls order_lab", "kind": "required_tool", "points": 2}]})
    v = view(task, turn(call("order_lab", {"test": "INR"})), answer="x")
    result = process_score(v, rubric=0.5)
    base = 0.6 * 1.0 + 0.2 * 1.0 + 0.2 * 1.0
    assert result.score == pytest.approx(0.3 * base + 0.7 * 0.5)


def test_process_does_not_apply_without_expected_actions_or_rubric():
    assert process_score(view(mc_task(), answer="D")).applicable is False


# -- format ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt, expected_turn", [("json", 1.0), ("openai", 1.0), ("hermes", 1.0), ("function", 0.8), ("fenced", 0.8)])
def test_format_scores_per_call_format(fmt, expected_turn):
    task = mc_task()
    v = view(task, turn(call("think", {"thought": "rickets"}, fmt=fmt)), answer="D", submit_fmt=fmt)
    score, details = format_score(v)
    assert details["turn_scores"] == [expected_turn, expected_turn]
    assert score == pytest.approx(0.8 * expected_turn + 0.2)


def test_format_partial_structure_and_plain_text():
    task = mc_task()
    v = view(task,
             turn(message="I will search now", fmt="text"),
             turn(parse_errors=["<tool_call> block is not valid JSON"], fmt="hermes", message="oops"),
             turn(call("search_pubmed", {"query": "x"}, error="unknown tool 'search_pubmed'. Did you mean: search?")),
             turn(call("get_lab", {"x": 1}, error="get_lab: patient not found")),
             answer="D")
    score, details = format_score(v)
    assert details["turn_scores"] == [0.0, 0.5, 0.5, 1.0, 1.0]
    assert score == pytest.approx(0.8 * (3.0 / 5) + 0.2)


def test_plain_text_final_conclusion_is_fine_and_short_answers_need_structure():
    task = Task(ticket="Explain the mechanism.", correct_answer="ACE inhibition", answer_type="free_text")
    text_final = episode(task, turn(message="Lisinopril inhibits angiotensin-converting enzyme.", fmt="text"), submit=False)
    assert format_score(EpisodeView(text_final, task))[0] == pytest.approx(1.0)
    short = episode(task, turn(message="ACE.", fmt="text"), submit=False)
    assert format_score(EpisodeView(short, task))[0] == 0.0
    # a committed option letter is a conclusion for a choice task even though it is one character
    assert format_score(view(mc_task(), answer="D"))[1]["conclusion"] is True
    assert format_score(EpisodeView(episode(mc_task(), submit=False), mc_task()))[0] == 0.0


# -- coherence -------------------------------------------------------------------------------------
def test_coherence_penalises_reasoning_that_disagrees_with_the_answer():
    task = mc_task("C")
    agree = view(task, turn(call("think", {"thought": "Iron deficiency fits. The answer is C."})), answer="C")
    disagree = view(task, turn(call("think", {"thought": "I conclude A."})), answer="C")
    s_agree, _ = coherence_score(agree)
    s_dis, d = coherence_score(disagree)
    assert s_agree == pytest.approx(1.0)
    assert d["stated"] == "A" and d["submitted"] == "C" and d["agreement"] == 0.0
    assert s_dis == pytest.approx(0.6)


def test_coherence_submit_reasoning_counts_and_hedges_lose():
    task = mc_task("C")
    v = view(task, answer="C", reasoning="Therefore the answer is B.")
    assert coherence_score(v)[1]["agreement"] == 0.0
    hedge = view(task, answer="A or C")
    score, details = coherence_score(hedge)
    # a hedge commits to no option: no real attempt at an answer, so no coherence credit at all
    assert score == 0.0 and details["no_attempt"] == "no single option committed to"


def test_coherence_contradictions_between_turns():
    task = Task(ticket="Prescribe for P1.", patient_id="P1", correct_answer="x", answer_type="exact")
    v = view(task,
             turn(message="The patient has no known allergies.", fmt="text"),
             turn(message="Patient is allergic to penicillin, so avoid it.", fmt="text"),
             turn(message="There is no interaction between warfarin and ibuprofen.", fmt="text"),
             turn(message="Careful: major interaction between warfarin and ibuprofen.", fmt="text"),
             answer="Prescribe azithromycin 500 mg daily for 3 days; follow up in one week.")
    score, details = coherence_score(v)
    assert len(details["contradictions"]) == 2
    assert details["consistency"] == 0.0
    assert score == pytest.approx(0.8)


def test_coherence_esi_reasoning_vs_answer():
    task = Task(ticket="Assign the ESI triage level.", correct_answer="2", answer_type="category", answer_unit="ESI")
    v = view(task, turn(message="Vitals unstable: this is ESI 2.", fmt="text"), answer="ESI 3")
    assert coherence_score(v)[1]["agreement"] == 0.0
