"""Triage domain: every tool on a known patient (values checked against hand computation), the
handbook import, and the task set (counts, splits, gold replay)."""

from __future__ import annotations

import re

import pytest

from envs import registry

registry.DOMAINS.setdefault("triage_emergency", "envs.domains.triage_emergency.environment")

from envs.domains.triage_emergency import build as tr_build  # noqa: E402


@pytest.fixture(scope="module")
def built():
    return tr_build.build()


@pytest.fixture
def env(built, monkeypatch):
    import envs.domains.triage_emergency.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    return m.get_environment()


def call(env, name, **args):
    out = env.toolkit.call(name, args)
    assert out.ok, out.error
    return out.result


def fails(env, name, **args) -> str:
    out = env.toolkit.call(name, args)
    assert not out.ok, f"{name} should have failed: {out.result}"
    return out.error


def test_reads_and_handbook_import(env):
    p = call(env, "get_patient_presentation", patient_id="ESI-002")
    assert p["age"] == 18 and "barely breathing" in p["chief_complaint"] and p["triage_status"] == "not yet triaged"
    v = call(env, "get_vital_signs", patient_id="ESI-002")["vitals"][0]
    assert v["respiratory_rate"] == 10 and v["spo2"] == 86 and "heart_rate" not in v
    assert call(env, "get_vital_signs", patient_id="ESI-001")["vitals"] == []
    assert "gcs_total" in call(env, "get_vital_signs", patient_id="ED-105")["vitals"][0]
    assert "not found" in fails(env, "get_vital_signs", patient_id="ED-999")


def test_calculators_fill_from_the_chart(env):
    # ED-105: E2 V3 M5, SBP 88, RR 32 -> GCS 10 (code 3), SBP code 3, RR code 3
    assert call(env, "calculate_gcs", patient_id="ED-105")["score"] == 10
    rts = call(env, "calculate_revised_trauma_score", patient_id="ED-105")
    assert rts["score"] == pytest.approx(0.9368 * 3 + 0.7326 * 3 + 0.2908 * 3, abs=1e-4)
    assert call(env, "calculate_revised_trauma_score", gcs=15, patient_id="ED-105")["components"]["gcs_code"] == 4
    # ED-103: RR 28, SBP 82, GCS 13 -> qSOFA 3
    assert call(env, "calculate_qsofa", patient_id="ED-103")["score"] == 3
    assert call(env, "calculate_qsofa", respiratory_rate=16, systolic_bp=130, altered_mentation=False)["score"] == 0
    assert call(env, "calculate_parkland", patient_id="ED-106")["score"] == 4 * 80 * 30
    assert call(env, "calculate_shock_index", patient_id="ED-117")["score"] == pytest.approx(118 / 92)
    # ED-124 NEWS2: RR 24 (2), SpO2 92 (2), air (0), T 38.3 (1), SBP 98 (2), HR 110 (1), voice (3) = 11
    news = call(env, "calculate_news2", patient_id="ED-124")
    assert news["score"] == 11
    assert "argument 'bun_mg_dl' is required" in fails(env, "calculate_curb65", patient_id="ED-107")
    call(env, "order_point_of_care_test", patient_id="ED-107", test="bun")
    # ED-107: confusion no, BUN 28 (1), RR 24 (0), BP 104/58 (1), age 72 (1) -> 3
    assert call(env, "calculate_curb65", patient_id="ED-107")["score"] == 3
    assert call(env, "calculate_centor", patient_id="ED-120", tonsillar_exudate_or_swelling=True,
                tender_anterior_cervical_nodes=True, cough_absent=True)["score"] == 4
    # ESI for the febrile toddler: 2 resources + HR 172 > 160 (danger zone for 3 months-3 years) -> ESI 2
    esi = call(env, "calculate_esi_level", patient_id="ED-118", requires_immediate_lifesaving_intervention=False,
               high_risk_situation=False, confused_lethargic_or_disoriented=False, severe_pain_or_distress=False,
               expected_resources=2)
    assert esi["score"] == 2
    assert "'eye'" in fails(env, "calculate_gcs", eye=5, verbal=5, motor=6)


def test_sepsis_screen_and_orders(env):
    s = call(env, "screen_sepsis", patient_id="ED-103")
    assert s["sirs_components"]["white_cells"] is None and "WBC not resulted" in s["note"]
    out = call(env, "order_point_of_care_test", patient_id="ED-103", test="wbc")
    assert out["value"] == 19.2
    call(env, "order_point_of_care_test", patient_id="ED-103", test="lactate")
    s = call(env, "screen_sepsis", patient_id="ED-103")
    assert s["sirs_criteria_met"] == 4 and s["qsofa"] == 3 and s["septic_shock_physiology"]
    assert s["screen"].startswith("positive")
    assert "already resulted" in fails(env, "order_point_of_care_test", patient_id="ED-103", test="wbc")
    assert "not available" in fails(env, "order_point_of_care_test", patient_id="ED-111", test="troponin_i")


def test_alerts_triage_and_notes_change_the_record(env):
    assert "obtain a 12-lead ECG" in fails(env, "activate_stemi_alert", patient_id="ED-101", ecg_findings="STE")
    ecg = call(env, "order_ecg", patient_id="ED-101")
    assert "STEMI" in ecg["value"]
    call(env, "activate_stemi_alert", patient_id="ED-101", ecg_findings="inferior ST elevation")
    call(env, "activate_stroke_code", patient_id="ED-102", deficits="right hemiparesis, aphasia")
    assert "13:10" in env.db.patients["ED-102"].alerts[0].detail
    call(env, "escalate_care", patient_id="ED-113", reason="anaphylaxis with stridor", level="resuscitation_team")
    out = call(env, "assign_triage_level", patient_id="ED-101", esi_level=2, rationale="high-risk chest pain")
    assert out["area"].startswith("acute care")
    assert env.db.patients["ED-101"].triage.esi_level == 2
    assert "esi_level must be 1-5" in fails(env, "assign_triage_level", patient_id="ED-101", esi_level=7)
    call(env, "write_triage_note", patient_id="ED-101", note="ECG inferior STEMI, cath lab activated at 14:02.")
    res = call(env, "get_ed_results", patient_id="ED-101")
    assert [a["kind"] for a in res["alerts"]] == ["stemi"] and len(res["notes"]) == 1


def test_tasks_and_splits(built):
    tasks = registry.get_tasks("triage_emergency")
    splits = registry.get_splits("triage_emergency")
    assert len(tasks) >= 380 and len(splits["validation"]) == 20
    ids = [set(v) for v in splits.values()]
    assert sum(map(len, ids)) == len(set().union(*ids)) == len(tasks)
    kinds = {t.description.task_type for t in tasks}
    assert {"esi_handbook", "esi_vignette", "triage_workflow", "calc_gcs", "calc_parkland"} <= kinds
    assert sum(t.description.task_type == "esi_handbook" for t in tasks) == 50
    assert sum(t.description.source == "authored" for t in tasks) >= 20
    assert {t.emergency for t in tasks} >= {"stemi", "stroke", "sepsis"}
    # each GCS vignette reads "a patient <verb> ..., <verb> ... and <verb> ..." (E1 once read "a patient no eye opening")
    gcs = [t.ticket for t in tasks if t.description.task_type == "calc_gcs"]
    assert gcs and all(re.match(r"After a head injury a patient (opens|does not open) ", tk) for tk in gcs), gcs[:3]


def test_gold_replay_and_calculator_answers(built, monkeypatch):
    import envs.domains.triage_emergency.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    for task in registry.get_tasks("triage_emergency"):
        env = m.get_environment()
        last = None
        for action in task.evaluation_criteria.actions:
            out = env.toolkit.call(action.name, action.arguments)
            assert out.ok, (task.id, action.name, out.error)
            last = out.result
        if task.description.source in ("generated_calculator", "generated_esi"):
            assert abs(float(last["score"]) - float(task.correct_answer)) <= (task.answer_tolerance or 0) + 1e-9, task.id
