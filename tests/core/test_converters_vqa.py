"""The VQA converters added for the paper's suite: PMC-VQA, VQA-Med-2021, Quilt-VQA.

Fixtures are written by us in each benchmark's official layout (see the source notes in
envs/converters/formats.py): PMC-VQA's CSV with a BOM and CRLF line ends as a spreadsheet saves it.
"""

from pathlib import Path

import pytest

from envs.converters import convert
from envs.converters.base import SourceFileError

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"
IMAGES = FIX / "vqa_images"


def errors(result):
    return [(Path(e.path).name, e.line, e.message) for e in result.errors]


def test_pmc_vqa_choices_lose_their_letter_prefix_and_bad_rows_are_reported():
    result = convert("pmc-vqa", FIX / "pmc_vqa.csv", image_dir=IMAGES)
    assert len(result.tasks) == 2
    first, second = result.tasks
    assert first.options == {"A": "Diffuse uptake pattern", "B": "Focal uptake pattern", "C": "No uptake pattern",
                             "D": "Cannot determine from the information given"}
    assert first.correct_answer == "B" and first.answer_type == "choice" and first.domain == "visual_diagnosis"
    assert first.description.source == "pmc-vqa" and first.description.task_type == "vqa_choice"
    assert Path(first.image_path).name == "synpic100.jpg"
    # a quoted question with a comma, and "A: H&E " with a space after the colon
    assert second.ticket == "Which stain is shown, H&E or PAS?" and second.options["A"] == "H&E"
    assert errors(result) == [
        ("pmc_vqa.csv", 4, "Answer_label 'E' is not one of the choices ['A', 'B', 'C', 'D']"),
        ("pmc_vqa.csv", 5, f"image 'missing.jpg' not found in {IMAGES}"),
    ]


def test_pmc_vqa_wrong_header_names_the_missing_columns(tmp_path):
    bad = tmp_path / "test.csv"
    bad.write_text("image,question,answer\nx.jpg,q,a\n", encoding="utf-8")
    with pytest.raises(SourceFileError, match=r"header lacks column\(s\) \['Figure_path'"):
        convert("pmc-vqa", bad, image_dir=IMAGES)
    with pytest.raises(SourceFileError, match="image folder not found"):
        convert("pmc-vqa", FIX / "pmc_vqa.csv", image_dir=tmp_path / "no_such_folder")


def test_vqa_med_2021_pipe_lines():
    result = convert("vqa-med-2021", FIX / "vqa_med_2021.txt", image_dir=IMAGES)
    assert [t.answer_type for t in result.tasks] == ["exact", "choice"]
    open_task, closed_task = result.tasks
    assert open_task.correct_answer == "pulmonary embolism" and open_task.description.task_type == "vqa_open"
    assert closed_task.correct_answer == "B" and closed_task.options == {"A": "yes", "B": "no"}
    assert open_task.metadata["image_id"] == "synpic100" and open_task.image_path.endswith("synpic100.jpg")
    assert errors(result) == [
        ("vqa_med_2021.txt", 3, "expected 3 '|'-separated fields (image id|question|answer), got 2"),
        ("vqa_med_2021.txt", 4, f"image 'synpic999' not found in {IMAGES}"),
    ]


def test_quilt_vqa_closed_and_open():
    result = convert("quilt-vqa", FIX / "quilt_vqa.json", image_dir=IMAGES)
    closed, open_task = result.tasks
    assert closed.correct_answer == "A" and closed.description.task_type == "vqa_closed"
    assert open_task.correct_answer == "lymphocytes" and open_task.answer_type == "exact"
    assert open_task.description.source == "quilt-vqa"
    assert errors(result) == [("quilt_vqa.json", 3, "item 3: missing field 'answer'")]


def test_medlfqa_records_its_subset_file():
    result = convert("medlfqa", FIX / "medlfqa.jsonl")
    assert result.tasks[0].metadata["subset"] == "medlfqa"
