"""The EHR database, shaped like an ICU/inpatient record (MIMIC-style): patients with admissions,
ICU stays, timestamped lab and vital-sign events, medication orders (including vasopressor
infusions), ventilation periods, other orders, coded diagnoses and notes."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from envs.core.db import DB
from envs.core.models import StrictRecord


class LabEvent(StrictRecord):
    time: str
    test: str
    value: float
    unit: str
    source_id: str | None = None       # provenance of an imported row, e.g. "LABEVENTS.csv:ROW_ID=281"


class VitalEvent(StrictRecord):
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


class MedicationOrder(StrictRecord):
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


class Order(StrictRecord):
    order_id: str
    kind: Literal["lab", "imaging", "consult", "nursing", "diet", "procedure"]
    description: str
    time: str
    status: Literal["active", "discontinued", "completed"] = "active"
    priority: Literal["routine", "urgent", "stat"] = "routine"


class ICUStay(StrictRecord):
    stay_id: str
    unit: str
    intime: str
    outtime: str | None = None


class CodedDiagnosis(StrictRecord):
    """A coded discharge diagnosis of an admission (e.g. MIMIC-III DIAGNOSES_ICD, eICU diagnosis)."""

    seq: int                           # 1 = primary / principal
    code: str                          # as the source writes it (MIMIC-III: ICD-9 without the dot, "0389")
    system: Literal["ICD-9-CM", "ICD-10-CM"]
    title: str = ""
    primary: bool = False
    source_id: str | None = None


class Ventilation(StrictRecord):
    start: str
    end: str | None = None
    mode: str = "invasive"


class Note(StrictRecord):
    note_id: str
    time: str
    note_type: str
    text: str
    author: str = "agent"


class Escalation(StrictRecord):
    """A call for senior or specialist help now (recorded with the record clock)."""

    time: str
    team: str
    reason: str


class Admission(StrictRecord):
    hadm_id: str
    admit_time: str
    discharge_time: str | None = None
    admission_type: Literal["emergency", "elective", "urgent", "newborn", "unknown"] = "emergency"
    admission_diagnosis: str
    icd10_codes: list[str] = Field(default_factory=list)
    coded_diagnoses: list[CodedDiagnosis] = Field(default_factory=list)
    icu_stays: list[ICUStay] = Field(default_factory=list)
    lab_events: list[LabEvent] = Field(default_factory=list)
    vital_events: list[VitalEvent] = Field(default_factory=list)
    medication_orders: list[MedicationOrder] = Field(default_factory=list)
    orders: list[Order] = Field(default_factory=list)
    ventilation: list[Ventilation] = Field(default_factory=list)
    notes: list[Note] = Field(default_factory=list)
    escalations: list[Escalation] = Field(default_factory=list)
    comorbidities: dict[str, bool] = Field(default_factory=dict)


class Condition(StrictRecord):
    """A coded condition of the longitudinal record (authored, or a Synthea/OMOP condition occurrence)."""

    start: str
    end: str | None = None
    name: str
    code: str | None = None
    vocabulary: str | None = None      # "SNOMED" or "ICD10CM" (the code's system)
    concept_id: int | None = None      # OMOP concept id
    visit_id: str | None = None
    source_id: str | None = None       # provenance of the record: "<OMOP table>/<row id>"


class DrugExposure(StrictRecord):
    """A drug exposure (dispensing, administration or vaccination) of the longitudinal record."""

    start: str
    end: str | None = None
    name: str                          # the RxNorm (or CVX vaccine) concept name
    code: str | None = None
    vocabulary: str | None = None      # "RxNorm", "CVX", "NDC"
    concept_id: int | None = None
    ingredients: list[str] = Field(default_factory=list)  # RxNorm ingredients (empty for vaccines)
    days_supply: int | None = None
    quantity: float | None = None
    visit_id: str | None = None
    source_id: str | None = None


class ProcedureRecord(StrictRecord):
    date: str
    name: str
    code: str | None = None
    vocabulary: str | None = None
    concept_id: int | None = None
    visit_id: str | None = None
    source_id: str | None = None


class Visit(StrictRecord):
    visit_id: str
    start: str
    end: str | None = None
    visit_type: str = "inpatient"
    source_id: str | None = None


class MeasurementRecord(StrictRecord):
    """That a measurement was taken, and when. The Synthea/Eunomia source records no result values,
    so there is no value field: nothing is invented."""

    date: str
    name: str
    code: str | None = None
    vocabulary: str | None = None      # "LOINC" or "SNOMED"
    concept_id: int | None = None
    source_id: str | None = None


class ObservationRecord(StrictRecord):
    """An observation of the record: allergies, history items (e.g. "History of appendectomy")."""

    date: str
    name: str
    code: str | None = None
    vocabulary: str | None = None
    concept_id: int | None = None
    source_id: str | None = None


class EHRPatient(StrictRecord):
    patient_id: str
    name: str
    age: int = Field(ge=0, le=120)
    sex: Literal["male", "female"]
    weight_kg: float | None = None
    birth_date: str | None = None
    race: str | None = None
    ethnicity: str | None = None
    record_start: str | None = None    # the longitudinal record's span (OMOP observation period)
    record_end: str | None = None
    allergies: list[str] = Field(default_factory=list)
    conditions: list[Condition] = Field(default_factory=list)
    drug_exposures: list[DrugExposure] = Field(default_factory=list)
    procedures: list[ProcedureRecord] = Field(default_factory=list)
    visits: list[Visit] = Field(default_factory=list)
    measurements: list[MeasurementRecord] = Field(default_factory=list)
    observations: list[ObservationRecord] = Field(default_factory=list)
    admissions: list[Admission] = Field(default_factory=list)
    source: str = "authored"
    provenance: dict[str, str] = Field(default_factory=dict)


class EHRDB(DB):
    patients: dict[str, EHRPatient]
    clock: str = "2025-03-05T08:00"
    next_order_number: int = 1

