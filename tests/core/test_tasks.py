import json
from pathlib import Path

import pytest

from envs.core.db import DataFileError
from envs.converters.reference import import_reference_tasks
from envs.core.task import Task, load_tasks, parse_tasks
from envs import registry

FIXTURES = Path(__file__).parents[1] / "fixtures"


def test_ids_are_stable_content_hashes():
    a = Task(ticket="What is 2+2?", correct_answer="4", answer_type="numeric")
    b = Task(ticket="What is 2+2?", correct_answer="4", answer_type="numeric")
    c = Task(ticket="What is 2+3?", correct_answer="5", answer_type="numeric")
    assert a.id == b.id != c.id and a.id.startswith("task_")


def test_malformed_task_file_names_file_task_and_field(tmp_path):
    path = tmp_path / "tasks.json"
    path.write_text(json.dumps([
        {"id": "ok", "ticket": "fine", "correct_answer": "x", "answer_type": "exact"},
        {"id": "bad_one", "ticket": "q", "options": {"A": "1"}, "correct_answer": "C"},
        {"id": "bad_two", "ticket": "q", "evaluation_criteria": {"actions": [{"arguments": {}}]}},
    ]))
    with pytest.raises(DataFileError) as err:
        load_tasks(path)
    text = str(err.value)
    assert str(path) in text and "task 'bad_one'" in text and "correct_answer" in text
    assert "task 'bad_two'" in text and "evaluation_criteria.actions.0.name" in text
    path.write_text("[{")
    with pytest.raises(DataFileError, match="not valid JSON at line 1"):
        load_tasks(path)
    with pytest.raises(DataFileError, match="duplicate task id"):
        parse_tasks([{"id": "x", "ticket": "a"}, {"id": "x", "ticket": "b"}], source="mem")


def test_choice_task_validation():
    with pytest.raises(ValueError, match="not one of the option letters"):
        Task(ticket="q", options={"A": "a", "B": "b"}, correct_answer="E")
    t = Task(ticket="q", options={"A": "a", "B": "b"}, correct_answer="A")
    assert t.answer_type == "choice" and t.has_gold_answer and t.is_gradeable
    assert not Task(ticket="just talk").is_gradeable


def test_import_reference_format_reports_instead_of_dropping():
    result = import_reference_tasks(FIXTURES / "reference_format" / "tasks_reference.json", "ward",
                                    tool_names=set(registry.get_environment("ward").toolkit.tool_names))
    ids = [t.id for t in result.tasks]
    assert ids == ["ref_mcq_1", "ref_mcq_2"]
    first, second = result.tasks
    assert first.correct_answer == "B" and first.options["B"] == "Azithromycin"
    assert first.evaluation_criteria.nl_assertions == ["Mentions the allergy"]
    assert first.evaluation_criteria.actions[0].action_id == "a0"
    assert first.metadata["reference_description"] == {"extra_field": 3}
    assert second.correct_answer == "A" and second.options == {"A": "Atorvastatin", "B": "Metformin"}
    issues = "\n".join(result.issues)
    assert "ref_missing_tool" in issues and "order_ct_scan" in issues
    assert "ref_bad_answer" in issues and "task #4" in issues


def test_domain_import_failure_names_the_domain(monkeypatch):
    monkeypatch.setitem(registry.DOMAINS, "broken", "tests.fixtures.does_not_exist")
    registry.domain_module.cache_clear()
    with pytest.raises(registry.DomainLoadError, match="domain 'broken' failed to import"):
        registry.get_environment("broken")
    with pytest.raises(KeyError, match="unknown domain 'nope'"):
        registry.get_environment("nope")


def test_validator_on_ward_domain():
    from envs.validate import validate_domain

    reports = validate_domain("ward")
    assert [r.problems for r in reports] == [[], [], []]
    bad = Task(id="bad", ticket="q", correct_answer="x", answer_type="exact",
               evaluation_criteria={"actions": [{"name": "get_patient", "arguments": {"patient_id": 3, "oops": 1}},
                                                {"name": "no_such_tool"}]})
    from envs.validate import validate_task

    report = validate_task(bad, "ward", registry.get_environment("ward").toolkit.definitions)
    text = " | ".join(report.problems)
    assert "unknown argument 'oops'" in text and "no such tool" in text


def test_validator_checks_the_final_database_of_a_task_with_a_gold_answer():
    """A task with a gold answer and an expected final DB state: its gold replay must reach that state
    (accuracy grades the answer only, so the validator checks the hash itself)."""
    from envs.validate import gold_replay, validate_task

    definitions = registry.get_environment("ward").toolkit.definitions
    record = next(t for t in registry.get_tasks("ward") if t.id == "ward_record")
    trajectory, _ = gold_replay(record, "ward")
    right = record.model_copy(deep=True)
    right.evaluation_criteria.expected_db_hash = trajectory.db_hash_final
    assert validate_task(right, "ward", definitions).problems == []
    wrong = record.model_copy(deep=True)
    wrong.evaluation_criteria.expected_db_hash = "0" * 16
    problems = validate_task(wrong, "ward", definitions).problems
    assert problems == [f"gold replay: final DB hash {trajectory.db_hash_final} != expected_db_hash {'0' * 16}"]
