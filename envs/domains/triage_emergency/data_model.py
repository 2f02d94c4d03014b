"""The emergency-department triage database: patients at the front door with chief complaint, vital
signs, GCS components, point-of-care results held back until ordered, and what the triage nurse or
physician did (triage level, ECG and test orders, alerts, escalations, notes)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from envs.core.db import DB
from envs.core.models import StrictRecord


class EDVitals(StrictRecord):
    time: str
    heart_rate: float | None = None
    systolic_bp: float | None = None
    diastolic_bp: float | None = None
    respiratory_rate: float | None = None
    temperature_c: float | None = None
    spo2: float | None = None
    on_supplemental_oxygen: bool = False
    gcs_eye: int | None = Field(default=None, ge=1, le=4)
    gcs_verbal: int | None = Field(default=None, ge=1, le=5)
    gcs_motor: int | None = Field(default=None, ge=1, le=6)
    avpu: Literal["alert", "new_confusion", "voice", "pain", "unresponsive"] | None = None
    pain_score: int | None = Field(default=None, ge=0, le=10)


class HeldResult(StrictRecord):
    value: float | str
    unit: str


class EDResult(StrictRecord):
    test: str
    value: float | str
    unit: str
    order_id: str


class GivenMedication(StrictRecord):
    """A medication given at triage under a standing order (time from the department clock)."""

    drug: str
    dose_mg: float
    route: str
    time: str
    indication: str = ""


class TriageAssignment(StrictRecord):
    esi_level: int = Field(ge=1, le=5)
    rationale: str = ""


class Alert(StrictRecord):
    kind: Literal["stemi", "stroke", "escalation"]
    detail: str


class EDPatient(StrictRecord):
    patient_id: str
    age: int = Field(ge=0, le=120)
    age_months: int | None = None
    sex: Literal["male", "female", "other"]
    weight_kg: float | None = None
    arrival_mode: Literal["walk-in", "ambulance", "helicopter", "police", "transfer"] = "walk-in"
    chief_complaint: str
    history: str = ""
    medical_history: list[str] = Field(default_factory=list)
    medications: list[str] = Field(default_factory=list)
    allergies: list[str] = Field(default_factory=list)
    vitals: list[EDVitals] = Field(default_factory=list)
    burn_tbsa_percent: float | None = None
    last_known_well: str | None = None
    held_results: dict[str, HeldResult] = Field(default_factory=dict)
    results: list[EDResult] = Field(default_factory=list)
    triage: TriageAssignment | None = None
    alerts: list[Alert] = Field(default_factory=list)
    medications_given: list[GivenMedication] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)
    source: str = "authored"
    source_case_id: str | None = None


class TriageDB(DB):
    patients: dict[str, EDPatient]
    clock: str = "2025-03-01T14:00"
    next_order_number: int = 1

