"""The obstetrics database: pregnant patients with dating, vitals, labs, cervical examinations,
ultrasound, CTG tracings (FHR series) and newborn observations, plus the orders and escalations
the agent writes.

Patients and reference tables are read-only (no tool changes them); orders, escalations and notes
are the episode state. `fork()` shares the read-only part so that a reset, a WRITE snapshot and
the content hash stay cheap.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field

from envs.core.db import ForkableDB
from envs.core.models import StrictModel


class BloodPressure(StrictModel):
    hours_ago: float = Field(description="hours before now (0 = now)")
    systolic: int
    diastolic: int


class Vitals(StrictModel):
    blood_pressures: list[BloodPressure]
    heart_rate: int
    respiratory_rate: int
    temperature_c: float
    spo2: int


class LabResult(StrictModel):
    name: str
    value: float
    unit: str
    ref_low: float | None = None
    ref_high: float | None = None
    hours_ago: float = 0


class CervicalExam(StrictModel):
    dilation_cm: float
    effacement_percent: float
    station: int
    consistency: Literal["firm", "medium", "soft"]
    position: Literal["posterior", "mid", "anterior"]
    membranes: Literal["intact", "ruptured"] = "intact"
    findings: str = ""


class Ultrasound(StrictModel):
    scan: Literal["dating", "biophysical profile", "growth"]
    weeks_ago: float = 0
    crown_rump_length_mm: float | None = None
    fetal_breathing: bool | None = None
    body_movements_count: int | None = None
    fetal_tone: bool | None = None
    deepest_vertical_pocket_cm: float | None = None
    nst_reactive: bool | None = None
    notes: str = ""


class CTGTracing(StrictModel):
    tracing_id: str
    minutes: int
    sample_interval_s: int
    fhr: list[int]
    contractions: list[list[int]] = Field(description="[start, peak, end] in seconds from the start")
    recorded: str


class NewbornObservation(StrictModel):
    minute: int
    heart_rate: int
    respiratory_effort: Literal["absent", "weak", "strong"]
    muscle_tone: Literal["limp", "some_flexion", "active"]
    reflex_irritability: Literal["none", "grimace", "cry"]
    color: Literal["blue_pale", "acrocyanosis", "pink"]


class Symptoms(StrictModel):
    headache: bool = False
    visual_disturbance: bool = False
    epigastric_or_ruq_pain: bool = False
    pulmonary_edema: bool = False
    seizure: bool = False
    vaginal_bleeding: bool = False
    reduced_fetal_movements: bool = False
    other: list[str] = Field(default_factory=list)


class Patient(StrictModel):
    patient_id: str
    name: str
    age: int
    gravida: int
    para: int
    setting: str
    presenting_complaint: str
    history: str
    lmp_date: str | None = Field(default=None, description="ISO date of the last menstrual period")
    chronic_hypertension: bool = False
    conditions: list[str] = Field(default_factory=list, description="other maternal conditions, e.g. asthma")
    prior_cesarean: int = 0
    medications: list[str] = Field(default_factory=list)
    allergies: list[str] = Field(default_factory=list)
    symptoms: Symptoms = Field(default_factory=Symptoms)
    vitals: Vitals
    labs: list[LabResult] = Field(default_factory=list)
    orderable_results: dict[str, LabResult] = Field(default_factory=dict)
    cervical_exam: CervicalExam | None = None
    ultrasounds: list[Ultrasound] = Field(default_factory=list)
    ctg: list[CTGTracing] = Field(default_factory=list)
    newborn: list[NewbornObservation] = Field(default_factory=list)
    provenance: dict[str, str] = Field(default_factory=dict)


class ObstetricDrug(StrictModel):
    name: str
    routes: list[str]
    usual_dose: str
    max_single_dose_mg: float | None = None
    indications: list[str] = Field(default_factory=list)
    contraindications: list[str] = Field(default_factory=list)
    source: dict[str, str] = Field(default_factory=dict)


class DrugInteraction(StrictModel):
    drugs: list[str] = Field(min_length=2, max_length=2)
    severity: Literal["contraindicated", "major", "moderate", "minor"]
    effect: str
    management: str


class MedicationOrder(StrictModel):
    patient_id: str
    drug: str
    dose_mg: float
    route: str
    indication: str
    warnings: list[str] = Field(default_factory=list)


class LabOrder(StrictModel):
    patient_id: str
    test: str
    status: Literal["resulted", "not available"]


class Escalation(StrictModel):
    patient_id: str
    level: str
    reason: str


class ClinicalNote(StrictModel):
    patient_id: str
    assessment: str
    plan: str


REFERENCE_FIELDS = ("today", "patients", "formulary", "interactions")
STATE_FIELDS = ("medication_orders", "lab_orders", "escalations", "notes")


class ObstetricsDB(ForkableDB):
    REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = REFERENCE_FIELDS
    STATE_FIELDS: ClassVar[tuple[str, ...]] = STATE_FIELDS
    today: str = Field(description="ISO date of 'now' in this world (gestational ages are computed to it)")
    patients: dict[str, Patient]
    formulary: dict[str, ObstetricDrug]
    interactions: list[DrugInteraction] = Field(default_factory=list)
    medication_orders: list[MedicationOrder] = Field(default_factory=list)
    lab_orders: list[LabOrder] = Field(default_factory=list)
    escalations: list[Escalation] = Field(default_factory=list)
    notes: list[ClinicalNote] = Field(default_factory=list)
