"""The EHR database, shaped like an ICU/inpatient record (MIMIC-style): patients with admissions,
ICU stays, timestamped lab and vital-sign events, medication orders (including vasopressor
infusions), ventilation periods, other orders, coded diagnoses and notes."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from envs.core.db import DB


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class LabEvent(_Strict):
    time: str
    test: str
    value: float
    unit: str


class VitalEvent(_Strict):
    time: str
    heart_rate: float | None = None
    systolic_bp: float | None = None
    diastolic_bp: float | None = None
    map_mmhg: float | None = None
    respiratory_rate: float | None = None
    temperature_c: float | None = None
    spo2: float | None = None
    fio2: float | None = None
    gcs: int | None = Field(default=None, ge=3, le=15)
    urine_output_ml: float | None = None  # since the previous charted event


class MedicationOrder(_Strict):
    order_id: str
    drug: str
    dose: float
    dose_unit: str
    route: str
    frequency: str
    start: str
    stop: str | None = None
    status: Literal["active", "discontinued", "completed"] = "active"
    indication: str = ""


class Order(_Strict):
    order_id: str
    kind: Literal["lab", "imaging", "consult", "nursing", "diet", "procedure"]
    description: str
    time: str
    status: Literal["active", "discontinued", "completed"] = "active"
    priority: Literal["routine", "urgent", "stat"] = "routine"


class ICUStay(_Strict):
    stay_id: str
    unit: str
    intime: str
    outtime: str | None = None


class Ventilation(_Strict):
    start: str
    end: str | None = None
    mode: str = "invasive"


class Note(_Strict):
    note_id: str
    time: str
    note_type: str
    text: str
    author: str = "agent"


class Escalation(_Strict):
    """A call for senior or specialist help now (recorded with the record clock)."""

    time: str
    team: str
    reason: str


class Admission(_Strict):
    hadm_id: str
    admit_time: str
    discharge_time: str | None = None
    admission_type: Literal["emergency", "elective", "urgent"] = "emergency"
    admission_diagnosis: str
    icd10_codes: list[str] = Field(default_factory=list)
    icu_stays: list[ICUStay] = Field(default_factory=list)
    lab_events: list[LabEvent] = Field(default_factory=list)
    vital_events: list[VitalEvent] = Field(default_factory=list)
    medication_orders: list[MedicationOrder] = Field(default_factory=list)
    orders: list[Order] = Field(default_factory=list)
    ventilation: list[Ventilation] = Field(default_factory=list)
    notes: list[Note] = Field(default_factory=list)
    escalations: list[Escalation] = Field(default_factory=list)
    comorbidities: dict[str, bool] = Field(default_factory=dict)


class Condition(_Strict):
    """A coded condition from the longitudinal record (e.g. Synthea/OMOP condition occurrences)."""

    start: str
    end: str | None = None
    name: str
    code: str | None = None


class EHRPatient(_Strict):
    patient_id: str
    name: str
    age: int = Field(ge=0, le=120)
    sex: Literal["male", "female"]
    weight_kg: float | None = None
    allergies: list[str] = Field(default_factory=list)
    conditions: list[Condition] = Field(default_factory=list)
    admissions: list[Admission] = Field(default_factory=list)
    source: str = "authored"


class EHRDB(DB):
    patients: dict[str, EHRPatient]
    clock: str = "2025-03-05T08:00"
    next_order_number: int = 1

