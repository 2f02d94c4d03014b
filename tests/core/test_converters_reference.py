"""Reference implementation task files (../shared/reference/reference_implementation.md) and the
import-time check of `hcgym tasks import`: the EHR legacy schema, renamed tools, "Answer: (C)",
cross_domain imports that load and replay, ungradeable tasks reported by reason, nothing replaced
without --replace, and the per-domain table. Task files are written here in the reference's layouts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from envs import registry
from envs.cli import main
from envs.converters.reference import REFERENCE_TOOL_RENAMES, convert_reference_task, import_reference_tasks
from envs.core.paths import data_dir
from envs.core.task import Task
from envs.validate import EMPTY_REQUIRED, NO_GOLD, static_problems

BUILT = data_dir() / "domains" / "ehr_management" / "db.json"
needs_build = pytest.mark.skipif(not BUILT.is_file(), reason="needs `hcgym data build` (the EHR and KB builds)")

# The EHR legacy schema, as in the reference's data/ehr_benchmarks files
LEGACY_EHR = {
    "id": "mimic_ehr_046", "domain": "ehr_management", "source": "mimic_iii", "category": "chart_review",
    "difficulty": "medium",
    "ticket": "Review the chart for admission MHADM_30452653 and name the primary diagnosis.",
    "patient_id": "MPAT_e54eb3dc", "hadm_id": "MHADM_30452653",
    "expected_actions": [{"tool": "get_patient_summary", "args": {"hadm_id": "MHADM_30452653"}},
                         {"tool": "get_lab_results", "args": {"hadm_id": "MHADM_30452653"}},
                         {"tool": "get_quality_indicators", "args": {"hadm_id": "MHADM_30452653"}}],
    "expected_answer": "Sepsis",
    "rubric": {"must_mention": ["sepsis", "lactate trend"]},
}


@pytest.fixture
def built_data(tmp_path, monkeypatch):
    """A data folder of our own for imports, sharing the built domains and KB (read only)."""
    if not BUILT.is_file():
        pytest.skip("needs `hcgym data build`")
    real = data_dir()
    root = tmp_path / "data"
    root.mkdir()
    for name in ("domains", "kb"):
        if (real / name).exists():
            (root / name).symlink_to(real / name)
    monkeypatch.setenv("HCGYM_DATA_DIR", str(root))
    return root


def test_legacy_ehr_schema_becomes_actions_answer_and_must_mention_assertions():
    data = convert_reference_task(dict(LEGACY_EHR), "ehr_management")
    task = Task.model_validate(data)
    names = [a.name for a in task.evaluation_criteria.actions]
    # renamed tools mapped to ours; the one with no counterpart stays (and is reported at import)
    assert names == ["summarize_admission", "get_lab_events", "get_quality_indicators"]
    first = task.evaluation_criteria.actions[0]
    # the task's patient_id fills the argument our tool requires and the reference's did not take
    assert first.arguments == {"hadm_id": "MHADM_30452653", "patient_id": "MPAT_e54eb3dc"}
    assert first.compare_args == ["hadm_id"]
    assert task.correct_answer == "Sepsis" and task.answer_type == "exact"
    assert task.evaluation_criteria.nl_assertions == ["The response mentions sepsis",
                                                      "The response mentions lactate trend"]
    assert [r.criterion for r in task.evaluation_criteria.rubric] == ["Mentions sepsis", "Mentions lactate trend"]
    assert {"ACTION", "NL_ASSERTION", "RUBRIC", "ANSWER"} <= set(task.evaluation_criteria.reward_basis)
    assert task.description.category == "chart_review" and task.description.source == "mimic_iii"


def test_rubric_keys_and_a_prose_expected_answer():
    raw = {"id": "x", "ticket": "Summarise.", "expected_answer": "The patient has improving renal function and stable "
                                                                  "haemoglobin over the admission.",
           "evaluation_criteria": {"actions": [], "rubric_keys": ["renal function", "haemoglobin"]}}
    task = Task.model_validate(convert_reference_task(raw, "ehr_management"))
    assert task.answer_type == "free_text"
    assert task.evaluation_criteria.nl_assertions == ["The response mentions renal function",
                                                      "The response mentions haemoglobin"]


@pytest.mark.parametrize("written", ["Answer: (C)", "answer: c", "The answer is C.", "Correct answer - (c)", "C)",
                                     "Answer: Ceftriaxone"])
def test_answer_letter_in_the_forms_the_reference_wrote(written):
    raw = {"id": "q", "ticket": "Which?", "options": {"A": "Ampicillin", "B": "Bactrim", "C": "Ceftriaxone"},
           "correct_answer": written}
    assert convert_reference_task(raw, "medical_qa")["correct_answer"] == "C"


def test_an_answer_that_names_no_option_is_still_rejected():
    raw = {"id": "q", "ticket": "Which?", "options": {"A": "x", "B": "y"}, "correct_answer": "Answer: (E)"}
    with pytest.raises(ValueError, match="not one of the option letters"):
        Task.model_validate(convert_reference_task(raw, "medical_qa"))


def test_rename_table_maps_only_to_tools_that_exist():
    if not BUILT.is_file():
        pytest.skip("needs `hcgym data build`")
    for domain, renames in REFERENCE_TOOL_RENAMES.items():
        # "*" renames apply in every domain of the project (the test-only "ward" domain has no knowledge tools)
        targets = [[d for d in registry.DOMAINS if d != "ward"]] if domain == "*" else [[domain]]
        for names in targets:
            for name in names:
                tools = set(registry.get_environment(name).toolkit.tool_names)
                if name == "cross_domain":
                    from envs.domains.cross_domain.environment import _imported_toolkit

                    tools = set(_imported_toolkit().tool_names)
                for reference_name, (ours, _) in renames.items():
                    assert ours in tools, f"{reference_name} -> {ours} is not a tool of {name}"


@needs_build
def test_static_problems_name_the_reason():
    definitions = registry.get_environment("ehr_management").toolkit.definitions
    empty = Task.model_validate(convert_reference_task(
        {"id": "e", "ticket": "t", "correct_answer": "x",
         "evaluation_criteria": {"actions": [{"name": "get_admission_info", "arguments": {}}]}}, "ehr_management"))
    assert [r for r, _ in static_problems(empty, "ehr_management", definitions)] == [EMPTY_REQUIRED]
    blank = Task.model_validate({"id": "b", "ticket": "t", "correct_answer": "x", "evaluation_criteria": {
        "actions": [{"name": "get_lab_trend", "arguments": {"patient_id": "P1", "test": ""}}]}})
    assert [r for r, _ in static_problems(blank, "ehr_management", definitions)] == [EMPTY_REQUIRED]
    no_gold = Task.model_validate({"id": "n", "ticket": "t", "evaluation_criteria": {
        "actions": [{"name": "summarize_admission", "arguments": {"patient_id": "P1"}}]}})
    assert [r for r, _ in static_problems(no_gold, "ehr_management", definitions)] == [NO_GOLD]


def _write(path: Path, tasks: list[dict]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(tasks, indent=2), encoding="utf-8")
    return path


CROSS = [
    {"id": "evid_cross_domain_ok", "ticket": "Which drug is first line for anaphylaxis?", "correct_answer": "epinephrine",
     "evaluation_criteria": {"actions": [{"name": "think", "arguments": {"thought": "anaphylaxis"}},
                                         {"name": "submit_answer", "arguments": {"answer": ""},
                                          "compare_args": ["answer"]}],
                             "nl_assertions": ["Names epinephrine"], "reward_basis": ["ACTION", "NL_ASSERTION"]}},
    {"id": "evid_cross_domain_empty", "ticket": "Explain BLS.", "correct_answer": "Basic life support ...",
     "evaluation_criteria": {"actions": [{"name": "search_wiki", "arguments": {}}],
                             "reward_basis": ["ACTION", "NL_ASSERTION"]}},
]


def test_reference_folder_import_table_reasons_and_cross_domain_loading(built_data, tmp_path, capsys):
    ref = tmp_path / "reference" / "data" / "domains"
    _write(ref / "cross_domain" / "tasks_auto_generated.json", CROSS)
    _write(ref / "ehr_management" / "tasks.json", [LEGACY_EHR, LEGACY_EHR | {
        "id": "mimic_ehr_047", "expected_actions": [{"tool": "get_patient_summary", "args": {"hadm_id": "H9"}}]},
        {"id": "mimic_ehr_048", "ticket": "Review the chart.", "patient_id": "P1",
         "expected_actions": [{"tool": "get_patient_summary", "args": {"hadm_id": "H9"}}]}])
    _write(ref / "full_4modality_clean" / "tasks.json", CROSS)  # a reference folder that is not a domain here
    assert main(["tasks", "import", "--format", "reference", str(ref)]) == 0
    out = capsys.readouterr().out
    assert "full_4modality_clean: skipped, 'full_4modality_clean' is not a domain here" in out
    lines = {line.split()[0]: line for line in out.splitlines() if line.split()[:1] in (["cross_domain"],
                                                                                          ["ehr_management"])}
    # domain, read, imported, rejected, reasons
    assert lines["cross_domain"].split()[1:4] == ["2", "1", "1"] and "empty required arguments 1" in lines["cross_domain"]
    assert lines["ehr_management"].split()[1:4] == ["3", "1", "2"]
    assert "unknown tool 1" in lines["ehr_management"] and "no gold answer 1" in lines["ehr_management"]
    assert "reference tool renamed get_patient_summary -> summarize_admission" in out
    # imported cross-domain tasks load with the domain (split 'imported') and replay to full accuracy
    from envs.validate import gold_replay

    imported = registry.get_tasks("cross_domain", "imported")
    assert [t.id for t in imported] == ["evid_cross_domain_ok"]
    assert [a.name for a in imported[0].evaluation_criteria.actions] == ["think"]  # submit_answer is graded as the answer
    _, info = gold_replay(imported[0], "cross_domain")
    assert info["reward_components"]["accuracy"] == 1.0
    assert len(registry.get_tasks("cross_domain")) == 27  # the 26 pathways and the import


def test_keep_ungradeable_and_replace(built_data, tmp_path, capsys):
    path = _write(tmp_path / "cross_domain" / "tasks.json", CROSS)
    assert main(["tasks", "import", "--format", "reference", str(path)]) == 0
    output = built_data / "imported" / "cross_domain" / "reference-tasks.json"
    assert [t["id"] for t in json.loads(output.read_text())] == ["evid_cross_domain_ok"]
    capsys.readouterr()
    # the same import again: refused, the file untouched
    before = output.read_text()
    assert main(["tasks", "import", "--format", "reference", "--keep-ungradeable", str(path)]) == 1
    assert "not replaced (pass --replace" in capsys.readouterr().err and output.read_text() == before
    assert main(["tasks", "import", "--format", "reference", "--keep-ungradeable", "--replace", str(path)]) == 0
    out = capsys.readouterr().out
    assert "kept though ungradeable: empty required arguments 1" in out
    assert [t["id"] for t in json.loads(output.read_text())] == ["evid_cross_domain_ok", "evid_cross_domain_empty"]


def test_an_id_of_the_domains_own_tasks_is_not_imported_again(built_data, tmp_path, capsys):
    own = registry.get_tasks("cross_domain")[0]
    clash = {"id": own.id, "ticket": "Again?", "correct_answer": "yes"}
    path = _write(tmp_path / "cross_domain" / "tasks.json", [clash, CROSS[0]])
    assert main(["tasks", "import", "--format", "reference", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"id {own.id} already defined in the 'cross_domain' domain's tasks" in out
    assert len(registry.get_tasks("cross_domain")) == 27


def test_first_n_problems_are_shown_with_the_count(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path / "data"))
    rows = [{"question": f"q{i}", "options": {"A": "a", "B": "b"}, "answer_idx": "Z"} for i in range(30)]
    rows.append({"question": "fine", "options": {"A": "a", "B": "b"}, "answer_idx": "A", "answer": "a"})
    path = tmp_path / "test.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in rows) + "\n", encoding="utf-8")
    assert main(["tasks", "import", "--format", "medqa", "--show-errors", "5", str(path)]) == 0
    out = capsys.readouterr().out
    assert "30 problem(s) in" in out and "(first 5; --show-errors N for more)" in out
    assert out.count("answer_idx 'Z' is not one of the options") == 5
    table = next(line for line in out.splitlines() if line.startswith("medical_qa"))
    assert table.split()[1:4] == ["31", "1", "30"] and "unreadable row 30" in table


def test_import_reference_tasks_counts_reasons():
    fixture = Path(__file__).parents[1] / "fixtures" / "reference_format" / "tasks_reference.json"
    result = import_reference_tasks(fixture, "ward", tool_names=set(registry.get_environment("ward").toolkit.tool_names))
    assert result.rows_read == 5 and len(result.tasks) == 2
    assert result.rejected == {"unknown tool": 1, "schema": 1, "not a task object": 1}


def test_empty_options_with_a_letter_and_a_basis_that_grades_nothing_are_refused():
    with pytest.raises(ValueError, match="options are empty but correct_answer is 'C'"):
        convert_reference_task({"id": "o", "ticket": "t", "options": {}, "correct_answer": "C"}, "medical_qa")
    with pytest.raises(ValueError, match=r"reward_basis \['STYLE'\] names nothing we grade"):
        convert_reference_task({"id": "b", "ticket": "t", "correct_answer": "x",
                                "evaluation_criteria": {"reward_basis": ["STYLE"]}}, "medical_qa")
    mcqa = convert_reference_task({"id": "m", "ticket": "t", "options": {"A": "x", "B": "y"}, "correct_answer": "B",
                                   "evaluation_criteria": {"reward_basis": ["MCQA"]}}, "medical_qa")
    assert mcqa["evaluation_criteria"]["reward_basis"] == ["ANSWER"]


def test_replay_at_import_reports_tasks_whose_gold_fails(built_data, tmp_path, capsys):
    # a legacy EHR task about a patient our EHR database does not have: its expected calls fail on replay
    unknown_patient = LEGACY_EHR | {"id": "mimic_ehr_900", "expected_actions": [
        {"tool": "get_patient_summary", "args": {"hadm_id": "MHADM_30452653"}}]}
    path = _write(tmp_path / "cross_domain" / "tasks.json", [CROSS[0]])
    ehr = _write(tmp_path / "ehr_management" / "tasks.json", [unknown_patient])
    assert main(["tasks", "import", "--format", "reference", "--replay", str(path)]) == 0
    assert main(["tasks", "import", "--format", "reference", "--replay", str(ehr)]) == 1
    captured = capsys.readouterr()
    assert "gold replay fails 1" in captured.out
    assert "mimic_ehr_900: not imported (gold replay fails): gold replay: call 'summarize_admission' failed" in \
        captured.err
    assert not (built_data / "imported" / "ehr_management").exists() or \
        not any((built_data / "imported" / "ehr_management").iterdir())


def test_a_damaged_file_in_a_reference_folder_is_named_and_the_others_import(built_data, tmp_path, capsys):
    ref = tmp_path / "domains"
    _write(ref / "cross_domain" / "tasks.json", [CROSS[0]])
    broken = ref / "ehr_management" / "tasks.json"
    broken.parent.mkdir(parents=True)
    broken.write_bytes(b'[\n {"id": "a", "ticket": "caf\xe9"}\n]\n')  # Latin-1, not UTF-8
    assert main(["tasks", "import", "--format", "reference", str(ref)]) == 1
    captured = capsys.readouterr()
    assert f"{broken}:2: not UTF-8 (byte 0xe9" in captured.err
    assert [t.id for t in registry.get_tasks("cross_domain", "imported")] == ["evid_cross_domain_ok"]
