"""Drug-interaction tasks: counts, schema, fixed splits, gradeability, gold replay through the
validator, authored answers re-derived from the tools, and no train/test leakage."""

from __future__ import annotations

import collections
import json

import pytest

from envs.core.contamination import find_leaks
from envs.validate import validate_task
from envs.domains.drug_interaction import build as di_build
from envs.domains.drug_interaction import environment as di_env
from envs.domains.drug_interaction.generate import split_of


@pytest.fixture(scope="module")
def tasks():
    di_build.build()
    return di_env.get_tasks()


@pytest.fixture(scope="module")
def authored(tasks):
    return [t for t in tasks if t.description.source == "authored"]


def test_counts_and_types(tasks, authored):
    generated = [t for t in tasks if t.description.source != "authored"]
    assert len(generated) >= 200
    assert len(authored) >= 20
    types = collections.Counter(t.description.task_type for t in generated)
    # pregnancy_label_risk asks one task per verified label entry, so it is as large as that table
    from envs.domains.drug_interaction.logic import PREGNANCY_LABEL_RULES

    assert types.pop("pregnancy_label_risk") == len(PREGNANCY_LABEL_RULES)
    assert len(types) >= 12 and min(types.values()) >= 10, types
    answer_types = collections.Counter(t.answer_type for t in tasks)
    assert {"choice", "category", "numeric", "exact"} <= set(answer_types)
    for t in tasks:
        assert t.is_gradeable and t.has_gold_answer, t.id
        assert t.description.source and t.description.provenance.get("package"), t.id
        assert t.evaluation_criteria.actions, t.id
        if "P0" in t.ticket:
            assert t.patient_id and t.patient_id in t.ticket, t.id
        if t.answer_type == "numeric":
            assert t.answer_tolerance is not None and t.answer_unit, t.id
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 2 and len(t.evaluation_criteria.nl_assertions) >= 2, t.id
        assert "NL_ASSERTION" in t.evaluation_criteria.reward_basis


def test_splits_are_fixed_disjoint_and_complete(tasks):
    splits = di_env.get_splits()
    train, test = set(splits["train"]), set(splits["test"])
    assert not train & test
    assert train | test == {t.id for t in tasks}
    assert 0.1 < len(test) / len(tasks) < 0.3
    for task_id in list(train)[:50] + list(test)[:50]:
        assert (task_id in train) == (split_of(task_id) == "train")
    committed = json.loads((di_build.HERE / "split_tasks.json").read_text())
    assert committed["test"] and committed["train"]
    assert {t.id for t in di_env.get_tasks("test")} == test


def test_no_train_test_leakage(tasks):
    splits = di_env.get_splits()
    by_id = {t.id: t for t in tasks}
    leaks = find_leaks([by_id[i] for i in splits["train"]], [by_id[i] for i in splits["test"]])
    assert leaks == []


def test_expected_actions_succeed_on_a_fresh_database(tasks):
    for task in tasks:
        env = di_env.get_environment()
        for action in task.evaluation_criteria.actions:
            outcome = env.toolkit.call(action.name, action.arguments)
            assert outcome.ok, f"{task.id}: {action.name} failed: {outcome.error}"


def test_gold_replay_through_the_validator(tasks, authored):
    definitions = di_env.get_environment().toolkit.definitions
    sample = authored + [t for t in tasks if t.description.source != "authored"][::10]
    for task in sample:
        report = validate_task(task, "drug_interaction", definitions)
        assert report.ok, (task.id, report.problems)


def _results(task):
    env = di_env.get_environment()
    return [env.toolkit.call(a.name, a.arguments).result for a in task.evaluation_criteria.actions]


def test_authored_answers_agree_with_the_tools(authored):
    """Each authored gold answer, recomputed from what its own expected tool calls return."""
    checked = 0
    for task in authored:
        results = _results(task)
        by_tool = collections.defaultdict(list)
        for action, result in zip(task.evaluation_criteria.actions, results):
            by_tool[action.name].append((action.arguments, result))
        gold = task.correct_answer
        if task.answer_type == "category" and gold in ("contraindicated", "major", "moderate", "minor", "none"):
            proposals = [r for args, r in by_tool["check_patient_interactions"] if args.get("drug")]
            if proposals:
                assert proposals[0]["highest_severity_with_proposed_drug"] == gold, task.id
            else:
                assert by_tool["check_patient_interactions"][0][1]["highest_severity"] == gold, task.id
        elif "get_renal_dose_adjustment" in by_tool:
            assert by_tool["get_renal_dose_adjustment"][0][1]["adjustment_type"] == gold, task.id
        elif "check_hepatic_adjustment" in by_tool:
            assert by_tool["check_hepatic_adjustment"][0][1]["recommendation"] == gold, task.id
        elif "check_pregnancy_safety" in by_tool and task.answer_type == "category":
            assert by_tool["check_pregnancy_safety"][0][1]["fda_category"] == gold, task.id
        elif "get_dose_range" in by_tool:
            value = by_tool["get_dose_range"][0][1]["ranges"][0]["recommended_max_single_dose"]
            assert value == pytest.approx(float(gold)), task.id
        elif "find_safer_alternatives" in by_tool:
            out = by_tool["find_safer_alternatives"][0][1]
            best = {x["drug"] for x in out["safer_alternatives"] if x["worst_severity"] == "none"}
            chosen = task.options[gold] if task.options else gold
            assert chosen in best, task.id
            if not task.options:
                assert best == {gold, *task.answer_aliases}, task.id
        elif task.answer_type == "numeric":
            assert by_tool["check_patient_interactions"][0][1]["pair_count"] == int(gold), task.id
        elif task.options:
            drug = task.options[gold]
            assert all(not r["conflict"] for args, r in by_tool["check_allergy"] if args["drug"] == drug)
            assert any(r["conflict"] for _, r in by_tool["check_allergy"]), task.id
        else:
            raise AssertionError(f"{task.id}: no rule to re-derive its answer")
        checked += 1
    assert checked == len(authored)


def test_gym_episode_smoke(tasks):
    from envs.env import HealthcareGymEnv

    env = HealthcareGymEnv(domain="drug_interaction", task_id="di-auth-01-warfarin-nsaid", max_turns=4)
    obs, info = env.reset(seed=0)
    assert "P001" in obs and "Drug interaction and medication safety policy" in obs
    assert "check_patient_interactions" in {t["function"]["name"] for t in info["tools"]}
    call = {"name": "check_interaction", "arguments": {"drugs": ["ibuprofen", "warfarin"]}}
    obs, reward, terminated, truncated, info = env.step("<tool_call>" + json.dumps(call) + "</tool_call>")
    assert '"severity_level": "major"' in obs and not terminated
    assert env.observation_space.contains(obs)
    submit = {"name": "submit_answer", "arguments": {"answer": "minor", "reasoning": "wrong on purpose"}}
    _, reward, terminated, _, info = env.step("<tool_call>" + json.dumps(submit) + "</tool_call>")
    assert terminated and info["reward_components"]["accuracy"] == 0.0
