"""Known-input tests for tools that the domain test files exercise only indirectly."""

from datetime import datetime

import pytest

from envs import registry
from envs.env import HealthcareGymEnv


def test_ehr_get_vital_trend_matches_the_charted_series():
    env = registry.get_environment("ehr_management")
    out = env.toolkit.use_tool("get_vital_trend", patient_id="EHR-001", vital="heart_rate")
    assert out["vital"] == "heart_rate" and out["n"] >= 2
    assert out["delta"] == pytest.approx(out["last"] - out["first"])
    assert out["min"] <= min(out["first"], out["last"]) and out["max"] >= max(out["first"], out["last"])
    assert out["direction"] == ("falling" if out["slope_per_day"] < 0 else "rising" if out["slope_per_day"] > 0 else "stable")
    days = (datetime.fromisoformat(out["last_time"]) - datetime.fromisoformat(out["first_time"])).total_seconds() / 86400
    assert days > 0
    with pytest.raises(Exception, match="vital"):
        env.toolkit.use_tool("get_vital_trend", patient_id="EHR-001", vital="pulse_pressure")


def test_ehr_summarize_admission_agrees_with_the_lab_trend_tool():
    env = registry.get_environment("ehr_management")
    summary = env.toolkit.use_tool("summarize_admission", patient_id="EHR-001")
    assert summary["patient_id"] == "EHR-001" and summary["icu_stays"]
    bun = summary["labs"]["bun"]
    trend = env.toolkit.use_tool("get_lab_trend", patient_id="EHR-001", test="bun")
    assert (bun["first"], bun["last"]) == (trend["first"], trend["last"])
    assert "not found" in env.toolkit.call("summarize_admission", {"patient_id": "EHR-999"}).error


def test_medical_qa_get_question_returns_the_task_stem_and_options():
    env = HealthcareGymEnv(domain="medical_qa", task_id="mqa_a_icd_dm_ckd")
    env.reset(seed=0)
    question = env.domain_env.toolkit.use_tool("get_question")
    task = env.task
    assert question["question_id"] == task.id
    assert question["options"] == task.options
    assert question["stem"] in task.ticket


def test_visual_get_clinical_history_reads_the_study_record():
    env = registry.get_environment("visual_diagnosis")
    study = env.toolkit.db.studies["VIS-101"]
    history = env.toolkit.use_tool("get_clinical_history", study_id="VIS-101")
    assert history["study_id"] == "VIS-101"
    patient = study.patient if isinstance(study.patient, dict) else study.patient.model_dump()
    assert history["age"] == patient["age"] and history["sex"] == patient["sex"]
    assert "not found" in env.toolkit.call("get_clinical_history", {"study_id": "VIS-000"}).error.lower()
