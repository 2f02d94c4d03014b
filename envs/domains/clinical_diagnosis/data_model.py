"""The clinical-diagnosis database: outpatient/ED/ward patients with history, vitals, examination,
coded findings, laboratory results, hidden (not yet ordered) results, orders, diagnoses,
prescriptions and notes."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from envs.core.db import DB
from envs.core.models import StrictRecord


class Allergy(StrictRecord):
    substance: str
    reaction: str = ""
    severity: Literal["mild", "moderate", "severe"] = "moderate"


class Medication(StrictRecord):
    name: str
    dose: str = ""
    frequency: str = ""


class VitalSigns(StrictRecord):
    time: str
    heart_rate: float | None = None
    systolic_bp: float | None = None
    diastolic_bp: float | None = None
    respiratory_rate: float | None = None
    temperature_c: float | None = None
    spo2: float | None = None
    on_supplemental_oxygen: bool = False
    pain_score: int | None = None


class Finding(StrictRecord):
    """A clinical finding coded to HPO so the differential engine can use it."""

    hpo_id: str
    label: str
    source: Literal["history", "exam", "lab", "imaging"] = "history"
    # A lab/imaging finding is known only once this test has a visible result.
    requires_test: str | None = None


class LabResult(StrictRecord):
    test: str
    value: float | str
    unit: str
    time: str
    order_id: str | None = None


class HiddenResult(StrictRecord):
    """A result the case holds back until the test is ordered (then it is 'resulted')."""

    value: float | str
    unit: str
    turnaround_min: int = 60


class LabOrder(StrictRecord):
    order_id: str
    test: str
    priority: Literal["routine", "urgent", "stat"] = "routine"
    status: Literal["resulted", "pending"] = "pending"
    indication: str = ""


class DiagnosisRecord(StrictRecord):
    icd10_code: str
    description: str
    certainty: Literal["confirmed", "provisional", "differential"] = "provisional"


class Prescription(StrictRecord):
    prescription_id: str
    drug: str
    dose: str
    route: str
    frequency: str
    duration_days: int | None = None
    indication: str = ""


class ClinicalNote(StrictRecord):
    note_id: str
    note_type: str
    content: str


class FollowUp(StrictRecord):
    appointment_id: str
    service: str
    within_days: int
    reason: str


class Patient(StrictRecord):
    patient_id: str
    name: str
    age: int = Field(ge=0, le=120)
    sex: Literal["male", "female"]
    weight_kg: float | None = None
    setting: Literal["clinic", "emergency", "ward", "genetics clinic"] = "clinic"
    chief_complaint: str
    history_of_present_illness: str
    past_medical_history: list[str] = Field(default_factory=list)
    medications: list[Medication] = Field(default_factory=list)
    allergies: list[Allergy] = Field(default_factory=list)
    social_history: str = ""
    family_history: str = ""
    review_of_systems: dict[str, str] = Field(default_factory=dict)
    vitals: list[VitalSigns] = Field(default_factory=list)
    physical_exam: dict[str, str] = Field(default_factory=dict)
    findings: list[Finding] = Field(default_factory=list)
    lab_results: list[LabResult] = Field(default_factory=list)
    hidden_results: dict[str, HiddenResult] = Field(default_factory=dict)
    orders: list[LabOrder] = Field(default_factory=list)
    diagnoses: list[DiagnosisRecord] = Field(default_factory=list)
    prescriptions: list[Prescription] = Field(default_factory=list)
    notes: list[ClinicalNote] = Field(default_factory=list)
    follow_ups: list[FollowUp] = Field(default_factory=list)
    provenance: str = "authored"


class FormularyDrug(StrictRecord):
    """A prescribable drug: its class, the allergy groups it belongs to, and the usual dose bounds."""

    name: str
    drug_class: str
    allergy_groups: list[str] = Field(default_factory=list)
    routes: list[str] = Field(default_factory=list)
    max_single_dose_mg: float | None = None
    max_daily_dose_mg: float | None = None
    aliases: list[str] = Field(default_factory=list)


class ClinicalDiagnosisDB(DB):
    patients: dict[str, Patient]

    formulary: dict[str, FormularyDrug] = Field(default_factory=dict)
    clock: str = "2025-03-01T09:00"
    next_order_number: int = 1
