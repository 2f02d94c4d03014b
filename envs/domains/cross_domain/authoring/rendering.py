"""A validated case rendered as the pathway `pathways.json` holds: one person written as each
domain's own record (so the patient is the same person everywhere: id, name, age, sex, weight,
allergies, home medications) and the phases in the engine's shape.

Only what is derived lives here: the fields the records share, the chart's vitals (the triage row
without GCS and AVPU), a medication's dose text, the mean arterial pressure, order and note ids, and
the time-pressure flag of a phase with a call budget. Everything clinical is in the case files.
"""

from __future__ import annotations

from typing import Any

from .schema import (
    Admission,
    Case,
    ClinicalRecord,
    EHRRecord,
    EHRVitals,
    Medication,
    Person,
    PharmacyRecord,
    Phase,
    TriageRecord,
    Vitals,
)

# The diagnostic chart's vital-sign fields (`clinical_diagnosis` records no GCS or AVPU).
CHART_VITAL_FIELDS = ("time", "heart_rate", "systolic_bp", "diastolic_bp", "respiratory_rate", "temperature_c",
                      "spo2", "on_supplemental_oxygen", "pain_score")


def dose_text(medication: Medication) -> str:
    return f"{medication.dose:g} {medication.unit}"


def mean_arterial_pressure(systolic: float, diastolic: float) -> float:
    """MAP = (SBP + 2 x DBP) / 3, to one decimal."""
    return round((systolic + 2 * diastolic) / 3, 1)


def triage_vitals(rows: list[Vitals]) -> list[dict[str, Any]]:
    return [row.model_dump(exclude_none=True) for row in rows]


def chart_vitals(rows: list[Vitals]) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.model_dump(exclude_none=True).items() if k in CHART_VITAL_FIELDS} for row in rows]


def ehr_vitals(row: EHRVitals) -> dict[str, Any]:
    out: dict[str, Any] = {"time": row.time, "heart_rate": row.heart_rate, "systolic_bp": row.systolic_bp,
                           "diastolic_bp": row.diastolic_bp,
                           "map_mmhg": mean_arterial_pressure(row.systolic_bp, row.diastolic_bp),
                           "respiratory_rate": row.respiratory_rate, "temperature_c": row.temperature_c,
                           "spo2": row.spo2, "gcs": row.gcs}
    if row.fio2 is not None:
        out["fio2"] = row.fio2
    if row.urine_output_ml is not None:
        out["urine_output_ml"] = row.urine_output_ml
    return out


def inpatient_medications(case: Case) -> list[Medication]:
    """The admission's own orders, listed after the home medications in the chart and the pharmacy
    profile (none outside an admission)."""
    ehr = case.records.ehr_management
    return list(ehr.admission.medication_orders) if ehr else []


def triage_record(person: Person, record: TriageRecord, vitals: list[Vitals]) -> dict[str, Any]:
    """`triage_emergency.EDPatient`."""
    out: dict[str, Any] = {
        "patient_id": person.patient_id, "age": person.age, "sex": person.sex, "weight_kg": person.weight_kg,
        "arrival_mode": record.arrival_mode, "chief_complaint": record.chief_complaint, "history": record.history,
        "medical_history": list(person.conditions), "medications": [m.drug for m in person.medications],
        "allergies": [a.substance for a in person.allergies], "vitals": triage_vitals(vitals),
        "held_results": {test: r.model_dump() for test, r in record.held_results.items()},
        "encounter_time": record.encounter_time,
    }
    if person.age_months is not None:
        out["age_months"] = person.age_months
    if record.last_known_well is not None:
        out["last_known_well"] = record.last_known_well
    return out


def clinical_record(person: Person, record: ClinicalRecord, vitals: list[Vitals],
                    inpatient: list[Medication]) -> dict[str, Any]:
    """`clinical_diagnosis.Patient`."""
    return {
        "patient_id": person.patient_id, "name": person.name, "age": person.age, "sex": person.sex,
        "weight_kg": person.weight_kg, "setting": record.setting, "chief_complaint": record.chief_complaint,
        "history_of_present_illness": record.history_of_present_illness,
        "past_medical_history": list(person.conditions),
        "medications": [{"name": m.drug, "dose": dose_text(m), "frequency": m.frequency}
                        for m in (*person.medications, *inpatient)],
        "allergies": [{"substance": a.substance, "reaction": a.reaction, "severity": a.severity}
                      for a in person.allergies],
        "social_history": record.social_history, "family_history": record.family_history,
        "review_of_systems": dict(record.review_of_systems), "vitals": chart_vitals(vitals),
        "physical_exam": dict(record.physical_exam),
        "findings": [f.model_dump() for f in record.findings],
        "lab_results": [r.model_dump() for r in record.lab_results],
        "hidden_results": {test: r.model_dump() for test, r in record.hidden_results.items()},
        "encounter_time": record.encounter_time,
    }


def _medication(m: Medication) -> dict[str, Any]:
    return {"drug": m.drug, "dose": m.dose, "unit": m.unit, "route": m.route, "frequency": m.frequency,
            "indication": m.indication}


def pharmacy_record(person: Person, record: PharmacyRecord, inpatient: list[Medication]) -> dict[str, Any]:
    """`drug_interaction.Patient`, written the way that domain's patients.json is."""
    return {
        "patient_id": person.patient_id, "name": person.name, "age": person.age, "sex": person.sex,
        "weight_kg": person.weight_kg, "height_cm": person.height_cm,
        "serum_creatinine_mg_dl": person.creatinine_mg_dl, "pregnant": record.pregnant,
        "conditions": list(person.conditions),
        "allergies": [{"allergen": a.pharmacy or a.substance, "kind": a.kind, "reaction": a.reaction,
                       "severity": a.severity} for a in person.allergies],
        "medications": [_medication(m) for m in (*person.medications, *inpatient)],
        "notes": record.notes,
    }


def _order(order_id: str, m: Medication, start: str) -> dict[str, Any]:
    return {"order_id": order_id, "drug": m.drug, "dose": m.dose, "dose_unit": m.unit, "route": m.route.lower(),
            "frequency": m.frequency, "start": start, "indication": m.indication}


def ehr_record(person: Person, record: EHRRecord) -> dict[str, Any]:
    """`ehr_management.EHRPatient`: home medications continued as inpatient orders from admission."""
    admission: Admission = record.admission
    orders = [_order(f"{admission.hadm_id}-HOME{i + 1}", m, admission.admit_time)
              for i, m in enumerate(person.medications)]
    orders += [_order(f"{admission.hadm_id}-MED{i + 1}", m, m.start)
               for i, m in enumerate(admission.medication_orders)]
    return {
        "patient_id": person.patient_id, "name": person.name, "age": person.age, "sex": person.sex,
        "weight_kg": person.weight_kg, "allergies": [a.substance for a in person.allergies],
        "conditions": [{"start": record.conditions_since, "name": c} for c in person.conditions],
        "admissions": [{
            "hadm_id": admission.hadm_id, "admit_time": admission.admit_time,
            "admission_type": admission.admission_type, "admission_diagnosis": admission.diagnosis,
            "icd10_codes": list(admission.icd10_codes),
            "lab_events": [e.model_dump() for e in admission.lab_events],
            "vital_events": [ehr_vitals(v) for v in admission.vital_events],
            "medication_orders": orders,
            "notes": [{"note_id": f"{admission.hadm_id}-N{i + 1}", "time": n.time, "note_type": n.note_type,
                       "text": n.text, "author": "surgical team"} for i, n in enumerate(admission.notes)],
        }],
        "source": "authored",
        "provenance": {"file": "envs/domains/cross_domain/pathways.json"},
        "encounter_time": record.encounter_time,
    }


def phase(p: Phase) -> dict[str, Any]:
    return {
        "name": p.name, "domain": p.domain, "goal": p.goal,
        "required_actions": [a.model_dump() for a in p.required_actions],
        "nl_assertions": list(p.nl_assertions), "gold_reasoning": p.gold_reasoning, "transition": p.transition,
        "time_pressure": p.max_calls is not None, "max_calls": p.max_calls,
    }


def pathway(case: Case, title: str) -> dict[str, Any]:
    """The case as one entry of pathways.json (`pathway.Pathway`)."""
    person, records, inpatient = case.patient, case.records, inpatient_medications(case)
    patients: dict[str, dict[str, Any]] = {}
    if records.ehr_management:
        patients["ehr_management"] = ehr_record(person, records.ehr_management)
    if records.triage_emergency:
        patients["triage_emergency"] = triage_record(person, records.triage_emergency, case.vitals)
    if records.clinical_diagnosis:
        patients["clinical_diagnosis"] = clinical_record(person, records.clinical_diagnosis, case.vitals, inpatient)
    if records.drug_interaction:
        patients["drug_interaction"] = pharmacy_record(person, records.drug_interaction, inpatient)
    return {
        "id": case.id, "title": title, "guideline": case.guideline, "presentation": case.presentation, "patient_id": person.patient_id,
        "patients": patients, "phases": [phase(p) for p in case.phases],
        "final_question": case.final_question, "final_answer": case.final_answer,
        "answer_aliases": list(case.answer_aliases), "emergency": case.emergency,
    }
