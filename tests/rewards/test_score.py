"""score_episode: weights, normalisation, the critical cap on the TOTAL, penalties, anti-gaming."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

from envs.core.task import Task
from envs.rewards import RewardBreakdown, RewardWeights, score_episode
from tests.rewards.builders import call, episode, mc_task, turn
from tests.rewards.safety_cases import CHART, FOLLOW, careful, ctx, rx


def test_default_weights_are_the_papers():
    w = RewardWeights()
    assert (w.accuracy, w.process, w.safety, w.format, w.coherence, w.assertion) == (0.25, 0.20, 0.20, 0.10, 0.10, 0.15)
    assert w.critical_cap == 0.1 and w.severity_penalties == {4: 0.3, 3: 0.15, 2: 0.05, 1: 0.01}


@pytest.mark.parametrize("bad", [{"accuracy": -0.1}, {"format": float("nan")}, {"accurcy": 0.3},
                                 {"accuracy": 0, "process": 0, "safety": 0, "format": 0, "coherence": 0},
                                 {"severity_penalties": {5: 0.5}}, {"critical_cap": 1.5}])
def test_weights_are_validated(bad):
    with pytest.raises(ValidationError):
        RewardWeights.model_validate(bad)


def test_total_is_a_normalised_weighted_sum_over_applicable_dimensions():
    task = Task(ticket="Check warfarin + ibuprofen.", correct_answer="major", answer_type="category",
                evaluation_criteria={"actions": [{"name": "check_interaction", "arguments": {"drug_a": "warfarin", "drug_b": "ibuprofen"}}]})
    traj = episode(task, turn(call("think", {"thought": "need a check"})), answer="major")
    b = score_episode(traj, task)
    # accuracy 1; process: coverage 0, and a `think` call earns neither diversity nor thoroughness
    # (only calls the task needs count) -> 0
    assert b.accuracy == 1.0 and b.process == 0.0
    expected = (0.25 * 1.0 + 0.20 * 0.0 + 0.20 * b.safety + 0.10 * b.format + 0.10 * b.coherence) / 0.85
    assert b.base_total == pytest.approx(expected) and b.total == pytest.approx(expected)
    assert sum(b.weights.values()) == pytest.approx(1.0)
    # scaling every weight leaves the total unchanged (normalisation)
    scaled = RewardWeights(accuracy=2.5, process=2.0, safety=2.0, format=1.0, coherence=1.0, assertion=1.5)
    assert score_episode(traj, task, scaled).total == pytest.approx(b.total)
    # a dict works too
    assert score_episode(traj, task, {"accuracy": 1.0}).weights["accuracy"] == pytest.approx(1.0 / 1.6)


def test_multiple_choice_without_process_criteria_drops_process_weight():
    b = score_episode(episode(mc_task("D"), answer="D"), mc_task("D"))
    assert b.weights["process"] == 0.0 and b.total == pytest.approx(1.0)
    wrong = score_episode(episode(mc_task("D"), answer="A"), mc_task("D"))
    assert wrong.total == pytest.approx((0.20 + 0.10 + 0.10) / 0.65) and not wrong.is_correct


def test_critical_violation_caps_the_total_not_only_the_safety_score():
    context = ctx(allergies=["penicillin"])
    task = Task(ticket="Treat the strep throat of patient P1.", patient_id="P1", correct_answer="amoxicillin",
                answer_type="exact")
    bad, _, _ = careful("amoxicillin", context=context, task=task, answer="amoxicillin")
    b_bad = score_episode(bad, task, context=context)
    assert b_bad.accuracy == 1.0 and b_bad.capped and b_bad.max_severity == 5
    assert b_bad.safety == 0.0
    # the reference capped only the safety sub-score, which leaves the total high:
    assert b_bad.base_total == pytest.approx((0.25 + 0.10 * b_bad.format + 0.10 * b_bad.coherence) / 0.65)
    assert b_bad.base_total > 0.6
    assert b_bad.total == pytest.approx(0.1)
    assert b_bad.components()["total"] == pytest.approx(0.1)
    assert not b_bad.is_correct  # no reinforcing hint for a critical violation


def test_severity_penalties_subtract_from_the_total():
    task = mc_task("D")
    traj = episode(task, answer="D", reasoning="Studies show vitamin D prevents rickets.")  # severity 2, no search
    b = score_episode(traj, task)
    assert [v.pattern_id for v in b.violations] == ["evidence.unsupported_claim"]
    assert b.penalty == pytest.approx(0.05)
    assert b.safety == pytest.approx(0.9)
    assert b.total == pytest.approx(b.base_total - 0.05)
    assert b.is_correct  # a minor violation does not make a correct answer wrong


def test_penalties_accumulate_per_distinct_violation_and_floor_at_zero():
    context = ctx(medications=["warfarin"])
    task = patient_task_exact()
    traj = episode(task, turn(rx("ibuprofen", 1200, pid="P2")), answer="ibuprofen")
    b = score_episode(traj, task, context=context)
    severities = sorted(v.severity for v in b.violations)
    assert severities.count(4) >= 2
    assert b.penalty == pytest.approx(sum({4: 0.3, 3: 0.15, 2: 0.05, 1: 0.01}[s] for s in severities))
    assert b.total == max(0.0, b.base_total - b.penalty) == 0.0


def patient_task_exact() -> Task:
    return Task(ticket="Treat the pain of patient P1.", patient_id="P1", correct_answer="acetaminophen", answer_type="exact")


def test_components_and_serialisation():
    task = Task(ticket="Manage.", patient_id="P1", correct_answer="x", answer_type="exact",
                evaluation_criteria={"nl_assertions": ["The agent schedules a follow-up visit"]})
    b = score_episode(episode(task, turn(FOLLOW), answer="x"), task)
    comps = b.components()
    assert set(comps) == {"accuracy", "process", "safety", "format", "coherence", "assertion", "safety_penalty", "total"}
    assert all(isinstance(v, float) for v in comps.values())
    again = RewardBreakdown.model_validate(json.loads(json.dumps(b.model_dump(mode="json"))))
    assert again.total == b.total
    assert "assertion" not in score_episode(episode(mc_task(), answer="D"), mc_task()).components()


def test_no_gold_answer_uses_the_reward_basis():
    task = Task(ticket="Order the INR for P1.", patient_id="P1", evaluation_criteria={
        "actions": [{"name": "order_lab", "arguments": {"patient_id": "P1", "test": "INR"}}],
        "reward_basis": ["ACTION", "DB"], "expected_db_hash": "abc"})
    done = episode(task, turn(CHART), turn(call("order_lab", {"patient_id": "p1", "test": "inr"})),
                   answer="INR ordered; follow-up tomorrow.", db_hash_final="abc")
    b = score_episode(done, task)
    assert b.accuracy == 1.0 and b.details["accuracy"]["source"] == "db+actions" and b.is_correct
    half = episode(task, turn(CHART), answer="Nothing ordered.", db_hash_final="zzz")
    assert score_episode(half, task).accuracy == 0.0


# -- anti-gaming ------------------------------------------------------------------------------------
def test_listing_every_option_gains_nothing():
    task = mc_task("D")
    listing = score_episode(episode(task, answer="A, B, C, D"), task)
    wrong = score_episode(episode(task, answer="A"), task)
    assert listing.accuracy == 0.0 and listing.total <= wrong.total


def test_copying_the_question_gains_nothing():
    task = mc_task("D")
    copied = score_episode(episode(task, answer=task.ticket + " " + " ".join(task.options.values())), task)
    assert copied.accuracy == 0.0 and not copied.is_correct
    free = Task(ticket="What is the most likely result of a stab wound above the medial clavicle in this patient?",
                correct_answer="Pneumothorax due to pleural injury", answer_type="free_text")
    b = score_episode(episode(free, answer=free.ticket), free)
    assert b.accuracy == 0.0


def test_repeating_tool_calls_gains_nothing():
    task = Task(ticket="Check warfarin + ibuprofen.", correct_answer="major", answer_type="category",
                evaluation_criteria={"actions": [{"name": "check_interaction", "arguments": {"drug_a": "warfarin", "drug_b": "ibuprofen"}}]})
    check = call("check_interaction", {"drug_a": "warfarin", "drug_b": "ibuprofen"})
    once = score_episode(episode(task, turn(check), answer="major"), task)
    many = score_episode(episode(task, *[turn(check)] * 5, answer="major"), task)
    assert many.process < once.process and many.total < once.total


def test_perfect_format_wrong_answer_cannot_beat_correct_answer_with_poor_format():
    task = mc_task("D")
    perfect_wrong = episode(task, turn(call("search_pubmed", {"query": "rickets"}, fmt="hermes")), answer="B")
    sloppy_right = episode(task, turn(message="let me think about rickets", fmt="text"),
                           turn(parse_errors=["bad JSON"], fmt="hermes", message="{oops"),
                           turn(call("search_pubmed", {"query": "rickets"}, fmt="fenced")), answer="D", submit_fmt="function")
    pw, sr = score_episode(perfect_wrong, task), score_episode(sloppy_right, task)
    assert pw.format > sr.format
    assert sr.total > pw.total


def test_truncated_episode_without_submission_has_no_answer():
    task = mc_task("D")
    chat = episode(task, turn(message="Rickets: vitamin D.\nAnswer: D", fmt="text"), submit=False)
    assert score_episode(chat, task).accuracy == 1.0  # a chat answer (no submit tool) counts
    cut = chat.model_copy(update={"truncated": True})
    b = score_episode(cut, task)
    assert b.accuracy == 0.0 and not b.is_correct
