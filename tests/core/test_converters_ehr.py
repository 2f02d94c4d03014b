"""MIMIC-III v1.4 / eICU-CRD v2.0 CSV converters on hand-written fixture extracts (synthetic rows in the
release formats, never real data): tasks and gold answers, malformed rows reported with file and line,
and every imported task replaying in the EHR environment through the validator."""

from __future__ import annotations

import gzip
import shutil
from pathlib import Path

import pytest

from envs import registry
from envs.converters.base import SourceFileError
from envs.converters.ehr import MIMIC3_COLUMNS, convert_eicu, convert_mimic3, dotted_icd9, icd_system

registry.DOMAINS.setdefault("ehr_management", "envs.domains.ehr_management.environment")

FIX = Path(__file__).parents[1] / "fixtures" / "benchmarks"


def errors(result):
    return [(Path(e.path).name, e.line, e.message) for e in result.errors]


def answers(result):
    return {t.id: t.correct_answer for t in result.tasks}


def test_icd_helpers():
    assert [dotted_icd9(c) for c in ("0389", "99592", "V4581", "E8798", "486")] == [
        "038.9", "995.92", "V45.81", "E879.8", "486"]
    assert [icd_system(c) for c in ("995.92", "486", "V45.81", "E879.8", "R65.20", "I50.9", "V43.52XA")] == [
        "ICD-9-CM", "ICD-9-CM", "ICD-9-CM", "ICD-9-CM", "ICD-10-CM", "ICD-10-CM", "ICD-10-CM"]


def test_mimic3_tasks_and_gold():
    result = convert_mimic3(FIX / "mimic3")
    assert answers(result) == {
        # stay 2001: creatinine 2.4, 2.9, 3.3, 3.0 inside 05-01 12:00..05-04 18:00 (2.1 before, 1.8 after)
        "mimic3_last_creatinine_2001": "3", "mimic3_lab_trend_2001_creatinine": "rising", "mimic3_icu_los_2001": "3.25",
        "mimic3_primary_diagnosis_1001": "038.9",
        # stay 2002: 4.2, 3.1, 2.0; its LOS column (2.6) disagrees with the times (2.525 days): no LOS task
        "mimic3_last_creatinine_2002": "2", "mimic3_lab_trend_2002_creatinine": "falling",
        "mimic3_primary_diagnosis_1002": "584.9",
        # stay 2003: 0.9 -> 0.95 (+5.6%): stable
        "mimic3_last_creatinine_2003": "0.95", "mimic3_lab_trend_2003_creatinine": "stable", "mimic3_icu_los_2003": "1.00",
        "mimic3_primary_diagnosis_1003": "414.01",
    }
    by_id = {t.id: t for t in result.tasks}
    dx = by_id["mimic3_primary_diagnosis_1001"]
    assert dx.answer_aliases == ["0389"] and dx.answer_type == "exact" and dx.domain == "ehr_management"
    assert dx.evaluation_criteria.actions[0].name == "get_admission_diagnoses"
    record = by_id["mimic3_last_creatinine_2001"].metadata["ehr_patient"]
    assert record["patient_id"] == "MIMIC3-101" and record["age"] == 65 and record["sex"] == "male"
    adm = record["admissions"][0]
    assert adm["hadm_id"] == "1001" and adm["admission_diagnosis"] == "SEPSIS"
    tests = {e["test"] for e in adm["lab_events"]}
    assert tests == {"creatinine", "creatinine_urine", "lactate"}  # urine creatinine kept apart; HEMOLYZED skipped
    assert all(e["source_id"].startswith("LABEVENTS.csv:ROW_ID=") for e in adm["lab_events"])
    assert [d["code"] for d in adm["coded_diagnoses"]] == ["0389", "99592", "5849"]
    assert by_id["mimic3_last_creatinine_2002"].metadata["ehr_patient"]["age"] == 90  # DOB shifted: age > 89
    assert by_id["mimic3_last_creatinine_2001"].answer_unit == "mg/dL"


def test_mimic3_malformed_rows_reported_with_file_and_line():
    result = convert_mimic3(FIX / "mimic3")
    assert errors(result) == [
        ("PATIENTS.csv", 5, "GENDER 'X' is not M or F"),
        ("ADMISSIONS.csv", 5, "SUBJECT_ID 999 is not in PATIENTS"),
        ("ADMISSIONS.csv", 6, "ADMITTIME '2161-13-40 09:00:00' is not a time YYYY-MM-DD HH:MM:SS"),
        ("ICUSTAYS.csv", 3, "LOS 2.6 disagrees with OUTTIME - INTIME = 2.5250 days; no length-of-stay task for this stay"),
        ("ICUSTAYS.csv", 5, "HADM_ID 1005 is not in ADMISSIONS"),
        ("LABEVENTS.csv", 17, "VALUENUM 'abc' is not a number"),
        ("LABEVENTS.csv", 22, "ITEMID 99999 is not in D_LABITEMS"),
        ("LABEVENTS.csv", 23, "expected 9 fields, got 5"),
        ("DIAGNOSES_ICD.csv", 9, "ICD9_CODE 'SEPSIS' is not an ICD-9-CM diagnosis code"),
    ]


def test_eicu_tasks_gold_and_errors():
    result = convert_eicu(FIX / "eicu")
    assert answers(result) == {
        # unit stay 300001: creatinine 2.6, 2.2, 1.7 in the stay (1.9 at -60 min is pre-ICU); 2968 min = 2.06 days
        "eicu_last_creatinine_300001": "1.7", "eicu_lab_trend_300001_creatinine": "falling", "eicu_icu_los_300001": "2.06",
        # the primary diagnosis active upon discharge (severe sepsis), not the earlier pneumonia primary
        "eicu_primary_diagnosis_400001": "995.92",
        "eicu_last_creatinine_300002": "1.65", "eicu_lab_trend_300002_creatinine": "stable", "eicu_icu_los_300002": "2.99",
        "eicu_primary_diagnosis_400002": "428.0",
    }
    by_id = {t.id: t for t in result.tasks}
    assert by_id["eicu_primary_diagnosis_400001"].answer_aliases == ["R65.20"]
    record = by_id["eicu_icu_los_300002"].metadata["ehr_patient"]
    assert record["age"] == 90 and record["weight_kg"] == 81.0  # "> 89"
    stay = record["admissions"][0]["icu_stays"][0]
    assert (stay["intime"], stay["outtime"]) == ("2015-01-01T23:10:00", "2015-01-04T22:59:00")  # 23:10 + 4309 min
    assert errors(result) == [
        ("patient.csv", 4, "gender '' is not Male or Female"),
        ("patient.csv", 5, "age is empty"),
        ("lab.csv", 9, "labresult 'high' is not a number"),
        ("lab.csv", 15, "labresultoffset 'x' is not an integer"),
        ("lab.csv", 16, "patientunitstayid 399999 is not in patient.csv"),
        ("diagnosis.csv", 7, "diagnosispriority 'Urgent' is not Primary, Major or Other"),
    ]


def test_gzipped_release_files_and_limits(tmp_path):
    for src in (FIX / "mimic3").glob("*.csv"):
        with src.open("rb") as fin, gzip.open(tmp_path / f"{src.name}.gz", "wb") as fout:
            shutil.copyfileobj(fin, fout)
    plain, zipped = convert_mimic3(FIX / "mimic3"), convert_mimic3(tmp_path)
    assert answers(zipped) == answers(plain)
    one = convert_mimic3(FIX / "mimic3", max_stays=1)
    assert {t.id for t in one.tasks} == {"mimic3_last_creatinine_2001", "mimic3_lab_trend_2001_creatinine",
                                         "mimic3_icu_los_2001", "mimic3_primary_diagnosis_1001"}


def test_whole_file_problems_raise(tmp_path):
    with pytest.raises(SourceFileError, match="PATIENTS.csv .*not found"):
        convert_mimic3(tmp_path)
    for name in MIMIC3_COLUMNS:
        shutil.copy(FIX / "mimic3" / f"{name}.csv", tmp_path / f"{name}.csv")
    (tmp_path / "LABEVENTS.csv").write_text('"ROW_ID","SUBJECT_ID","HADM_ID","ITEMID","CHARTTIME","VALUE"\n')
    with pytest.raises(SourceFileError, match="LABEVENTS.csv: missing column\\(s\\) VALUENUM, VALUEUOM, FLAG"):
        convert_mimic3(tmp_path)
    with pytest.raises(SourceFileError, match="not a folder"):
        convert_eicu(tmp_path / "nope")


@pytest.fixture(scope="module")
def ehr_env():
    from envs.domains.ehr_management import build as ehr_build

    ehr_build.build()
    import envs.domains.ehr_management.environment as m

    return m


def test_imported_tasks_replay_and_pass_the_validator(ehr_env, monkeypatch):
    from envs.validate import validate_task

    imported = convert_mimic3(FIX / "mimic3").tasks + convert_eicu(FIX / "eicu").tasks
    built = ehr_env.get_tasks()
    monkeypatch.setattr(ehr_env, "shared_toolkits", lambda: [])
    monkeypatch.setattr(ehr_env, "get_tasks", lambda split=None: built + imported if split is None else imported)
    definitions = ehr_env.get_environment().toolkit.definitions
    for task in imported:
        report = validate_task(task, "ehr_management", definitions)
        assert report.ok, (task.id, report.problems)
        assert report.reward_components["accuracy"] == 1.0
    # the imported chart is the episode's: the patient is not in the built database
    env = ehr_env.get_environment()
    task = imported[0]
    assert task.patient_id not in ehr_env.store()
    env.on_reset(env, task)
    assert list(env.db.patients) == [task.patient_id]


def test_an_invalid_imported_record_names_the_task(ehr_env):
    from envs.core.db import DataFileError

    task = convert_eicu(FIX / "eicu").tasks[0]
    broken = task.model_copy(update={"metadata": {**task.metadata, "ehr_patient": {"patient_id": "EICU-x"}}})
    env = ehr_env.get_environment()
    with pytest.raises(DataFileError, match=f"task {task.id!r}: metadata\\['ehr_patient'\\]"):
        env.on_reset(env, broken)
