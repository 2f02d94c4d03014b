"""EHR domain: trends and record-derived scores on known data, order management writes, task set."""

from __future__ import annotations

import pytest

from envs import registry

registry.DOMAINS.setdefault("ehr_management", "envs.domains.ehr_management.environment")

from envs.domains.ehr_management import build as ehr_build  # noqa: E402
from envs.domains.ehr_management.tools import trend  # noqa: E402


@pytest.fixture(scope="module")
def built():
    return ehr_build.build()


@pytest.fixture
def env(built, monkeypatch):
    import envs.domains.ehr_management.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    return m.get_environment()


def call(env, name, **args):
    out = env.toolkit.call(name, args)
    assert out.ok, out.error
    return out.result


def test_trend_math_on_known_points():
    t = trend([("2025-01-01T00:00", 1.0), ("2025-01-02T00:00", 2.0), ("2025-01-03T00:00", 3.0)])
    assert t["delta"] == 2.0 and t["slope_per_day"] == pytest.approx(1.0) and t["direction"] == "rising"
    assert t["percent_change"] == 200.0 and t["min"] == 1.0 and t["max"] == 3.0
    flat = trend([("2025-01-01T00:00", 5.0), ("2025-01-01T12:00", 5.1)])
    assert flat["direction"] == "stable"


def test_lab_trend_matches_events(env):
    events = call(env, "get_lab_events", patient_id="EHR-010", test="potassium")["events"]
    t = call(env, "get_lab_trend", patient_id="EHR-010", test="potassium")
    values = [e["value"] for e in events]
    assert t["first"] == values[0] and t["last"] == values[-1] and t["max"] == max(values)
    assert t["direction"] == "falling"
    assert "at least 2" in env.toolkit.call("get_lab_trend", {"patient_id": "EHR-010", "test": "troponin_i"}).error


def test_sofa_from_record_uses_worst_values(env):
    from envs.calculators import calculate_sofa

    out = call(env, "calculate_sofa", patient_id="EHR-001")
    inp = out["inputs"]
    assert inp["on_mechanical_ventilation"] is True and inp["norepinephrine_mcg_kg_min"] > 0.1
    assert out["score"] == calculate_sofa(**inp).score
    adm = env.extras["ehr_tools"].chart("EHR-001").admissions[0]
    begin = adm.icu_stays[0].intime
    day1 = [e.value for e in adm.lab_events if e.test == "platelets" and e.time < out["window"][1] and e.time >= begin]
    assert inp["platelets_k_per_ul"] == min(day1)


def test_apache_and_news2_from_record(env):
    ap = call(env, "calculate_apache2", patient_id="EHR-022")
    assert 10 <= ap["score"] <= 50 and ap["inputs"]["age"] == env.extras["ehr_tools"].chart("EHR-022").age
    news = call(env, "calculate_news2", patient_id="EHR-001")
    assert news["on_supplemental_oxygen"] is True


def test_news2_refused_on_invasive_ventilation(env):
    # EHR-001 is intubated from ICU admission (2025-02-26T15:00) to 2025-03-01T03:00
    out = env.toolkit.call("calculate_news2", {"patient_id": "EHR-001", "at_time": "2025-02-27T12:00"})
    assert not out.ok and "invasive ventilation" in out.error
    assert call(env, "calculate_news2", patient_id="EHR-001", at_time="2025-03-01T11:00")["charted_at"] == "2025-03-01T11:00"


def test_orders_write_and_are_read_back(env):
    before = env.db.content_hash()
    call(env, "discontinue_order", patient_id="EHR-010", order_id="EHR-010-MED-1", reason="hyperkalaemia")
    meds = call(env, "get_medication_orders", patient_id="EHR-010", status="discontinued")["medication_orders"]
    assert [m["drug"] for m in meds] == ["lisinopril"]
    assert "not active" in env.toolkit.call("discontinue_order", {"patient_id": "EHR-010", "order_id": "EHR-010-MED-1",
                                                                  "reason": "again"}).error
    order = call(env, "place_order", patient_id="EHR-010", kind="lab", description="BMP in 6 hours", priority="urgent")
    assert order["order_id"].startswith("ORD-")
    call(env, "write_clinical_note", patient_id="EHR-010", note_type="progress", text="Stopped lisinopril for K 6.8; BMP in 6 h.")
    assert len(call(env, "get_clinical_notes", patient_id="EHR-010")["notes"]) == 2
    allergic = env.extras["ehr_tools"].chart("EHR-003")
    assert "penicillin" in allergic.allergies
    err = env.toolkit.call("order_medication", {"patient_id": allergic.patient_id, "drug": "piperacillin-tazobactam",
                                                "dose": 4.5, "dose_unit": "g", "route": "iv", "frequency": "q8h"}).error
    assert "allergic" in err
    assert env.db.content_hash() != before


def test_icd_coding(env):
    assert "not billable" in env.toolkit.call("assign_icd10_code", {"patient_id": "EHR-010", "icd10_code": "N17"}).error
    out = call(env, "assign_icd10_code", patient_id="EHR-010", icd10_code="n179")
    assert out["icd10_codes"] == ["N17.9"]


def test_tasks_splits_and_gold_replay(built, monkeypatch):
    import envs.domains.ehr_management.environment as m

    monkeypatch.setattr(m, "shared_toolkits", lambda: [])
    tasks = registry.get_tasks("ehr_management")
    splits = registry.get_splits("ehr_management")
    assert len(tasks) >= 450 and len(splits["validation"]) == 25
    workflows = [t for t in tasks if t.description.source == "authored"]
    assert len(workflows) >= 20
    for task in tasks:
        env = m.get_environment()
        env.on_reset(env, task)
        for action in task.evaluation_criteria.actions:
            out = env.toolkit.call(action.name, action.arguments)
            assert out.ok, (task.id, action.name, out.error)
        if task.evaluation_criteria.expected_db_hash:
            assert env.db.content_hash() == task.evaluation_criteria.expected_db_hash, task.id
