"""The schema of an authored case file (`envs/domains/cross_domain/cases/<family>.yaml`).

One file holds one pathway family (its title and its cases); one case is one patient's journey:
the person (the same in every domain), the observations, the clinical content each domain's record
adds, the phases with their gold actions and the final question. Every model is strict: an unknown
or misspelt key is an error naming it, never a silently dropped value. What the records share or
can compute (identity, home medications, chart vitals, mean arterial pressure, order and note ids,
the time-pressure flag) is not written here: `rendering.py` derives it.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from envs.core.models import StrictModel

# Numbers keep the form they are written in (10 stays 10, 86.0 stays 86.0), so the generated JSON
# reads as the case file does.
Number = int | float
Value = int | float | str  # a result: a measurement or a report's text


class Allergy(StrictModel):
    substance: str
    reaction: str
    severity: Literal["mild", "moderate", "severe"] = "moderate"
    # How the drug-interaction profile names it when that differs from `substance`: a substance, or an
    # ANSM class (kind "class", e.g. "penicillins").
    pharmacy: str | None = None
    kind: Literal["substance", "class"] = "substance"


class Medication(StrictModel):
    drug: str
    dose: Number
    unit: str
    route: Literal["PO", "IV", "SC", "IM", "INH", "PR", "SL", "TOP"]
    frequency: str
    indication: str


class Person(StrictModel):
    """What every domain's record of the patient shares."""

    patient_id: str = Field(pattern=r"^[A-Z]{2}-[A-Z]{2}\d{2}$")
    name: str
    age: int = Field(ge=0, le=120)
    sex: Literal["male", "female"]
    weight_kg: Number = Field(gt=0)
    height_cm: Number | None = None
    age_months: int | None = Field(default=None, ge=0)
    conditions: list[str] = Field(default_factory=list)
    allergies: list[Allergy] = Field(default_factory=list)
    medications: list[Medication] = Field(default_factory=list)  # home medications
    creatinine_mg_dl: Number = 0.9


class Observations(StrictModel):
    """The observations every vital-sign row has, in the order the records list them."""

    time: str
    heart_rate: Number
    systolic_bp: Number
    diastolic_bp: Number
    respiratory_rate: Number
    temperature_c: Number
    spo2: Number


class Vitals(Observations):
    """One set of observations in the triage shape; the diagnostic chart shows the same row without
    GCS and AVPU."""

    on_supplemental_oxygen: bool = False
    gcs_eye: int | None = None
    gcs_verbal: int | None = None
    gcs_motor: int | None = None
    avpu: Literal["alert", "new_confusion", "voice", "pain", "unresponsive"] | None = None  # ACVPU (NEWS2)
    pain_score: int | None = Field(default=None, ge=0, le=10)


class HeldResult(StrictModel):
    """A triage ECG or point-of-care result, released when ordered."""

    value: Value
    unit: str


class HiddenResult(StrictModel):
    """A diagnostic result released by order_lab after its turnaround."""

    value: Value
    unit: str
    turnaround_min: int = Field(ge=0)


class LabResult(StrictModel):
    """A result already on the chart."""

    test: str
    value: Value
    unit: str
    time: str


class Finding(StrictModel):
    hpo_id: str = Field(pattern=r"^HP:\d{7}$")
    label: str
    source: Literal["history", "exam", "lab", "imaging"] = "history"
    requires_test: str | None = None


class TriageRecord(StrictModel):
    """The ED front door (`triage_emergency`); its vitals are the case's `vitals`."""

    arrival_mode: str = "walk-in"
    chief_complaint: str
    history: str
    held_results: dict[str, HeldResult] = Field(default_factory=dict)
    last_known_well: str | None = None
    encounter_time: str = "2025-03-01T14:00"


class ClinicalRecord(StrictModel):
    """The diagnostic chart (`clinical_diagnosis`); its vitals are the case's `vitals`, and an
    admitted patient's inpatient orders follow the home medications."""

    setting: str = "emergency"
    chief_complaint: str
    history_of_present_illness: str
    review_of_systems: dict[str, str] = Field(default_factory=dict)
    social_history: str = ""
    family_history: str = ""
    physical_exam: dict[str, str]
    findings: list[Finding]
    lab_results: list[LabResult] = Field(default_factory=list)
    hidden_results: dict[str, HiddenResult]
    encounter_time: str = "2025-03-01T14:30"


class PharmacyRecord(StrictModel):
    """The medication profile (`drug_interaction`); an admitted patient's inpatient orders follow
    the home medications."""

    pregnant: bool = False
    notes: str = ""


class EHRVitals(Observations):
    """A charted observation; the mean arterial pressure is computed from the blood pressure."""

    gcs: int = Field(default=15, ge=3, le=15)
    fio2: Number | None = None
    urine_output_ml: Number | None = None


class LabEvent(StrictModel):
    time: str
    test: str
    value: Value
    unit: str


class MedicationOrder(Medication):
    start: str


class Note(StrictModel):
    time: str
    note_type: str
    text: str


class Admission(StrictModel):
    """The inpatient stay (`ehr_management`): the home medications are continued as orders
    `<hadm_id>-HOME<n>` from admission, the admission's own orders are `<hadm_id>-MED<n>`."""

    hadm_id: str
    admit_time: str
    diagnosis: str
    admission_type: str = "elective"
    icd10_codes: list[str] = Field(default_factory=list)
    medication_orders: list[MedicationOrder] = Field(default_factory=list)
    lab_events: list[LabEvent] = Field(default_factory=list)
    vital_events: list[EHRVitals] = Field(default_factory=list)
    notes: list[Note] = Field(default_factory=list)


class EHRRecord(StrictModel):
    admission: Admission
    conditions_since: str = "2015-01-01"
    encounter_time: str = "2025-03-05T08:00"


class Records(StrictModel):
    """The clinical content each domain adds to the person, keyed by domain."""

    ehr_management: EHRRecord | None = None
    triage_emergency: TriageRecord | None = None
    clinical_diagnosis: ClinicalRecord | None = None
    drug_interaction: PharmacyRecord | None = None


class Action(StrictModel):
    """A required action: the tool, its gold arguments, and the arguments that must match."""

    name: str
    arguments: dict[str, Any] = Field(default_factory=dict)
    compare_args: list[str] = Field(default_factory=lambda: ["patient_id"])


class Phase(StrictModel):
    name: str
    domain: Literal["triage_emergency", "clinical_diagnosis", "drug_interaction", "ehr_management"]
    goal: str
    required_actions: list[Action] = Field(min_length=1)
    nl_assertions: list[str] = Field(min_length=1)
    # What the reference clinician states in this phase: the findings and decisions each of the phase's
    # NL assertions checks, in the guideline's words. The phases' statements are the gold submission's
    # reasoning (the task's `metadata.gold_reasoning`, which `envs.validate.gold_replay` submits), so
    # an assertion about what the agent says or plans ("plans aPTT monitoring") can be met by the gold.
    gold_reasoning: str = Field(min_length=20)
    # "required_actions": the phase ends when every required action is done; "agent_declares": the
    # agent ends it with complete_phase.
    transition: Literal["required_actions", "agent_declares"] = "required_actions"
    max_calls: int | None = Field(default=None, ge=1)  # a call budget marks the phase time-pressured


class Case(StrictModel):
    id: str = Field(pattern=r"^[a-z0-9_]+$")
    split: Literal["train", "test"] = "train"
    # The published guideline(s) or product label(s) the case's decisions follow, for the reviewer.
    guideline: str = Field(min_length=10)
    emergency: str | None = None
    presentation: str
    patient: Person
    vitals: list[Vitals] = Field(default_factory=list)
    records: Records
    phases: list[Phase] = Field(min_length=1)
    final_question: str
    final_answer: str
    answer_aliases: list[str] = Field(default_factory=list)


class CaseFile(StrictModel):
    """One pathway family: its title (the tasks' category), what it covers, and its cases."""

    title: str
    summary: str
    cases: list[dict[str, Any]] = Field(min_length=1)  # each validated as a `Case`, so errors name it
