"""Task data whose natural-language assertions the gold solution satisfies.

The criteria of a task are written from its guideline; its expected actions and gold answer are the
reference solution. When a criterion asks for something the gold never does ("starts
anticoagulation" with no prescription among the expected actions), either the gold was incomplete
or the criterion was wrong, and the task data is fixed, not the grader. These tests replay the gold
of a sample of tasks per domain (`envs.validate.gold_replay`, the replay of `hcgym tasks
validate`) and grade it against the task's own assertions with the default rule grader: it must
score >= 0.9, and the gold replay of another task of the domain (a competent episode about the
wrong patient or question) must score clearly lower. The full distribution over every task is
bench/assertion_calibration.py.
"""

from __future__ import annotations

import pytest

from envs import registry
from envs.core.task import Task
from envs.validate import gold_replay
from envs.rewards.assertions import RuleGrader, grade_assertions
from envs.rewards.view import EpisodeView

DOMAINS = [d for d in registry.list_domains() if registry.DOMAINS[d].startswith("envs.domains.")]  # every built-in one
SAMPLE = 4  # tasks per domain, spread evenly over the domain's tasks with assertions


@pytest.fixture(autouse=True)
def _keywords_only(monkeypatch):
    """Keyword grading only: the gold must produce the criterion's content itself, and the figures do
    not depend on whether the embedding model is installed."""
    import envs.rewards.assertions as assertions

    monkeypatch.setattr(assertions, "similarity_matrix", lambda queries, candidates: None)


def _nl_only(task: Task) -> Task:
    criteria = task.evaluation_criteria.model_copy(update={"rubric": []})
    return task.model_copy(update={"evaluation_criteria": criteria})


def _score(trajectory, task: Task) -> tuple[float, list]:
    outcome = grade_assertions(EpisodeView(trajectory, _nl_only(task)), RuleGrader())
    return (outcome.score or 0.0), outcome.nl


def _sample(domain: str) -> list[Task]:
    tasks = [t for t in registry.get_tasks(domain) if t.evaluation_criteria.nl_assertions]
    if not tasks:
        pytest.skip(f"{domain}: no tasks with NL assertions in this build")
    step = max(1, len(tasks) // SAMPLE)
    return tasks[::step][:SAMPLE]


@pytest.mark.parametrize("domain", DOMAINS)
def test_gold_replays_satisfy_their_own_assertions_and_a_wrong_episode_does_not(domain):
    sample = _sample(domain)
    everything = [t for t in registry.get_tasks(domain) if t.evaluation_criteria.nl_assertions]
    for task in sample:
        replay, _ = gold_replay(task, domain)
        score, results = _score(replay, task)
        failing = [(r.text, r.score, r.reason) for r in results if r.score is not None and r.score < 0.9]
        assert score >= 0.9, f"{task.id}: gold replay scores {score:.2f} on its own assertions; {failing}"
        # a competent episode of another question: a different gold answer and different assertions (the
        # same workflow replayed on another patient would rightly meet these patient-agnostic criteria)
        other = next((t for t in everything if t.id != task.id and t.correct_answer != task.correct_answer
                      and t.evaluation_criteria.nl_assertions != task.evaluation_criteria.nl_assertions), None)
        if other is None:
            continue
        wrong_replay, _ = gold_replay(other, domain)
        wrong, _ = _score(wrong_replay, task)
        # clearly lower: below the bar the gold meets, and by a margin (tasks of one kind share their
        # process criteria, e.g. "confirms the code with an ICD-10-CM lookup", so the margin is not larger)
        assert wrong < 0.9 and wrong <= score - 0.15, f"{task.id}: the replay of {other.id} scores {wrong:.2f}, gold {score:.2f}"


# -- rare-disease questions the domain's ranking tool identifies ------------------------------------
def test_every_medical_qa_rare_disease_question_ranks_its_gold_in_the_top_three():
    """The phenotype list of an hpo_diagnosis question must identify its disease: the domain's own
    ranking tool (search_diseases_by_phenotypes) puts the gold in its top 3, else the question reads as
    one of its distractors and was dropped at generation."""
    env = registry.get_environment("medical_qa")
    tasks = [t for t in registry.get_tasks("medical_qa") if t.description.task_type == "hpo_diagnosis"]
    assert len(tasks) >= 150
    outside = []
    for t in tasks:
        out = env.toolkit.call("search_diseases_by_phenotypes", {"phenotypes": t.metadata["phenotypes"], "limit": 3})
        assert out.error is None, (t.id, out.error)
        if t.metadata["disease_id"] not in [r["disease_id"] for r in out.result["results"]]:
            outside.append(t.id)
    assert not outside, f"{len(outside)} rare-disease questions whose gold ranks below 3: {outside[:5]}"


def test_handbook_stroke_cases_activate_the_stroke_code():
    """AHA/ASA 2019: a suspected acute stroke at triage activates the stroke code, not only an ESI level."""
    stroke = [t for t in registry.get_tasks("triage_emergency") if t.emergency == "stroke"]
    assert any(t.id == "tr_esi_handbook_esi_037" for t in stroke)
    for t in stroke:
        names = [a.name for a in t.evaluation_criteria.actions]
        assert "activate_stroke_code" in names, t.id
        replay, _ = gold_replay(t, "triage_emergency")
        assert not [c.name for turn in replay.turns for c in turn.tool_calls if c.error], t.id
