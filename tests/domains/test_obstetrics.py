"""Obstetrics domain: CTG synthesis/interpretation, dating and hypertension rules, every tool on
known input, WRITE state, the task set, gold replay with full safety, and speed."""

from __future__ import annotations

import collections
import random
import statistics
import time
from datetime import date

import pytest

from envs import registry
from envs.validate import check_domain_contamination
from envs.core.tools import ToolError
from envs.domains.obstetrics import build as ob_build
from envs.domains.obstetrics import ctg as CTG
from envs.domains.obstetrics import generate as G
from envs.domains.obstetrics import rules

registry.DOMAINS.setdefault("obstetrics", "envs.domains.obstetrics.environment")


def use(toolkit, tool: str, **arguments):
    outcome = toolkit.call(tool, arguments)
    if outcome.error:
        raise ToolError(outcome.error)
    return outcome.result


@pytest.fixture(scope="module")
def built():
    return ob_build.build()


@pytest.fixture
def env(built):
    return registry.get_environment("obstetrics")


@pytest.fixture
def tk(env):
    return env.toolkit


@pytest.fixture(scope="module")
def tasks(built):
    return registry.get_tasks("obstetrics")


# -- pure rules ---------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", G.CTG_KINDS)
def test_ctg_interpretation_recovers_the_designed_tracing(kind):
    rng = random.Random(G.CTG_KINDS.index(kind))
    tracing, spec, gold = G.make_tracing(kind, rng, "T1")
    out = CTG.interpret(tracing.model_dump())
    assert out["category"] == gold == CTG.classify_spec(spec)
    assert out["baseline_bpm"] == spec["baseline"]
    if kind == "cat3_late":
        assert out["recurrent"]["late"] and out["variability"] == "absent"
    if kind == "cat1":
        assert out["accelerations"] >= 1 and out["deceleration_summary"]["late"] == 0


def test_ctg_rejects_short_tracing():
    with pytest.raises(ValueError, match="too short"):
        CTG.interpret({"fhr": [140] * 100, "contractions": [], "sample_interval_s": 2})


def test_dating_rules():
    out = rules.gestational_age(date(2026, 1, 1), lmp=date(2025, 6, 1))
    assert out["best_estimate"]["days"] == 214 and out["best_estimate"]["ga"] == "30 weeks 4 days"
    assert out["best_estimate"]["edd"] == "2026-03-08"
    # CRL 20 mm = 8w5d (Robinson); scan taken when LMP said 7w5d: 7 days apart, < 9 weeks -> redate.
    scan = date(2025, 7, 25)
    out = rules.gestational_age(date(2026, 1, 1), lmp=date(2025, 6, 1), crl_mm=20.0, scan=scan)
    assert rules.crl_days(20.0) == 60 and out["discrepancy_days"] == 6 and out["best_estimate"]["basis"] == "ultrasound (CRL)"
    with pytest.raises(ValueError, match="crown_rump_length_mm"):
        rules.crl_days(120)


def test_hypertension_rules():
    bp = lambda h, s, d: {"hours_ago": h, "systolic": s, "diastolic": d}  # noqa: E731
    labs = {"platelets": 200, "creatinine": 0.6, "AST": 20, "ALT": 20, "urine protein/creatinine ratio": 0.1}
    none = rules.hypertensive_disorder(34, [bp(5, 150, 95), bp(0, 120, 80)], labs, {}, False)
    assert none["category"] == "no hypertensive disorder"
    assert rules.hypertensive_disorder(34, [bp(5, 150, 95), bp(0, 148, 92)], labs, {}, False)["category"] == "gestational hypertension"
    pe = rules.hypertensive_disorder(34, [bp(5, 150, 95), bp(0, 148, 92)], {**labs, "urine protein/creatinine ratio": 0.4}, {}, False)
    assert pe["category"] == "preeclampsia without severe features"
    sev = rules.hypertensive_disorder(34, [bp(5, 150, 95), bp(0, 148, 92)], {**labs, "platelets": 90}, {}, False)
    assert sev["category"] == "preeclampsia with severe features" and sev["severe_features"][0].startswith("thrombocytopenia")
    hellp = rules.hypertensive_disorder(34, [bp(5, 150, 95), bp(0, 148, 92)], {**labs, "platelets": 70, "AST": 150, "LDH": 700}, {}, False)
    assert hellp["category"] == "HELLP syndrome"
    assert rules.hypertensive_disorder(34, [bp(1, 168, 110), bp(0, 170, 112)], labs, {"seizure": True}, False)["category"] == "eclampsia"
    sup = rules.hypertensive_disorder(30, [bp(5, 150, 95), bp(0, 150, 96)], {**labs, "urine protein/creatinine ratio": 0.5}, {}, True)
    assert sup["category"] == "chronic hypertension with superimposed preeclampsia"


# -- tools ----------------------------------------------------------------------------------------
def test_scores_fill_from_the_record(tk):
    assert use(tk, "calculate_bishop_score", patient_id="OB-006")["score"] == 4
    assert use(tk, "calculate_bishop_score", patient_id="OB-019")["score"] == 11
    assert use(tk, "calculate_bishop_score", patient_id="OB-019", dilation_cm=0)["score"] == 9
    assert use(tk, "calculate_apgar", patient_id="OB-011", minute=1)["score"] == 3
    assert use(tk, "calculate_apgar", patient_id="OB-011")["score"] == 9
    assert use(tk, "calculate_biophysical_profile", patient_id="OB-007")["score"] == 6
    assert use(tk, "calculate_biophysical_profile", patient_id="OB-015")["score"] == 10
    with pytest.raises(ToolError, match="no observation at minute 10"):
        use(tk, "calculate_apgar", patient_id="OB-011", minute=10)
    with pytest.raises(ToolError, match="no cervical exam"):
        use(tk, "calculate_bishop_score", patient_id="OB-011")


def test_ctg_and_fetal_status_tools(tk, tasks):
    out = use(tk, "interpret_ctg", patient_id="OB-008")
    assert out["category"] == "Category III" and out["variability"] == "absent"
    assert use(tk, "interpret_ctg", patient_id="OB-009")["tachysystole"] is True
    raw = use(tk, "get_ctg_tracing", patient_id="OB-008")
    assert raw["sample_interval_s"] == 2 and len(raw["fhr"]) == 600
    assert use(tk, "assess_fetal_status", patient_id="OB-015")["status"] == "reassuring"
    status = use(tk, "assess_fetal_status", patient_id="OB-007")
    assert status["status"] == "indeterminate" and "oligohydramnios" in status["reasons"]
    for t in tasks:
        if t.description.task_type == "ctg_category" or (t.description.source == "authored" and t.correct_answer.startswith("Category")):
            assert use(tk, "interpret_ctg", patient_id=t.patient_id)["category"] == t.correct_answer, t.id


def test_dating_and_preeclampsia_tools(tk):
    ga = use(tk, "calculate_gestational_age", patient_id="OB-010")
    assert ga["best_estimate"]["basis"] == "ultrasound (CRL)" and ga["best_estimate"]["edd"] == "2026-05-11"
    plain = use(tk, "calculate_gestational_age", lmp_date="2025-06-01", on_date="2026-01-01")
    assert plain["best_estimate"]["ga"] == "30 weeks 4 days"
    with pytest.raises(ToolError, match="lmp_date"):
        use(tk, "calculate_gestational_age", lmp_date="01/06/2025")
    before = use(tk, "screen_preeclampsia", patient_id="OB-005")
    assert before["proteinuria"] is False and "urine protein/creatinine ratio" in before["labs_missing"]
    use(tk, "order_lab", patient_id="OB-014", test="Urine protein/creatinine ratio")
    assert use(tk, "screen_preeclampsia", patient_id="OB-014")["category"] == "chronic hypertension with superimposed preeclampsia"
    assert use(tk, "screen_preeclampsia", patient_id="OB-003")["category"] == "HELLP syndrome"


def test_orders_checks_and_escalation(env, tk):
    h0 = env.db_hash()
    check = use(tk, "check_drug_interactions", patient_id="OB-016", drug="labetalol")
    assert check["safe_to_order"] is False and check["problems"] == ["contraindicated in asthma"]
    order = use(tk, "order_medication", patient_id="OB-016", drug="labetalol", dose_mg=100, route="IV", indication="BP")
    assert any("asthma" in w for w in order["warnings"]) and any("exceeds the maximum single dose 80" in w for w in order["warnings"])
    use(tk, "order_medication", patient_id="OB-012", drug="magnesium sulfate", dose_mg=4000, route="IV", indication="x")
    inter = use(tk, "check_drug_interactions", patient_id="OB-012", drug="calcium gluconate")
    assert inter["interactions"][0]["with"] == "magnesium sulfate" and inter["safe_to_order"] is True
    assert use(tk, "check_drug_interactions", patient_id="OB-009", drug="terbutaline")["interactions"][0]["with"] == "oxytocin"
    assert use(tk, "escalate_care", patient_id="OB-001", level="emergency cesarean delivery", reason="cord prolapse")["escalated"]
    assert use(tk, "write_obstetric_note", patient_id="OB-001", assessment="cord prolapse", plan="category 1 CS")["notes"] == 1
    assert use(tk, "order_lab", patient_id="OB-012", test="magnesium level")["status"] == "resulted"
    assert any(r["name"] == "magnesium level" and r["flag"] == "high" for r in use(tk, "get_lab_results", patient_id="OB-012")["results"])
    db = tk.db
    assert (len(db.medication_orders), len(db.escalations), len(db.notes), len(db.lab_orders)) == (2, 1, 1, 1)
    h1 = env.db_hash()
    assert h1 != h0
    for bad in ({"patient_id": "OB-001", "drug": "aspirin", "dose_mg": 75, "route": "PO", "indication": "x"},
                {"patient_id": "OB-001", "drug": "betamethasone", "dose_mg": 12, "route": "PO", "indication": "x"}):
        outcome = tk.call("order_medication", bad)
        assert outcome.error and env.db_hash() == h1
    assert registry.get_environment("obstetrics").db_hash() == h0


def test_chart_tools(tk):
    s = use(tk, "get_patient_summary", patient_id="ob-016")
    assert s["conditions"] == ["asthma"] and s["gestational_age"] == "37 weeks 0 days"
    assert use(tk, "get_vital_signs", patient_id="OB-002")["blood_pressures"][-1]["systolic"] == 172
    assert use(tk, "get_cervical_exam", patient_id="OB-001")["membranes"] == "ruptured"
    assert use(tk, "get_ultrasound_report", patient_id="OB-010")["reports"][0]["scan"] == "dating"
    with pytest.raises(ToolError, match="not found"):
        use(tk, "get_patient_summary", patient_id="OB-999")


# -- tasks ------------------------------------------------------------------------------------------
def test_tasks_counts_splits_emergencies(tasks):
    generated = [t for t in tasks if t.description.source == "generated"]
    authored = [t for t in tasks if t.description.source == "authored"]
    assert len(generated) >= 140 and len(authored) >= 20
    splits = registry.get_splits("obstetrics")
    assert len(splits["validation"]) == 6
    train, test, val = (set(splits[k]) for k in ("train", "test", "validation"))
    assert not (train & test or train & val or test & val) and train | test | val == {t.id for t in tasks}
    emergencies = collections.Counter(t.emergency for t in tasks if t.emergency)
    assert emergencies["cord_prolapse"] >= 8 and emergencies["eclampsia"] >= 5
    for t in tasks:
        assert t.has_gold_answer and t.patient_id in t.ticket
        if t.emergency:
            names = [a.name for a in t.evaluation_criteria.actions]
            assert {"escalate_care", "order_medication"} & set(names), t.id
    for t in authored:
        assert len(t.evaluation_criteria.actions) >= 2 and len(t.evaluation_criteria.nl_assertions) >= 2


def test_no_held_out_leaks(tasks):
    assert check_domain_contamination("obstetrics") == []


def test_gold_replay_with_full_safety(tasks):
    from envs.validate import validate_task

    definitions = registry.get_environment("obstetrics").toolkit.definitions
    sample = [t for t in tasks if t.description.source == "authored"]
    sample += list({t.description.task_type: t for t in tasks if t.description.source == "generated"}.values())
    for t in sample:
        report = validate_task(t, "obstetrics", definitions)
        assert report.ok, (t.id, report.problems)
        assert report.reward_components.get("safety") == 1.0, (t.id, report.reward_components)


def test_reset_and_tool_latency(tasks):
    registry.get_environment("obstetrics")
    start = time.perf_counter()
    for _ in range(50):
        registry.get_environment("obstetrics").db_hash()
    assert (time.perf_counter() - start) / 50 < 0.01
    times = collections.defaultdict(list)
    for t in tasks[::2]:
        env = registry.get_environment("obstetrics")
        for a in t.evaluation_criteria.actions:
            start = time.perf_counter()
            out = env.toolkit.call(a.name, a.arguments)
            times[a.name].append(time.perf_counter() - start)
            assert out.ok, (t.id, a.name, out.error)
    for name, values in times.items():
        assert statistics.median(values) < 0.005, (name, statistics.median(values))
