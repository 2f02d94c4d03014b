"""Building blocks of the authored pathways: one person, rendered as each domain's patient record.

A pathway's patient is the same person in every domain it touches: `Person` holds what every
record shares (id, name, age, sex, weight, conditions, allergies, home medications, creatinine)
and the `*_record` functions render it in each domain's own shape, adding that domain's clinical
content (triage vitals and held-back point-of-care results, the diagnostic chart with coded
findings and orderable results, the pharmacy profile, the inpatient record with timestamped
events). Everything here is authored (synthetic; provenance "authored").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Allergy:
    """A drug allergy. `pharmacy` is how the drug-interaction profile names it: a substance
    (`kind="substance"`) or an ANSM class (`kind="class"`, e.g. "penicillins")."""

    substance: str
    reaction: str
    severity: str = "moderate"
    pharmacy: str | None = None
    kind: str = "substance"


@dataclass(frozen=True)
class Med:
    """A home medication: generic name, dose, unit, route (PO, IV, SC, INH), frequency, indication."""

    drug: str
    dose: float
    unit: str
    route: str
    frequency: str
    indication: str


@dataclass(frozen=True)
class Person:
    patient_id: str
    name: str
    age: int
    sex: str
    weight_kg: float
    height_cm: float | None = None
    age_months: int | None = None
    conditions: tuple[str, ...] = ()
    allergies: tuple[Allergy, ...] = ()
    meds: tuple[Med, ...] = ()
    creatinine_mg_dl: float = 0.9

    @property
    def allergy_names(self) -> list[str]:
        return [a.substance for a in self.allergies]


def _dose(value: float, unit: str) -> str:
    return f"{value:g} {unit}"


def vitals(
    time: str,
    hr: float,
    sbp: float,
    dbp: float,
    rr: float,
    temp: float,
    spo2: float,
    *,
    o2: bool = False,
    gcs: tuple[int, int, int] | None = (4, 5, 6),
    avpu: str | None = "alert",
    pain: int | None = None,
) -> dict[str, Any]:
    """One set of vital signs in the triage shape (the diagnostic chart takes the same keys minus GCS/AVPU)."""
    row: dict[str, Any] = {
        "time": time,
        "heart_rate": hr,
        "systolic_bp": sbp,
        "diastolic_bp": dbp,
        "respiratory_rate": rr,
        "temperature_c": temp,
        "spo2": spo2,
        "on_supplemental_oxygen": o2,
    }
    if gcs is not None:
        row.update(gcs_eye=gcs[0], gcs_verbal=gcs[1], gcs_motor=gcs[2])
    if avpu is not None:
        row["avpu"] = avpu
    if pain is not None:
        row["pain_score"] = pain
    return row


def _chart_vitals(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    keep = (
        "time",
        "heart_rate",
        "systolic_bp",
        "diastolic_bp",
        "respiratory_rate",
        "temperature_c",
        "spo2",
        "on_supplemental_oxygen",
        "pain_score",
    )
    return [{k: v for k, v in row.items() if k in keep} for row in rows]


def triage_record(
    p: Person,
    *,
    chief_complaint: str,
    history: str,
    vitals_rows: list[dict[str, Any]],
    held: dict[str, tuple[float | str, str]],
    arrival_mode: str = "walk-in",
    last_known_well: str | None = None,
    encounter_time: str = "2025-03-01T14:00",
) -> dict[str, Any]:
    """The ED front-door record (`triage_emergency.EDPatient`); `held` are the ECG and point-of-care
    results released when ordered: {test: (value, unit)}."""
    record: dict[str, Any] = {
        "patient_id": p.patient_id,
        "age": p.age,
        "sex": p.sex,
        "weight_kg": p.weight_kg,
        "arrival_mode": arrival_mode,
        "chief_complaint": chief_complaint,
        "history": history,
        "medical_history": list(p.conditions),
        "medications": [m.drug for m in p.meds],
        "allergies": p.allergy_names,
        "vitals": vitals_rows,
        "held_results": {test: {"value": value, "unit": unit} for test, (value, unit) in held.items()},
        "encounter_time": encounter_time,
    }
    if p.age_months is not None:
        record["age_months"] = p.age_months
    if last_known_well is not None:
        record["last_known_well"] = last_known_well
    return record


def finding(
    hpo_id: str, label: str, source: str = "history", requires_test: str | None = None
) -> dict[str, Any]:
    return {"hpo_id": hpo_id, "label": label, "source": source, "requires_test": requires_test}


def clinical_record(
    p: Person,
    *,
    chief_complaint: str,
    hpi: str,
    exam: dict[str, str],
    findings: list[dict[str, Any]],
    hidden: dict[str, tuple[float | str, str, int]],
    vitals_rows: list[dict[str, Any]],
    labs: list[tuple[str, float | str, str, str]] = (),
    ros: dict[str, str] | None = None,
    social: str = "",
    family: str = "",
    setting: str = "emergency",
    inpatient: tuple[Med, ...] = (),
    encounter_time: str = "2025-03-01T14:30",
) -> dict[str, Any]:
    """The diagnostic chart (`clinical_diagnosis.Patient`); `hidden` are results released by order_lab:
    {test: (value, unit, turnaround_min)}; `labs` are results already on the chart: (test, value, unit, time);
    `inpatient` are medications started in hospital, listed after the home medications."""
    return {
        "patient_id": p.patient_id,
        "name": p.name,
        "age": p.age,
        "sex": p.sex,
        "weight_kg": p.weight_kg,
        "setting": setting,
        "chief_complaint": chief_complaint,
        "history_of_present_illness": hpi,
        "past_medical_history": list(p.conditions),
        "medications": [
            {"name": m.drug, "dose": _dose(m.dose, m.unit), "frequency": m.frequency}
            for m in (*p.meds, *inpatient)
        ],
        "allergies": [
            {"substance": a.substance, "reaction": a.reaction, "severity": a.severity} for a in p.allergies
        ],
        "social_history": social,
        "family_history": family,
        "review_of_systems": ros or {},
        "vitals": _chart_vitals(vitals_rows),
        "physical_exam": exam,
        "findings": findings,
        "lab_results": [{"test": t, "value": v, "unit": u, "time": tm} for t, v, u, tm in labs],
        "hidden_results": {
            t: {"value": v, "unit": u, "turnaround_min": n} for t, (v, u, n) in hidden.items()
        },
        "encounter_time": encounter_time,
    }


def pharmacy_record(
    p: Person, *, notes: str = "", pregnant: bool = False, inpatient: tuple[Med, ...] = ()
) -> dict[str, Any]:
    """The medication profile (`drug_interaction.Patient`, written the way its patients.json is): home
    medications, then those started in hospital."""
    return {
        "patient_id": p.patient_id,
        "name": p.name,
        "age": p.age,
        "sex": p.sex,
        "weight_kg": p.weight_kg,
        "height_cm": p.height_cm,
        "serum_creatinine_mg_dl": p.creatinine_mg_dl,
        "pregnant": pregnant,
        "conditions": list(p.conditions),
        "allergies": [
            {
                "allergen": a.pharmacy or a.substance,
                "kind": a.kind,
                "reaction": a.reaction,
                "severity": a.severity,
            }
            for a in p.allergies
        ],
        "medications": [
            {
                "drug": m.drug,
                "dose": m.dose,
                "unit": m.unit,
                "route": m.route,
                "frequency": m.frequency,
                "indication": m.indication,
            }
            for m in (*p.meds, *inpatient)
        ],
        "notes": notes,
    }


@dataclass
class Admission:
    """An inpatient admission for the EHR record: events are (time, ...) tuples."""

    hadm_id: str
    admit_time: str
    diagnosis: str
    admission_type: str = "elective"
    labs: list[tuple[str, str, float, str]] = field(default_factory=list)  # (time, test, value, unit)
    vitals: list[dict[str, Any]] = field(default_factory=list)  # VitalEvent dicts
    orders: list[tuple[Med, str]] = field(default_factory=list)  # inpatient medication orders: (med, start)
    notes: list[tuple[str, str, str]] = field(default_factory=list)  # (time, note_type, text)
    icd10_codes: list[str] = field(default_factory=list)

    @property
    def inpatient_meds(self) -> tuple[Med, ...]:
        return tuple(m for m, _ in self.orders)


def ehr_vitals(
    time: str,
    hr: float,
    sbp: float,
    dbp: float,
    rr: float,
    temp: float,
    spo2: float,
    gcs: int = 15,
    *,
    fio2: float | None = None,
    urine_ml: float | None = None,
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "time": time,
        "heart_rate": hr,
        "systolic_bp": sbp,
        "diastolic_bp": dbp,
        "map_mmhg": round((sbp + 2 * dbp) / 3, 1),
        "respiratory_rate": rr,
        "temperature_c": temp,
        "spo2": spo2,
        "gcs": gcs,
    }
    if fio2 is not None:
        row["fio2"] = fio2
    if urine_ml is not None:
        row["urine_output_ml"] = urine_ml
    return row


def ehr_record(
    p: Person,
    admission: Admission,
    *,
    conditions_since: str = "2015-01-01",
    encounter_time: str = "2025-03-05T08:00",
) -> dict[str, Any]:
    """The inpatient record (`ehr_management.EHRPatient`): the person's home medications are
    continued as inpatient orders alongside the admission's own orders."""
    orders = [
        {
            "order_id": f"{admission.hadm_id}-HOME{i + 1}",
            "drug": m.drug,
            "dose": m.dose,
            "dose_unit": m.unit,
            "route": m.route.lower(),
            "frequency": m.frequency,
            "start": admission.admit_time,
            "indication": m.indication,
        }
        for i, m in enumerate(p.meds)
    ]
    orders += [
        {
            "order_id": f"{admission.hadm_id}-MED{i + 1}",
            "drug": m.drug,
            "dose": m.dose,
            "dose_unit": m.unit,
            "route": m.route.lower(),
            "frequency": m.frequency,
            "start": start,
            "indication": m.indication,
        }
        for i, (m, start) in enumerate(admission.orders)
    ]
    return {
        "patient_id": p.patient_id,
        "name": p.name,
        "age": p.age,
        "sex": p.sex,
        "weight_kg": p.weight_kg,
        "allergies": p.allergy_names,
        "conditions": [{"start": conditions_since, "name": c} for c in p.conditions],
        "admissions": [
            {
                "hadm_id": admission.hadm_id,
                "admit_time": admission.admit_time,
                "admission_type": admission.admission_type,
                "admission_diagnosis": admission.diagnosis,
                "icd10_codes": admission.icd10_codes,
                "lab_events": [
                    {"time": t, "test": test, "value": v, "unit": u} for t, test, v, u in admission.labs
                ],
                "vital_events": admission.vitals,
                "medication_orders": orders,
                "notes": [
                    {
                        "note_id": f"{admission.hadm_id}-N{i + 1}",
                        "time": t,
                        "note_type": kind,
                        "text": text,
                        "author": "surgical team",
                    }
                    for i, (t, kind, text) in enumerate(admission.notes)
                ],
            }
        ],
        "source": "authored",
        "provenance": {"file": "envs/domains/cross_domain/pathways.json"},
        "encounter_time": encounter_time,
    }


# -- pathway pieces ------------------------------------------------------------------------------
def act(name: str, compare: list[str] | None = None, **arguments: Any) -> dict[str, Any]:
    """A required action: the tool, its gold arguments and the arguments that must match
    (default: patient_id only)."""
    return {
        "name": name,
        "arguments": arguments,
        "compare_args": compare if compare is not None else ["patient_id"],
    }


def phase(
    name: str,
    domain: str,
    goal: str,
    actions: list[dict[str, Any]],
    assertions: list[str],
    *,
    max_calls: int | None = None,
    transition: str = "required_actions",
) -> dict[str, Any]:
    """A pathway phase; a `max_calls` budget marks it time-pressured."""
    out: dict[str, Any] = {
        "name": name,
        "domain": domain,
        "goal": goal,
        "required_actions": actions,
        "nl_assertions": assertions,
        "transition": transition,
        "time_pressure": max_calls is not None,
        "max_calls": max_calls,
    }
    return out


def pathway(
    pid: str,
    title: str,
    person: Person,
    presentation: str,
    patients: dict[str, dict[str, Any]],
    phases: list[dict[str, Any]],
    question: str,
    answer: str,
    aliases: list[str] = (),
    emergency: str | None = None,
) -> dict[str, Any]:
    return {
        "id": pid,
        "title": title,
        "presentation": presentation,
        "patient_id": person.patient_id,
        "patients": patients,
        "phases": phases,
        "final_question": question,
        "final_answer": answer,
        "answer_aliases": list(aliases),
        "emergency": emergency,
    }
