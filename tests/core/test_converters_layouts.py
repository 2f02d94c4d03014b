"""Benchmark files in the layouts they are really distributed in (../shared/reference/benchmark_layouts.md):
MedMCQA's two `cop` numberings, the MIMIC-III demo's lower-case headers, BOMs, and `hcgym tasks import`
never overwriting good tasks or letting a duplicate id into a domain. Fixtures are hand-written rows in the
official layouts, never dataset files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from envs.cli import main
from envs.converters import convert
from envs.converters.ehr import convert_mimic3

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"


def errors(result):
    return [(Path(e.path).name, e.line, e.message) for e in result.errors]


# -- MedMCQA `cop` base -------------------------------------------------------------------------------
def test_medmcqa_hugging_face_layout_is_detected_as_zero_based():
    """The HF layout numbers `cop` 0-3: a 0 in the file means every row's gold is `cop` + 1 letters in,
    and the gold option text is the one the source marks (no answer one letter off)."""
    path = FIX / "medmcqa_hf.json"
    rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]
    result = convert("medmcqa", path)
    assert result.errors == [] and len(result.tasks) == 3
    for task, row in zip(result.tasks, rows):
        assert task.options[task.correct_answer] == row[("opa", "opb", "opc", "opd")[row["cop"]]]
    assert [t.correct_answer for t in result.tasks] == ["C", "A", "D"]
    assert any("0-based" in n and "cop of 0" in n for n in result.notes)


def test_medmcqa_original_layout_with_a_four_is_one_based(tmp_path):
    path = tmp_path / "dev.json"
    row = {"id": "o-1", "question": "q", "opa": "a", "opb": "b", "opc": "c", "opd": "d", "cop": 4}
    path.write_text(json.dumps(row) + "\n" + json.dumps(row | {"id": "o-2", "cop": 1}) + "\n", encoding="utf-8")
    result = convert("medmcqa", path)
    assert [t.correct_answer for t in result.tasks] == ["D", "A"]
    assert any("1-based" in n and "cop of 4" in n for n in result.notes)


def test_medmcqa_ambiguous_file_says_which_base_was_assumed_and_option_overrides():
    # medmcqa.json has only cop 3 (and an out-of-range 7): no 0, no 4
    result = convert("medmcqa", FIX / "medmcqa.json")
    assert [t.correct_answer for t in result.tasks] == ["C"]
    assert any("ASSUMED 1-based" in n and "--cop-base" in n for n in result.notes)
    forced = convert("medmcqa", FIX / "medmcqa_hf.json", cop_base=1)
    # cop 0 is out of range 1..4 when the user insists on the original numbering
    assert [t.correct_answer for t in forced.tasks] == ["B", "C"]
    assert errors(forced) == [("medmcqa_hf.json", 2, "field 'cop' 0 out of range 1..4")]
    assert any("set by --cop-base" in n for n in forced.notes)


def test_medmcqa_non_integer_cop_is_rejected_with_file_line_and_field():
    result = convert("medmcqa", FIX / "medmcqa_bad_cop.json")
    assert result.tasks == []
    errs = errors(result)
    assert [(name, line) for name, line, _ in errs] == [("medmcqa_bad_cop.json", 1), ("medmcqa_bad_cop.json", 2),
                                                        ("medmcqa_bad_cop.json", 3)]
    assert all("field 'cop' must be an integer" in msg for _, _, msg in errs)
    assert "2.5" in errs[0][2] and "True" in errs[1][2] and "'2'" in errs[2][2]


def test_medmcqa_file_with_both_a_zero_and_a_four_reports_the_four(tmp_path):
    path = tmp_path / "mixed.json"
    row = {"id": "m", "question": "q", "opa": "a", "opb": "b", "opc": "c", "opd": "d"}
    path.write_text(json.dumps(row | {"cop": 0}) + "\n" + json.dumps(row | {"id": "n", "cop": 4}) + "\n")
    result = convert("medmcqa", path)
    assert [t.correct_answer for t in result.tasks] == ["A"]
    assert errors(result) == [("mixed.json", 2, "field 'cop' 4 out of range 0..3")]
    assert any("also has a 4" in n for n in result.notes)


def test_medmcqa_test_split_without_cop_is_reported(tmp_path):
    path = tmp_path / "test.json"
    path.write_text(json.dumps({"id": "t", "question": "q", "opa": "a", "opb": "b", "opc": "c", "opd": "d"}) + "\n")
    assert errors(convert("medmcqa", path)) == [("test.json", 1, "missing field 'cop'")]


# -- MIMIC-III header case and BOM ---------------------------------------------------------------------
def test_mimic3_demo_lower_case_headers_convert_like_the_full_release():
    full = convert_mimic3(FIX / "mimic3")
    demo = convert_mimic3(FIX / "mimic3_demo")
    # same rows reported (by file, line and message) and the same tasks with the same gold
    assert full.tasks and errors(demo) == errors(full)
    assert {t.id: t.correct_answer for t in demo.tasks} == {t.id: t.correct_answer for t in full.tasks}


def test_mimic3_header_with_bom_keeps_the_first_column(tmp_path):
    folder = tmp_path / "mimic"
    shutil.copytree(FIX / "mimic3_demo", folder)
    for table in folder.glob("*.csv"):
        table.write_bytes(b"\xef\xbb\xbf" + table.read_bytes())
    assert {t.id for t in convert_mimic3(folder).tasks} == {t.id for t in convert_mimic3(FIX / "mimic3").tasks}


# -- ids ------------------------------------------------------------------------------------------------
def test_medqa_four_and_five_option_versions_of_a_question_get_different_ids():
    four = convert("medqa", FIX / "medqa_us_4options_sample.jsonl").tasks[0]
    five = convert("medqa", FIX / "medqa_us_5options_sample.jsonl").tasks[0]
    assert four.ticket == five.ticket and four.correct_answer == five.correct_answer
    assert four.id != five.id and len(five.options) == 5


# -- `hcgym tasks import`: names, failures, collisions --------------------------------------------------
@pytest.fixture
def data_root(tmp_path, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path / "data"))
    return tmp_path / "data" / "imported"


def test_default_output_is_named_after_the_source_file(data_root, capsys):
    assert main(["tasks", "import", "--format", "medqa", str(FIX / "medqa_us_4options_sample.jsonl")]) == 0
    assert main(["tasks", "import", "--format", "medqa", str(FIX / "medqa_us_5options_sample.jsonl")]) == 0
    folder = data_root / "medical_qa"
    assert sorted(p.name for p in folder.iterdir()) == ["medqa-medqa_us_4options_sample.json",
                                                         "medqa-medqa_us_5options_sample.json"]
    assert len(json.loads((folder / "medqa-medqa_us_4options_sample.json").read_text())) == 12


def test_import_summary_names_the_assumed_cop_base(data_root, capsys):
    assert main(["tasks", "import", "--format", "medmcqa", str(FIX / "medmcqa.json")]) == 0
    out = capsys.readouterr().out
    assert "ASSUMED 1-based" in out and "medmcqa.json:2:" in out


def test_import_where_every_row_fails_exits_non_zero_and_writes_nothing(data_root, tmp_path, capsys):
    good = tmp_path / "good.json"
    assert main(["tasks", "import", "--format", "medmcqa", "--output", str(good), str(FIX / "medmcqa_hf.json")]) == 0
    before = good.read_text()
    assert main(["tasks", "import", "--format", "medmcqa", "--output", str(good), "--replace",
                 str(FIX / "medmcqa_bad_cop.json")]) == 1
    err = capsys.readouterr().err
    assert "nothing was written" in err and "medmcqa_bad_cop.json:3: field 'cop' must be an integer" in err
    assert good.read_text() == before
    # the default output of a failed import is not created either
    assert main(["tasks", "import", "--format", "medmcqa", str(FIX / "medmcqa_bad_cop.json")]) == 1
    assert not (data_root / "medical_qa" / "medmcqa-medmcqa_bad_cop.json").exists()


def test_ids_colliding_with_an_existing_import_are_reported_by_id_and_file(data_root, tmp_path, capsys):
    assert main(["tasks", "import", "--format", "medmcqa", str(FIX / "medmcqa_hf.json")]) == 0
    copy = tmp_path / "medmcqa_hf_copy.json"
    lines = (FIX / "medmcqa_hf.json").read_text(encoding="utf-8").splitlines()
    extra = json.dumps({"id": "new", "question": "New one", "opa": "w", "opb": "x", "opc": "y", "opd": "z", "cop": 0})
    copy.write_text("\n".join(lines + [extra]) + "\n", encoding="utf-8")
    capsys.readouterr()
    assert main(["tasks", "import", "--format", "medmcqa", str(copy)]) == 0
    out = capsys.readouterr().out
    first = data_root / "medical_qa" / "medmcqa-medmcqa_hf.json"
    first_ids = [t["id"] for t in json.loads(first.read_text())]
    for task_id in first_ids:
        assert f"id {task_id} already defined in {first}" in out
    second = json.loads((data_root / "medical_qa" / "medmcqa-medmcqa_hf_copy.json").read_text())
    assert [t["ticket"] for t in second] == ["New one"] and "duplicate id 3" in out
    # re-importing the same file is refused without --replace, and with it rewrites its own output
    # rather than colliding with it
    assert main(["tasks", "import", "--format", "medmcqa", str(FIX / "medmcqa_hf.json")]) == 1
    assert "holds 3 tasks: not replaced (pass --replace" in capsys.readouterr().err
    assert main(["tasks", "import", "--format", "medmcqa", "--replace", str(FIX / "medmcqa_hf.json")]) == 0
    assert len(json.loads(first.read_text())) == 3


def test_duplicate_ids_inside_one_file_keep_the_first(data_root, tmp_path, capsys):
    path = tmp_path / "dups.jsonl"
    line = (FIX / "medqa_us_5options_sample.jsonl").read_text(encoding="utf-8")
    path.write_text(line + line, encoding="utf-8")
    assert main(["tasks", "import", "--format", "medqa", str(path)]) == 0
    out = capsys.readouterr().out
    assert "occurs more than once" in out and "imported 1 tasks" in out


def test_import_into_a_domain_not_built_yet(data_root, capsys):
    """visual_diagnosis has no authored task file: with no data build there is nothing to clash with, and
    the import still lands (the suite commands of evals/suites print exactly this command)."""
    images = FIX / "vqa_images"
    assert main(["tasks", "import", "--format", "vqa-rad", "--image-dir", str(images), str(FIX / "vqa_rad.json")]) == 0
    written = json.loads((data_root / "visual_diagnosis" / "vqa-rad-vqa_rad.json").read_text(encoding="utf-8"))
    assert len(written) == 2
