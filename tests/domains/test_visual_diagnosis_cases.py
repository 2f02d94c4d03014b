"""The authored visual-diagnosis case files (`envs/domains/visual_diagnosis/cases/*.json`): the strict
schema names the file, the case and the field of every mistake; placeholders are filled from the
rendered image's values. Reads the case files only (no rendering)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from envs.core.db import DataFileError
from envs.domains.visual_diagnosis import case_schema
from envs.domains.visual_diagnosis.case_schema import CASES_DIR, fill, load_cases


def _copy_cases(tmp_path: Path) -> Path:
    folder = tmp_path / "cases"
    shutil.copytree(CASES_DIR, folder)
    return folder


def _edit(folder: Path, stem: str, change) -> None:
    path = folder / f"{stem}.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    change(data)
    path.write_text(json.dumps(data, indent=1), encoding="utf-8")


def _set(data, keys, value):
    for key in keys[:-1]:
        data = data[key]
    data[keys[-1]] = value


def test_the_committed_cases_load_in_study_id_order():
    cases = load_cases()
    assert len(cases) == 20
    assert [c.study_id for c, _ in cases] == [f"VIS-{i:03d}" for i in range(1, 21)]
    assert all(guideline.strip() for _, guideline in cases)
    assert {c.image.modality for c, _ in cases} == {"radiograph", "ct"}


@pytest.mark.parametrize(
    ("keys", "value", "field"),
    [
        (["cases", 1, "patient", "pack_year"], 5, "patient.pack_year"),  # a misspelt key is refused, not dropped
        (["cases", 1, "patient", "age"], "old", "patient.age"),
        (["cases", 1, "image", "side"], "both", "image.radiograph.side"),
        (["cases", 1, "image", "modality"], "mri", "image"),
        (["cases", 1, "answer_type"], "free text", "answer_type"),
        (["cases", 1, "actions"], [], "actions"),
        (["cases", 1, "study_id"], "VIS-2", "study_id"),
    ],
)
def test_a_malformed_case_names_file_case_and_field(tmp_path, keys, value, field):
    folder = _copy_cases(tmp_path)
    _edit(folder, "chest_radiograph", lambda data: _set(data, keys, value))
    with pytest.raises(DataFileError) as info:
        load_cases(folder)
    message = str(info.value)
    assert "chest_radiograph.json" in message and "case #2 'vis_a_pneumonia'" in message, message
    assert f"field '{field}'" in message, message


def test_a_missing_field_is_named(tmp_path):
    folder = _copy_cases(tmp_path)
    _edit(folder, "chest_ct", lambda data: data["cases"][0].pop("ticket"))
    with pytest.raises(DataFileError, match=r"chest_ct\.json \[case #1 'vis_a_growing_nodule'\] field 'ticket': Field required"):
        load_cases(folder)


def test_an_unknown_or_foreign_placeholder_is_refused(tmp_path):
    folder = _copy_cases(tmp_path)
    # a CT value named in a radiograph case
    _edit(folder, "chest_radiograph", lambda data: _set(data, ["cases", 2, "answer"], "{first_nodule_side}"))
    with pytest.raises(DataFileError, match=r"case #3 'vis_a_effusion_heart'\] .*answer: placeholder\(s\) \['first_nodule_side'\]"):
        load_cases(folder)
    folder = _copy_cases(tmp_path / "again")
    _edit(folder, "chest_ct", lambda data: _set(data, ["cases", 0, "actions", 3, "arguments", "side"], "{nodule_sid}"))
    with pytest.raises(DataFileError, match=r"actions\.3\.arguments: placeholder\(s\) \['nodule_sid'\]"):
        load_cases(folder)


def test_a_category_without_a_guideline_is_refused(tmp_path):
    folder = _copy_cases(tmp_path)
    _edit(folder, "chest_ct", lambda data: _set(data, ["cases", 2, "category"], "chest emergency"))
    with pytest.raises(DataFileError, match=r"chest_ct\.json \[case #3 'vis_a_part_solid'\] field 'category': 'chest emergency' "
                                            r"is not among the file's guidelines"):
        load_cases(folder)


def test_repeated_keys_and_ids_are_refused(tmp_path):
    folder = _copy_cases(tmp_path)
    path = folder / "chest_ct.json"
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace('"indication": "follow-up of a right lung nodule",',
                                 '"indication": "follow-up of a right lung nodule", "indication": "cough",', 1), encoding="utf-8")
    with pytest.raises(DataFileError, match=r"chest_ct\.json: case file repeats the key 'indication'"):
        load_cases(folder)
    folder = _copy_cases(tmp_path / "ids")
    _edit(folder, "chest_ct", lambda data: _set(data, ["cases", 0, "study_id"], "VIS-001"))
    with pytest.raises(DataFileError, match=r"chest_radiograph\.json: case study_id 'VIS-001' is already in .*chest_ct\.json"):
        load_cases(folder)


def test_placeholders_fill_with_the_value_or_its_formatted_text():
    values = {"cardiothoracic_ratio": 0.5912, "first_nodule_side": "left", "lesion_x": 101,
              "known_malignancy_aliases": ["a", "b"]}
    assert fill("{cardiothoracic_ratio:.2f}", values) == "0.59"
    assert fill("{first_nodule_side} lung", values) == "left lung"
    assert fill({"x": "{lesion_x}", "kept": 11.0, "n": ["{first_nodule_side}"]}, values) == {"x": 101, "kept": 11.0, "n": ["left"]}
    assert fill("{known_malignancy_aliases}", values) == ["a", "b"]
    assert fill("no placeholder", values) == "no placeholder"
    assert set(case_schema.VALUES["radiograph"]) >= {"cardiothoracic_ratio", "lesion_x"}
