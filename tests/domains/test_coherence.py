"""Coherent patients: each rule of `envs.coherence` fires on a contradicting task shaped like what the
generators used to write, stays quiet on its coherent counterpart, and no built task breaks any rule."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from envs import registry
from envs.coherence import RULES, Subject, check_subject, check_tasks, rules_for
from envs.core.task import Task

ROOT = Path(__file__).resolve().parents[2]
ICU_CLOCK = {"clock": "2025-03-05T08:00"}
OB_TODAY = {"today": "2026-03-02"}


def _task(**kw) -> Task:
    base = {"id": "t1", "ticket": "A task.", "correct_answer": "1", "answer_type": "exact"}
    return Task.model_validate({**base, **kw})


def _icu(gcs: int, *, status: str = "completed", stop: str = "2025-03-01T15:00") -> dict:
    return {"name": "Abel Singh", "sex": "male", "age": 54, "admissions": [{
        "ventilation": [{"start": "2025-02-26T15:00", "end": "2025-03-01T03:00", "mode": "invasive"}],
        "vital_events": [{"time": "2025-02-26T15:00", "gcs": gcs}, {"time": "2025-03-01T11:00", "gcs": 15}],
        "medication_orders": [{"order_id": "VP-6", "drug": "norepinephrine", "start": "2025-03-01T03:00", "stop": stop,
                               "status": status}]}]}


def _dka(stop: str | None, subcutaneous: bool = True) -> dict:
    """EHR-008 as it was (the infusion running four days after pH 7.34, bicarbonate 20) or as it is now."""
    labs = [{"time": t, "test": k, "value": v} for t, ph, hco3 in (("2025-02-28T21:00", 7.24, 18.0),
                                                                  ("2025-03-01T09:00", 7.34, 20.0))
            for k, v in (("ph_arterial", ph), ("bicarbonate", hco3))]
    orders = [{"order_id": "MED-1", "drug": "insulin regular infusion", "route": "iv", "start": "2025-02-27T07:00",
               "stop": stop, "status": "active" if stop is None else "completed"}]
    if subcutaneous:
        orders.append({"order_id": "MED-5", "drug": "insulin aspart", "route": "subcutaneous",
                       "start": "2025-03-01T12:00", "status": "active"})
    return {"name": "Hugo Eriks", "sex": "male", "admissions": [{"admission_diagnosis": "diabetic ketoacidosis",
                                                                  "lab_events": labs, "medication_orders": orders}]}


# P014 as drug_interaction's record has it: nothing on it is treated with methotrexate
P014 = {"patient_id": "P014", "sex": "female", "conditions": ["Alzheimer dementia", "overactive bladder", "insomnia",
                                                           "hypertension"],
        "medications": [{"drug_id": "amlodipine", "indication": "hypertension", "status": "active"}]}


def _renal_task(drug: str, indication: str | None) -> Task:
    challenges = ["The label metric (CrCl or eGFR) decides which value to use."]
    challenges += [f"Indication on the record: {indication}."] if indication else []
    return _task(patient_id="P014", description={"task_type": "renal_adjustment_patient", "key_challenges": challenges},
                 evaluation_criteria={"actions": [{"name": "get_renal_dose_adjustment",
                                                   "arguments": {"drug": drug, "patient_id": "P014"}}]})


def _infusion(stop: str | None, frequency: str = "continuous", last: str = "2025-03-01T18:00") -> dict:
    """EHR-016 as it was (propofol 'active' at the clock, charting ended four days before) or as it is now."""
    order = {"order_id": "MED-2", "drug": "propofol infusion", "route": "iv", "frequency": frequency,
             "start": "2025-02-26T22:00", "status": "active" if stop is None else "completed"}
    if stop is not None:
        order["stop"] = stop
    return {"name": "Abel Singh", "sex": "male", "admissions": [{
        "vital_events": [{"time": "2025-02-26T22:00", "gcs": 8}, {"time": last, "gcs": 15}],
        "lab_events": [{"time": "2025-02-27T05:00", "test": "creatinine", "value": 1.0}], "medication_orders": [order]}]}


def _breast(indication: str, exam: str, description: str, shape: str = "oval", margin: str = "circumscribed",
            stable: bool = False) -> dict:
    return {"region": "breast", "indication": indication, "exam": exam, "exam_complete": True, "prior": None,
            "known_biopsy_proven_malignancy": False,
            "findings": [{"kind": "breast_mass", "mass_shape": shape, "mass_margin": margin, "stable_2_years": stable,
                          "mass_typically_benign": False, "description": description}]}


def _news2_task(at: str) -> Task:
    return _task(evaluation_criteria={"actions": [{"name": "calculate_news2", "arguments": {"patient_id": "EHR-001",
                                                                                           "at_time": at}}]})


# rule -> (domain, the contradicting subject as the old generators wrote it, its coherent counterpart)
CASES: dict[str, tuple[str, tuple[Task, dict, dict], tuple[Task, dict, dict]]] = {
    "name_matches_sex": ("ehr_management", (_task(), {"name": "Olga Novak", "sex": "male"}, {}),
                         (_task(), {"name": "Abel Novak", "sex": "male"}, {})),
    "sex_specific_drug": ("psychiatry",
                          (_task(metadata={"current": ["carbamazepine"], "proposed": "ethinyl estradiol"}),
                           {"sex": "male", "medications": [{"name": "carbamazepine"}]}, {}),
                          (_task(metadata={"current": ["carbamazepine"], "proposed": "ethinyl estradiol"}),
                           {"sex": "female", "medications": [{"name": "carbamazepine"}]}, {})),
    "sex_specific_condition": ("clinical_diagnosis", (_task(), {"sex": "male", "past_medical_history": ["Ovarian cyst"]}, {}),
                               (_task(), {"sex": "female", "past_medical_history": ["Ovarian cyst"]}, {})),
    "occupation_matches_age": ("psychiatry",
                               (_task(), {"age": 21, "social": {"employment": "retired teacher", "recent_stressors": ["exams"]}}, {}),
                               (_task(), {"age": 66, "social": {"employment": "retired teacher",
                                                                "recent_stressors": ["bereavement"]}}, {})),
    "living_matches_age": ("psychiatry", (_task(), {"age": 71, "social": {"living": "lives with parents"}}, {}),
                           (_task(), {"age": 27, "social": {"living": "lives with parents"}}, {})),
    "visit_reason_matches_setting": (
        "psychiatry",
        (_task(), {"setting": "emergency department", "chief_complaint": "annual review; partner concerned about drinking"}, {}),
        (_task(), {"setting": "telehealth follow-up", "chief_complaint": "annual review; partner concerned about drinking"}, {})),
    "indication_matches_age": ("visual_diagnosis",
                               (_task(), {"indication": "pre-employment screening", "patient": {"age": 84}}, {}),
                               (_task(), {"indication": "pre-employment screening", "patient": {"age": 49}}, {})),
    "post_dates_gestation": ("obstetrics",
                             (_task(), {"lmp_date": "2025-06-01", "history": "Post-dates induction.",
                                        "presenting_complaint": "booked for induction of labour"}, OB_TODAY),
                             (_task(), {"lmp_date": "2025-05-18", "history": "Late-term pregnancy (41 weeks): induction of labour.",
                                        "presenting_complaint": "booked for induction of labour"}, OB_TODAY)),
    "complaint_matches_symptom_flags": ("obstetrics",
                                        (_task(), {"presenting_complaint": "reduced fetal movements", "history": "",
                                                   "symptoms": {"reduced_fetal_movements": False}}, OB_TODAY),
                                        (_task(), {"presenting_complaint": "reduced fetal movements", "history": "",
                                                   "symptoms": {"reduced_fetal_movements": True}}, OB_TODAY)),
    "breast_indication_matches_finding": (
        "radiology_report",
        (_task(), _breast("palpable lump", "MG bilateral diagnostic mammogram",
                          "solid oval circumscribed mass, no prior films"), {}),
        (_task(), _breast("baseline screening recall", "MG bilateral diagnostic mammogram",
                          "solid oval circumscribed mass, no prior films"), {})),
    "intubated_gcs_verbal": ("ehr_management", (_task(), _icu(14), ICU_CLOCK), (_task(), _icu(10), ICU_CLOCK)),
    "avpu_matches_gcs_eye": (
        "triage_emergency",
        (_task(), {"vitals": [{"time": "2025-03-01T13:59", "avpu": "alert", "gcs_eye": 3, "gcs_verbal": 5, "gcs_motor": 6}]}, {}),
        (_task(), {"vitals": [{"time": "2025-03-01T13:59", "avpu": "voice", "gcs_eye": 3, "gcs_verbal": 5, "gcs_motor": 6}]}, {})),
    "news2_not_on_ventilator": ("ehr_management", (_news2_task("2025-02-26T15:00"), _icu(10), ICU_CLOCK),
                                (_news2_task("2025-03-01T11:00"), _icu(10), ICU_CLOCK)),
    "order_status_matches_clock": ("ehr_management", (_task(), _icu(10, status="active"), ICU_CLOCK),
                                   (_task(), _icu(10, status="completed"), ICU_CLOCK)),
    "dka_insulin_infusion_stops_after_resolution": ("ehr_management", (_task(), _dka(stop=None), ICU_CLOCK),
                                                    (_task(), _dka(stop="2025-03-01T13:00"), ICU_CLOCK)),
    "renal_drug_has_indication": ("drug_interaction", (_renal_task("methotrexate", None), P014, {}),
                                  (_renal_task("spironolactone", "hypertension"), P014, {})),
    "infusion_active_only_while_charted": ("ehr_management", (_task(), _infusion(stop=None), ICU_CLOCK),
                                           (_task(), _infusion(stop="2025-03-01T10:00"), ICU_CLOCK)),
    "sex_factor_matches_sex": ("drug_interaction",
                               (_task(description={"key_challenges": ["Female sex factor 0.85."]}), {"sex": "male"}, {}),
                               (_task(description={"key_challenges": ["No sex factor for a man."]}), {"sex": "male"}, {})),
    "vignette_matches_arguments": (
        "medical_qa",
        (_task(ticket="A 62-year-old man weighing 70 kg has a creatinine of 1.2 mg/dL.",
               evaluation_criteria={"actions": [{"name": "calculate_creatinine_clearance",
                                                 "arguments": {"age": 62, "sex": "female"}}]}), {}, {}),
        (_task(ticket="A 62-year-old man weighing 70 kg has a creatinine of 1.2 mg/dL.",
               evaluation_criteria={"actions": [{"name": "calculate_creatinine_clearance",
                                                 "arguments": {"age": 62, "sex": "male"}}]}), {}, {})),
}


def test_every_rule_has_a_contradicting_case():
    assert sorted(CASES) == sorted(RULES), "add a contradicting and a coherent case for each coherence rule"


@pytest.mark.parametrize("name", sorted(CASES))
def test_rule_fires_on_the_contradiction_only(name):
    domain, bad, good = CASES[name]
    assert RULES[name] in rules_for(domain)
    found = check_subject(Subject(domain, *bad), [RULES[name]])
    assert found and all(v.rule == name and v.fields and v.task_id == "t1" for v in found)
    assert check_subject(Subject(domain, *good), [RULES[name]]) == []


def test_a_patient_brought_in_is_not_seen_by_telehealth():
    rule = [RULES["visit_reason_matches_setting"]]
    reason = {"chief_complaint": "brought in by family after a crisis"}
    assert check_subject(Subject("psychiatry", _task(), {**reason, "setting": "telehealth follow-up"}), rule)
    assert check_subject(Subject("psychiatry", _task(), {**reason, "setting": "emergency department"}), rule) == []


def test_a_dka_insulin_infusion_stops_only_after_resolution_and_subcutaneous_insulin():
    rule = [RULES["dka_insulin_infusion_stops_after_resolution"]]
    # stopped with no subcutaneous insulin started: rebound ketoacidosis (JBDS-IP)
    bare = check_subject(Subject("ehr_management", _task(), _dka("2025-03-01T13:00", subcutaneous=False), ICU_CLOCK), rule)
    assert [v.fields for v in bare] == [("medication_orders.stop", "medication_orders.route")]
    # within a day of the charted resolution the infusion may still run
    assert check_subject(Subject("ehr_management", _task(), _dka(None), {"clock": "2025-03-02T08:00"}), rule) == []


def test_an_active_infusion_needs_a_charted_day_and_a_one_off_dose_is_done_once_given():
    rule = [RULES["infusion_active_only_while_charted"]]
    # charted until 2025-03-04T09:00: under 24 h before the clock, the infusion may still run
    assert check_subject(Subject("ehr_management", _task(), _infusion(None, last="2025-03-04T09:00"), ICU_CLOCK), rule) == []
    # a one-off dose (calcium gluconate in EHR-010) 'active' days after it was given
    once = check_subject(Subject("ehr_management", _task(), _infusion(None, frequency="once", last="2025-03-04T09:00"),
                                 ICU_CLOCK), rule)
    assert len(once) == 1 and "one-off dose given at 2025-02-26T22:00" in once[0].message
    # scheduled doses are not infusions: this rule leaves them to order_status_matches_clock
    scheduled = _infusion(None, frequency="q12h")
    assert check_subject(Subject("ehr_management", _task(), scheduled, ICU_CLOCK), rule) == []


def test_a_first_name_in_neither_list_is_reported():
    found = check_subject(Subject("psychiatry", _task(), {"name": "Xqz Doe", "sex": "female"}), [RULES["name_matches_sex"]])
    assert "neither list" in found[0].message


@pytest.fixture(scope="module")
def built_violations() -> dict[str, list[str]]:
    return {d: [f"[{v.task_id}] {v}" for v in check_tasks(d, registry.get_tasks(d))] for d in registry.list_domains()}


def test_built_tasks_break_no_rule(built_violations):
    broken = {d: v[:5] for d, v in built_violations.items() if v}
    assert not broken, broken


def test_readmes_list_their_rules():
    contract = (ROOT / "envs" / "domains" / "README.md").read_text(encoding="utf-8")
    missing = [r for r in RULES if f"`{r}`" not in contract]
    for domain in registry.list_domains():
        readme = ROOT / "envs" / "domains" / domain / "README.md"
        if not readme.exists():
            continue
        text = readme.read_text(encoding="utf-8")
        missing += [f"{domain}: {r.name}" for r in rules_for(domain) if r.domains and f"`{r.name}`" not in text]
    assert not missing, f"coherence rules not listed in the domain READMEs: {missing}"


def test_validate_fails_a_contradicting_task_naming_task_rule_and_fields(monkeypatch):
    """`hcgym tasks validate` (validate_domain) reports the contradiction as a problem of the task."""
    from envs.validate import validate_domain

    task = _task(id="psy_coherence_probe", patient_id="PSY-002", metadata={"proposed": "ethinyl estradiol"},
                 evaluation_criteria={"actions": [{"name": "check_psych_med_interactions",
                                                   "arguments": {"patient_id": "PSY-002", "proposed_drug": "ethinyl estradiol"}}]})
    monkeypatch.setattr(registry, "get_tasks", lambda domain, split=None: [task])
    (report,) = validate_domain("psychiatry", replay=False)
    assert not report.ok and report.task_id == "psy_coherence_probe"
    assert any(p.startswith("coherence rule 'sex_specific_drug' (sex, medications)") for p in report.problems), report.problems


def test_pathway_patients_are_checked_by_their_own_domains_rules():
    """cross_domain has no db.json: its pathways hand each touched domain a record (coherence_records)."""
    records = registry.domain_module("cross_domain").coherence_records
    pathway_tasks = [t for t in registry.get_tasks("cross_domain") if "pathway_id" in t.metadata]
    assert pathway_tasks and all(records(t) for t in pathway_tasks)
    task = pathway_tasks[0]
    inner, record = next((d, r) for d, r in records(task).items() if r.get("name") and r.get("sex"))
    swapped = {**record, "sex": "female" if record["sex"] == "male" else "male"}
    assert [v.rule for v in check_subject(Subject(inner, task, swapped))] == ["name_matches_sex"]
    assert check_subject(Subject(inner, task, record)) == []


@pytest.mark.parametrize("fmt", ["mimic3", "eicu"])
def test_imported_icu_tasks_are_coherent(fmt):
    """Imported MIMIC-III / eICU tasks carry their patient (named by an identifier, not a given name)."""
    from envs.converters import ehr

    convert = {"mimic3": ehr.convert_mimic3, "eicu": ehr.convert_eicu}[fmt]
    tasks = convert(ROOT / "tests" / "fixtures" / "benchmarks" / fmt).tasks
    assert tasks and all("ehr_patient" in t.metadata for t in tasks)
    assert check_tasks("ehr_management", tasks, db={"clock": "2025-03-05T08:00"}) == []
