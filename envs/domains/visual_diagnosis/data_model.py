"""The visual-diagnosis database: imaging studies whose pixels live in PNG files of the build folder,
an archive of confirmed reference cases, a glossary of imaging signs, and what the reader records.

The ground truth a study was rendered from is not stored here (tools see only the pixels and the
metadata); it lives in the generated task's metadata for grading.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field

from envs.core.db import ForkableDB
from envs.core.models import StrictModel


class PatientInfo(StrictModel):
    age: int
    sex: Literal["female", "male"]
    history: str
    smoking_pack_years: float = 0
    lung_cancer_risk: Literal["low", "high"] = "low"
    symptoms: list[str] = Field(default_factory=list)
    # A known primary cancer (e.g. a CT done for staging): Fleischner 2017 excludes these patients.
    known_malignancy: str | None = None


class Study(StrictModel):
    study_id: str
    modality: Literal["CR", "CT"]
    body_part: str
    view: str
    image_file: str = Field(description="PNG path relative to the domain build folder")
    width: int
    height: int
    pixel_spacing_mm: float
    orientation: str
    indication: str
    acquired: str
    patient: PatientInfo
    prior_study_id: str | None = None
    provenance: dict[str, str] = Field(default_factory=dict)


class ArchivedCase(StrictModel):
    """A reference case with a confirmed diagnosis and its structured findings."""

    case_id: str
    modality: Literal["CR", "CT"]
    finding: str
    side: str
    zone: str
    size_mm: float | None = None
    nodule_type: str | None = None
    age: int
    sex: Literal["female", "male"]
    smoking_pack_years: float
    confirmed_diagnosis: str
    confirmation: str
    summary: str


class ImagingSign(StrictModel):
    term: str
    definition: str
    significance: str
    synonyms: list[str] = Field(default_factory=list)


class RecordedFinding(StrictModel):
    study_id: str
    finding: str
    side: str
    location: str
    size_mm: float | None = None


class CriticalEscalation(StrictModel):
    study_id: str
    finding: str
    recipient: str


REFERENCE_FIELDS = ("studies", "archive", "signs")
STATE_FIELDS = ("recorded_findings", "escalations")


class VisualDB(ForkableDB):
    REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = REFERENCE_FIELDS
    STATE_FIELDS: ClassVar[tuple[str, ...]] = STATE_FIELDS
    studies: dict[str, Study]
    archive: dict[str, ArchivedCase]
    signs: dict[str, ImagingSign]
    recorded_findings: list[RecordedFinding] = Field(default_factory=list)
    escalations: list[CriticalEscalation] = Field(default_factory=list)
