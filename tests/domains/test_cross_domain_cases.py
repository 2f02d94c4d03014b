"""The cross-domain case files: the data rebuilds the committed pathways.json and split_tasks.json
byte for byte, every case names its guideline, and a malformed case file is refused with an error
naming the file, the case and the field."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from envs.core.db import DataFileError
from envs.domains.cross_domain import authoring
from envs.domains.cross_domain.authoring import rendering as render
from envs.domains.cross_domain.authoring.schema import EHRVitals
from envs.domains.cross_domain.pathway import Pathway

DOMAIN_DIR = authoring.HERE


def test_the_case_files_rebuild_the_committed_json_byte_for_byte():
    built = authoring.render()
    assert set(built) == {"pathways.json", "split_tasks.json"}
    for name, text in built.items():
        assert (DOMAIN_DIR / name).read_text(encoding="utf-8") == text, \
            f"{name} differs from what the case files build: run python -m envs.domains.cross_domain.authoring"


def test_every_case_renders_a_valid_pathway_and_names_its_guideline():
    cases = authoring.load_cases()
    assert len(cases) == len(json.loads((DOMAIN_DIR / "pathways.json").read_text(encoding="utf-8")))
    for title, case in cases:
        Pathway.model_validate(render.pathway(case, title))
        assert case.guideline.strip() and any(ch.isdigit() for ch in case.guideline), case.id  # a dated source
    test = [c.id for _, c in cases if c.split == "test"]
    assert len(test) == len(authoring.FAMILIES)  # one held-out variant per family


def test_derived_values_are_computed_not_written():
    row = EHRVitals(time="t", heart_rate=90, systolic_bp=120, diastolic_bp=60, respiratory_rate=16,
                    temperature_c=37.0, spo2=97)
    assert render.ehr_vitals(row)["map_mmhg"] == 80.0 and render.ehr_vitals(row)["gcs"] == 15
    _, case = next((t, c) for t, c in authoring.load_cases() if c.records.ehr_management)
    record = render.pathway(case, "x")["patients"]
    orders = record["ehr_management"]["admissions"][0]["medication_orders"]
    hadm = case.records.ehr_management.admission.hadm_id
    assert [o["order_id"] for o in orders[:len(case.patient.medications)]] == \
        [f"{hadm}-HOME{i + 1}" for i in range(len(case.patient.medications))]
    # the admission's orders follow the home medications in the chart and the pharmacy profile
    inpatient = [m.drug for m in case.records.ehr_management.admission.medication_orders]
    assert [m["drug"] for m in record["drug_interaction"]["medications"]][-len(inpatient):] == inpatient


def _copy_cases(tmp_path: Path) -> Path:
    folder = tmp_path / "cases"
    shutil.copytree(authoring.CASES_DIR, folder)
    return folder


def _edit(folder: Path, stem: str, change) -> Path:
    path = folder / f"{stem}.yaml"
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    change(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return path


def _set(data, keys, value):
    for key in keys[:-1]:
        data = data[key]
    data[keys[-1]] = value


@pytest.mark.parametrize(
    ("keys", "value", "field"),
    [
        # a misspelt key is refused, not dropped
        (["cases", 1, "patient", "medications", 0, "dose_mg"], 5, "patient.medications.0.dose_mg"),
        (["cases", 1, "records", "triage_emergency", "chief_complaint"], 42, "records.triage_emergency.chief_complaint"),
        (["cases", 1, "phases", 2, "max_calls"], 0, "phases.2.max_calls"),
        (["cases", 1, "phases", 0, "domain"], "cardiology", "phases.0.domain"),
        (["cases", 1, "guideline"], "", "guideline"),
        (["cases", 1, "split"], "validation", "split"),
        (["cases", 1, "vitals", 0, "avpu"], "asleep", "vitals.0.avpu"),
        (["cases", 1, "phases", 1, "gold_reasoning"], "", "phases.1.gold_reasoning"),
    ],
)
def test_a_malformed_case_names_file_case_and_field(tmp_path, keys, value, field):
    folder = _copy_cases(tmp_path)
    _edit(folder, "chest_pain", lambda data: _set(data, keys, value))
    with pytest.raises(DataFileError) as info:
        authoring.load_cases(folder)
    message = str(info.value)
    assert "chest_pain.yaml" in message and "case #2 'chest_pain_stemi_antiretroviral'" in message, message
    assert f"field {field}" in message, message


def test_a_missing_field_is_named(tmp_path):
    folder = _copy_cases(tmp_path)
    _edit(folder, "postop", lambda data: data["cases"][0]["records"]["ehr_management"]["admission"].pop("admit_time"))
    with pytest.raises(DataFileError, match=r"postop\.yaml: case #1 'postop_pulmonary_embolism': field "
                                            r"records\.ehr_management\.admission\.admit_time: Field required"):
        authoring.load_cases(folder)


def test_a_phase_without_its_gold_statement_is_refused(tmp_path):
    """Every phase states what the reference clinician concludes (the gold submission's reasoning), so an
    assertion about what the agent says or plans can be met by the gold."""
    folder = _copy_cases(tmp_path)
    _edit(folder, "stroke", lambda data: data["cases"][2]["phases"][2].pop("gold_reasoning"))
    with pytest.raises(DataFileError, match=r"stroke\.yaml: case #3 'stroke_code_anticoagulated': field "
                                            r"phases\.2\.gold_reasoning: Field required"):
        authoring.load_cases(folder)


def test_the_gold_reasoning_is_every_phase_statement_in_order():
    from envs.domains.cross_domain import environment as cross

    pathways = cross.load_pathways.__wrapped__(cross.PATHWAY_FILE)
    for _, case in authoring.load_cases():
        task = cross.pathway_task(pathways[case.id])
        reasoning = task.metadata["gold_reasoning"]
        assert reasoning.split("\n") == [p.gold_reasoning.strip() for p in case.phases], case.id


def test_yaml_syntax_errors_and_repeated_keys_name_the_line(tmp_path):
    folder = _copy_cases(tmp_path)
    path = folder / "stroke.yaml"
    lines = path.read_text(encoding="utf-8").splitlines()
    index = next(i for i, line in enumerate(lines) if line.startswith("  emergency:"))
    repeated = lines[: index + 1] + [lines[index]] + lines[index + 1:]
    path.write_text("\n".join(repeated) + "\n", encoding="utf-8")
    with pytest.raises(DataFileError, match=rf"stroke\.yaml: line {index + 2} not valid YAML: repeated key 'emergency'"):
        authoring.load_cases(folder)
    path.write_text("title: [unclosed\n", encoding="utf-8")
    with pytest.raises(DataFileError, match=r"stroke\.yaml: line \d+ not valid YAML"):
        authoring.load_cases(folder)


def test_repeated_ids_and_unlisted_files_are_refused(tmp_path):
    folder = _copy_cases(tmp_path)
    _edit(folder, "sepsis", lambda data: _set(data, ["cases", 1, "id"], data["cases"][0]["id"]))
    with pytest.raises(DataFileError, match=r"repeated case ids \['sepsis_bundle_urosepsis'\]"):
        authoring.load_cases(folder)
    folder = _copy_cases(tmp_path / "second")
    shutil.copy(folder / "sepsis.yaml", folder / "sepsis_extra.yaml")
    with pytest.raises(DataFileError, match=r"\['sepsis_extra.yaml'\] are not in authoring.FAMILIES"):
        authoring.load_cases(folder)


def test_a_missing_case_file_is_named(tmp_path):
    folder = _copy_cases(tmp_path)
    (folder / "diabetic.yaml").unlink()
    with pytest.raises(DataFileError, match=r"diabetic\.yaml: case file not found"):
        authoring.load_cases(folder)


def test_every_pathway_task_names_its_guideline_in_provenance():
    from envs.domains.cross_domain import environment as cross

    pathways = cross.load_pathways.__wrapped__(cross.PATHWAY_FILE)  # the committed file, not a cached copy
    by_id = {case.id: case for _, case in authoring.load_cases()}
    for pathway_id, pathway in pathways.items():
        task = cross.pathway_task(pathway)
        assert task.description.provenance["guideline"] == by_id[pathway_id].guideline, pathway_id
