from pathlib import Path

import pytest

from envs.converters import convert
from envs.converters.base import SourceFileError

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"


def errors(result):
    return [(Path(e.path).name, e.line, e.message) for e in result.errors]


def test_medqa_us_4_option_layout_imports_every_row():
    """Our 12-question sample in MedQA's US 4-option layout (question, answer text, options A-D,
    meta_info, answer_idx, metamap_phrases): every row becomes a task whose letter names the answer
    text (docs/benchmarks.md evaluates the demo policies on it)."""
    import json

    path = FIX / "medqa_us_4options_sample.jsonl"
    rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]
    result = convert("medqa", path)
    assert result.errors == [] and len(result.tasks) == len(rows) == 12
    for task, row in zip(result.tasks, rows):
        assert task.correct_answer == row["answer_idx"] and task.options[task.correct_answer] == row["answer"]
    assert len({t.id for t in result.tasks}) == 12


def test_medqa_rows_and_errors_with_line_numbers():
    result = convert("medqa", FIX / "medqa.jsonl")
    assert len(result.tasks) == 1
    task = result.tasks[0]
    assert task.correct_answer == "D" and task.options["D"] == "Nitrofurantoin" and task.domain == "medical_qa"
    assert task.description.source == "medqa"
    errs = errors(result)
    assert ("medqa.jsonl", 2, "answer_idx 'F' is not one of the options ['A', 'B']") in errs
    assert any(e[1] == 3 and "not valid JSON" in e[2] for e in errs)
    assert any(e[1] == 4 and "'options'" in e[2] for e in errs)


def test_medmcqa_one_based_cop():
    result = convert("medmcqa", FIX / "medmcqa.json")
    assert [t.correct_answer for t in result.tasks] == ["C"]
    assert result.tasks[0].options["C"] == "Ethosuximide"
    assert errors(result)[0][1] == 2 and "out of range 1..4" in errors(result)[0][2]
    zero = convert("medmcqa", FIX / "medmcqa.json", cop_base=0)
    assert zero.tasks[0].correct_answer == "D"


def test_mmlu_csv():
    result = convert("mmlu", FIX / "anatomy_test.csv")
    assert [t.correct_answer for t in result.tasks] == ["B", "C"]
    assert result.tasks[0].metadata["subject"] == "anatomy"
    assert errors(result) == [("anatomy_test.csv", 2, "expected 6 columns, got 3")]


def test_pubmedqa_yes_no_maybe():
    result = convert("pubmedqa", FIX / "pubmedqa.json")
    assert len(result.tasks) == 1 and result.tasks[0].correct_answer == "A"
    assert "Recurrence was lower" in result.tasks[0].ticket
    assert errors(result)[0][1] == 2 and "final_decision must be yes/no/maybe" in errors(result)[0][2]  # the file line of record 87654321


def test_medlfqa_rubric():
    result = convert("medlfqa", FIX / "medlfqa.jsonl")
    task = result.tasks[0]
    assert task.answer_type == "free_text" and len(task.evaluation_criteria.rubric) == 3
    assert task.evaluation_criteria.nl_assertions == ["Face drooping is a warning sign", "Call emergency services immediately"]
    assert errors(result)[0][1] == 2 and "'Question'" in errors(result)[0][2]


def test_vqa_formats_with_images():
    images = FIX / "vqa_images"
    rad = convert("vqa-rad", FIX / "vqa_rad.json", image_dir=images)
    assert [t.answer_type for t in rad.tasks] == ["choice", "exact"]
    assert rad.tasks[0].correct_answer == "A" and Path(rad.tasks[0].image_path).is_file()
    assert rad.tasks[0].domain == "visual_diagnosis"
    assert errors(rad) == [("vqa_rad.json", 3, f"item 3: image 'missing.jpg' not found in {images}")]
    slake = convert("slake", FIX / "slake.json", image_dir=images)
    assert len(slake.tasks) == 1 and slake.tasks[0].correct_answer == "B"  # the Chinese row is skipped
    path = convert("pathvqa", FIX / "pathvqa.json", image_dir=images)
    assert path.tasks[0].correct_answer == "necrosis" and path.tasks[0].image_path.endswith("train_0001.png")


def test_whole_file_problems_raise_clearly(tmp_path):
    with pytest.raises(SourceFileError, match="file not found"):
        convert("medqa", tmp_path / "nope.jsonl")
    with pytest.raises(SourceFileError, match="image folder not found"):
        convert("vqa-rad", FIX / "vqa_rad.json", image_dir=tmp_path / "no_such_folder")
    with pytest.raises(ValueError, match="unknown format"):
        convert("medqa2", FIX / "medqa.jsonl")
    bad = tmp_path / "p.json"
    bad.write_text("[1, 2]")
    with pytest.raises(SourceFileError, match="expected an object of pmid"):
        convert("pubmedqa", bad)


def test_ids_are_stable():
    a = convert("medqa", FIX / "medqa.jsonl").tasks[0].id
    b = convert("medqa", FIX / "medqa.jsonl").tasks[0].id
    assert a == b and a.startswith("medqa_")
