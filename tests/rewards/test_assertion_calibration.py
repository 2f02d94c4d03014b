"""Calibration of the rule grader for NL assertions: what a gold replay did and
found counts, a negative criterion is broken only by the agent's own words and acts, and numbers
in a criterion must match. The full distribution over every task is bench/assertion_calibration.py."""

from __future__ import annotations

import json
import random
import statistics

import pytest

from envs import registry
from envs.core.task import Task
from envs.core.trajectory import ToolCallRecord, Trajectory, TurnRecord
from envs.rewards.assertions import RuleGrader, grade_assertions
from envs.rewards.view import EpisodeView
from tests.rewards.builders import call, episode, turn


def _task(*criteria: str) -> Task:
    return Task(id="t-calib", ticket="Pregnant patient P5 with severe-range blood pressure.", patient_id="P5",
                correct_answer="A", answer_type="category", evaluation_criteria={"nl_assertions": list(criteria)})


def _scores(trajectory, task, grader=None) -> list[float]:
    return [r.score for r in grade_assertions(EpisodeView(trajectory, task), grader or RuleGrader(use_observations=True)).nl]


@pytest.fixture(autouse=True)
def _keywords_only(monkeypatch):
    """Keyword grading only, so the numbers below do not depend on the embedding model."""
    import envs.rewards.assertions as assertions

    monkeypatch.setattr(assertions, "similarity_matrix", lambda queries, candidates: None)


def test_what_a_tool_returned_counts_as_evidence():
    task = _task("The agent reports FDA category A for magnesium sulfate.")
    result = json.dumps({"drug": "magnesium sulfate", "fda_pregnancy_category": "A", "source": "formulary"})
    replay = episode(task, turn(call("check_pregnancy_safety", {"drug": "magnesium sulfate", "patient_id": "P5"},
                                     result=result)), answer="A")
    # keywords: report, fda, category, magnesium, sulfate ("agent" is filler, "a" a stop word). With
    # the result: all but "report" -> recall 0.8 >= 0.7 -> 1.0. Without it only magnesium and sulfate
    # (the call's argument): recall 0.4 -> (0.4 - 0.2) / (0.7 - 0.2) = 0.4
    assert _scores(replay, task) == [1.0]
    assert _scores(replay, task, RuleGrader(use_observations=False)) == [pytest.approx(0.4)]
    # a failed call's text is no evidence
    failed = episode(task, turn(call("check_pregnancy_safety", {"drug": "magnesium sulfate"}, error="unknown patient")),
                     answer="A")
    assert _scores(failed, task)[0] < 0.5


def test_a_negative_criterion_is_broken_only_by_the_agents_own_acts():
    task = _task("The agent does not prescribe sildenafil.")
    checked = episode(task, turn(call("check_drug_interactions", {"patient_id": "P5", "drug": "sildenafil"},
                                      result="sildenafil + isosorbide mononitrate: contraindicated")), answer="A")
    prescribed = episode(task, turn(call("prescribe_medication", {"patient_id": "P5", "drug": "sildenafil",
                                                                  "dose_mg": 50}, result="ordered")), answer="A")
    # checking the interaction names sildenafil in a READ call and its result: not prescribing it
    # (before the calibration this scored 0); ordering it names both words -> present -> 0
    assert _scores(checked, task) == [1.0]
    assert _scores(prescribed, task) == [0.0]


def test_numbers_in_a_criterion_must_match():
    task = _task("The agent assigns ESI level 2.")
    right = episode(task, turn(call("assign_triage_level", {"patient_id": "P5", "esi_level": 2})), answer="A")
    wrong = episode(task, turn(call("assign_triage_level", {"patient_id": "P5", "esi_level": 3})), answer="A")
    # keywords assign, esi, level, 2 (a number weighs 3): right has all -> 1.0; wrong misses "2":
    # recall 3/6 = 0.5 -> (0.5 - 0.2) / (0.7 - 0.2) = 0.6 (unweighted, 3/4 = 0.75 gave 1.0)
    assert _scores(right, task) == [1.0]
    assert _scores(wrong, task) == [pytest.approx(0.6)]


def test_abbreviations_and_their_expansion_are_one_keyword():
    # "12-lead ECG" and "ECG" both read "electrocardiogram" (a standard ECG has 12 leads): keywords
    # order, electrocardiogram, both in "order electrocardiogram ..." -> 1.0
    task = _task("The agent orders a 12-lead ECG.")
    replay = episode(task, turn(call("order_ecg", {"patient_id": "P5"})), answer="A")
    assert _scores(replay, task) == [1.0]


def _answer_only(task: Task) -> Trajectory:
    submit = ToolCallRecord(name="submit_answer", arguments={"answer": task.correct_answer or ""}, format="hermes",
                            submit=True, result="ok")
    return Trajectory(task_id=task.id, domain=task.domain or "", submitted_answer=task.correct_answer or "",
                      terminated=True, turns=[TurnRecord(index=0, action="...", action_format="hermes", tool_calls=[submit])])


def test_gold_replays_score_above_other_episodes_on_a_sample():
    """One task with NL assertions per domain (fixed seed), replayed in its real environment."""
    from envs.validate import gold_replay

    rows = []
    for domain in registry.list_domains():
        try:
            tasks = [t for t in registry.get_tasks(domain) if t.evaluation_criteria.nl_assertions]
        except Exception:  # data not built on this machine
            continue
        if len(tasks) < 2:
            continue
        task, other = random.Random(14).sample(tasks, 2)
        gold_trajectory, _ = gold_replay(task, domain)
        other_trajectory, _ = gold_replay(other, domain)
        calibrated, baseline = RuleGrader(), RuleGrader(use_observations=False)

        def score(trajectory, grader):
            outcome = grade_assertions(EpisodeView(trajectory, task), grader)
            return outcome.score or 0.0

        rows.append({"domain": domain, "gold": score(gold_trajectory, calibrated),
                     "baseline_gold": score(gold_trajectory, baseline),
                     "other": score(other_trajectory, calibrated), "no_tools": score(_answer_only(task), calibrated)})
    if len(rows) < 3:
        pytest.skip("fewer than three domains built here")
    print("\n".join(f"{r['domain']}: gold {r['gold']:.2f} (baseline {r['baseline_gold']:.2f}), other task "
                    f"{r['other']:.2f}, gold answer without tools {r['no_tools']:.2f}" for r in rows))
    gold = [r["gold"] for r in rows]
    # the calibration raises what a gold replay earns and keeps it clearly above a competent episode
    # of another task and far above the bare gold answer
    assert statistics.mean(gold) > statistics.mean(r["baseline_gold"] for r in rows)
    assert statistics.mean(gold) >= statistics.mean(r["other"] for r in rows) + 0.15
    assert statistics.mean(gold) >= statistics.mean(r["no_tools"] for r in rows) + 0.3
    assert all(r["gold"] >= r["no_tools"] for r in rows)


def test_a_parenthesised_gloss_is_optional():
    task = _task("The agent orders a CK (or equivalent confirmatory tests).")
    replay = episode(task, turn(call("order_lab", {"patient_id": "P5", "test": "ck"})), answer="A")
    # all keywords: order, ck, equivalent, confirmatory, test -> 2/5 = 0.4 -> (0.4 - 0.2) / 0.5 = 0.4;
    # outside the parentheses: order, ck -> 2/2 -> 1.0, the higher one counts
    assert _scores(replay, task) == [1.0]
