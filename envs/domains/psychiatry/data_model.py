"""The psychiatry database: patients with interviews and symptom reports, and what clinicians record.

Reference tables (psychotropic formulary with FDA classes, the interaction rules, ICD-10-CM
chapter 5 codes) are read-only and shared by every episode; the episode state is the patients
and the records the agent writes (mental status exams, safety plans, escalations, diagnoses,
lab orders, follow-ups).
"""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field

from envs.core.db import ForkableDB
from envs.core.models import StrictModel


class Utterance(StrictModel):
    speaker: Literal["clinician", "patient", "collateral"]
    text: str


class Medication(StrictModel):
    name: str
    dose_mg: float
    frequency: str


class LabResult(StrictModel):
    name: str
    value: float
    unit: str
    ref_low: float | None = None
    ref_high: float | None = None
    collected: str = Field(description="relative time, e.g. 'today 08:10' or '3 months ago'")


class SuicideAttempt(StrictModel):
    when: str
    method: str
    medical_care_needed: bool


class PsychHistory(StrictModel):
    diagnoses: list[str] = Field(default_factory=list)
    hospitalizations: int = 0
    last_hospitalization: str | None = None
    suicide_attempts: list[SuicideAttempt] = Field(default_factory=list)
    self_harm: str | None = None
    family_history: list[str] = Field(default_factory=list)
    substance_use: list[str] = Field(default_factory=list)
    trauma: str | None = None


class SocialHistory(StrictModel):
    living: str
    supports: list[str] = Field(default_factory=list)
    employment: str
    firearms_access: bool = False
    recent_stressors: list[str] = Field(default_factory=list)


class CSSRSAnswers(StrictModel):
    wish_to_be_dead: bool
    suicidal_thoughts: bool
    thoughts_with_method: bool = False
    intent: bool = False
    plan_with_intent: bool = False
    suicidal_behavior: Literal["never", "over_3_months_ago", "past_3_months"] = "never"


class MDQAnswers(StrictModel):
    items: list[bool] = Field(min_length=13, max_length=13)
    same_period: bool
    problem_level: Literal["no problem", "minor problem", "moderate problem", "serious problem"]


class CAGEAnswers(StrictModel):
    cut_down: bool
    annoyed: bool
    guilty: bool
    eye_opener: bool


class CIWAObservation(StrictModel):
    nausea_vomiting: int
    tremor: int
    paroxysmal_sweats: int
    anxiety: int
    agitation: int
    tactile_disturbances: int
    auditory_disturbances: int
    visual_disturbances: int
    headache: int
    orientation: int


class SymptomReports(StrictModel):
    """Completed forms on file (self-report or clinician-administered). An instrument asked only
    in the interview is in the transcript, not here."""

    phq9: list[int] | None = None
    gad7: list[int] | None = None
    epds: list[int] | None = None
    audit_c: list[int] | None = None
    mdq: MDQAnswers | None = None
    cage: CAGEAnswers | None = None
    cssrs: CSSRSAnswers | None = None
    ciwa: CIWAObservation | None = None


class Patient(StrictModel):
    patient_id: str
    name: str
    age: int
    sex: Literal["female", "male"]
    setting: str
    chief_complaint: str
    presenting_history: str
    pregnant: bool = False
    weeks_postpartum: int | None = None
    history: PsychHistory
    social: SocialHistory
    medications: list[Medication] = Field(default_factory=list)
    allergies: list[str] = Field(default_factory=list)
    labs: list[LabResult] = Field(default_factory=list)
    orderable_results: dict[str, LabResult] = Field(
        default_factory=dict, description="results that appear in get_lab_results once the test is ordered")
    transcript: list[Utterance] = Field(default_factory=list)
    reports: SymptomReports = Field(default_factory=SymptomReports)
    observations: dict[str, str] = Field(default_factory=dict, description="nursing/clinician observations for the MSE")
    provenance: dict[str, str] = Field(default_factory=dict)


class FormularyDrug(StrictModel):
    name: str
    brands: list[str] = Field(default_factory=list)
    fda_classes: list[str] = Field(default_factory=list)
    groups: list[str] = Field(default_factory=list, description="interaction-rule groups (authored), e.g. 'serotonergic'")
    provenance: dict[str, str] = Field(default_factory=dict)


class InteractionRule(StrictModel):
    id: str
    name: str
    severity: Literal["contraindicated", "major", "moderate", "minor"]
    group_a: str
    group_b: str | None = Field(default=None, description="None: two distinct drugs of group_a")
    mechanism: str
    management: str
    reference: str


class LabelGradedPair(StrictModel):
    """A formulary pair as the drug_interaction domain grades it (computed at build time, `interactions.py`)."""
    a: str
    b: str
    severity: Literal["contraindicated", "major", "moderate", "minor"]
    rule: str = Field(description="the drug_interaction rule id that sets the level (US-0xx, US-Rxx, ANSM-xxxx)")
    summary: str


class MSERecord(StrictModel):
    patient_id: str
    appearance: str
    behavior: str
    speech: str
    mood: str
    affect: Literal["euthymic", "constricted", "blunted", "flat", "labile", "anxious", "dysphoric", "euphoric", "irritable"]
    thought_process: Literal["linear", "circumstantial", "tangential", "flight of ideas", "loose associations", "thought blocking"]
    thought_content: str
    suicidal_ideation: bool
    homicidal_ideation: bool
    perception: str
    cognition: str
    insight: Literal["good", "fair", "limited", "poor", "absent"]
    judgment: Literal["good", "fair", "limited", "poor"]
    risk_flags: list[str] = Field(default_factory=list)


class SafetyPlan(StrictModel):
    patient_id: str
    warning_signs: list[str]
    coping_strategies: list[str]
    social_contacts: list[str]
    professional_contacts: list[str]
    crisis_line: str
    means_restriction: str
    reasons_for_living: list[str] = Field(default_factory=list)


class Escalation(StrictModel):
    patient_id: str
    level: str
    reason: str


class DiagnosisRecord(StrictModel):
    patient_id: str
    icd10_code: str
    description: str


class LabOrder(StrictModel):
    patient_id: str
    test: str
    status: Literal["resulted", "not available"]


class FollowUp(StrictModel):
    patient_id: str
    within_days: int
    with_whom: str
    purpose: str


REFERENCE_FIELDS = ("patients", "formulary", "interaction_rules", "label_graded_pairs", "icd10_mental")
STATE_FIELDS = ("mse_records", "safety_plans", "escalations", "diagnoses", "lab_orders", "follow_ups")


class PsychiatryDB(ForkableDB):
    """Patients and reference tables are read-only (no tool changes them); the record lists are the
    episode state. Forks share the read-only part, so a reset, a WRITE snapshot and the content
    hash cost microseconds instead of re-serialising every patient."""
    REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = REFERENCE_FIELDS
    STATE_FIELDS: ClassVar[tuple[str, ...]] = STATE_FIELDS

    patients: dict[str, Patient]
    formulary: dict[str, FormularyDrug]
    interaction_rules: list[InteractionRule]
    label_graded_pairs: list[LabelGradedPair] = Field(
        description="the drug_interaction domain's severity of each formulary pair it grades; these pairs are not graded by interaction_rules")
    icd10_mental: dict[str, str] = Field(description="billable ICD-10-CM chapter 5 (F) codes -> description")
    mse_records: list[MSERecord] = Field(default_factory=list)
    safety_plans: list[SafetyPlan] = Field(default_factory=list)
    escalations: list[Escalation] = Field(default_factory=list)
    diagnoses: list[DiagnosisRecord] = Field(default_factory=list)
    lab_orders: list[LabOrder] = Field(default_factory=list)
    follow_ups: list[FollowUp] = Field(default_factory=list)
