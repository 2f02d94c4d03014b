"""The radiology-report database: imaging studies with structured findings, report templates, and
the reports radiologists draft, communicate and finalise.

Studies and templates are read-only (shared by every episode). The report state is structured:
status, category and whether a critical result was communicated. `content_hash` covers that
structured state only (not the narrative text, not the read-only studies), so two reports that
reach the same decisions hash equal and a task can be graded by its final database state.
"""

from __future__ import annotations

import hashlib
import json
from typing import ClassVar, Literal

from pydantic import Field

from envs.core.db import ForkableDB
from envs.core.models import StrictModel
from envs.domains.imaging_guidelines import (KNOWN_MALIGNANCY_ALIASES, KNOWN_MALIGNANCY_GUIDELINE,  # noqa: F401  re-exported
                                             KNOWN_MALIGNANCY_MANAGEMENT)


class PatientInfo(StrictModel):
    age: int
    sex: Literal["female", "male"]
    history: str
    smoking_pack_years: float = 0
    lung_cancer_risk: Literal["low", "high"] = "low"
    risk_factors: list[str] = Field(default_factory=list)
    # A known primary cancer (e.g. a CT done for staging): Fleischner 2017 excludes these patients.
    known_malignancy: str | None = None


class Finding(StrictModel):
    finding_id: str
    kind: Literal["thyroid_nodule", "breast_mass", "breast_calcifications", "breast_distortion", "lung_nodule", "other"]
    location: str
    description: str = ""
    # thyroid (ACR TI-RADS lexicon)
    dimensions_cm: list[float] | None = None
    composition: str | None = None
    echogenicity: str | None = None
    shape: str | None = None
    margin: str | None = None
    echogenic_foci: list[str] | None = None
    # breast (BI-RADS lexicon)
    mass_shape: str | None = None
    mass_margin: str | None = None
    mass_typically_benign: bool | None = None
    stable_2_years: bool | None = None
    calcification_morphology: str | None = None
    size_mm: float | None = None
    # lung
    nodule_type: str | None = None
    long_axis_mm: float | None = None
    short_axis_mm: float | None = None
    solid_long_mm: float | None = None
    solid_short_mm: float | None = None
    suspicious_features: list[str] = Field(default_factory=list)


class PriorStudy(StrictModel):
    study_id: str
    months_ago: float
    report: str
    category: str | None = None
    findings: list[Finding] = Field(default_factory=list)


class Study(StrictModel):
    study_id: str
    modality: Literal["US", "MG", "CT", "LDCT"]
    region: Literal["thyroid", "breast", "chest"]
    exam: str
    indication: str
    technique: str
    priority: Literal["routine", "urgent"] = "routine"
    patient: PatientInfo
    findings: list[Finding]
    exam_complete: bool = True
    known_biopsy_proven_malignancy: bool = False
    prior: PriorStudy | None = None
    provenance: dict[str, str] = Field(default_factory=dict)


class ReportTemplate(StrictModel):
    key: str
    modality: str
    region: str
    title: str
    sections: list[str]
    required_elements: list[str]
    category_system: str
    category_pattern: str
    critical_categories: list[str]
    reference: str


class Report(StrictModel):
    study_id: str
    status: Literal["draft", "final"]
    category: str
    findings_text: str
    impression: str
    recommendation: str
    revisions: int = 0


class CriticalCommunication(StrictModel):
    study_id: str
    recipient: str
    method: Literal["phone", "in person", "secure message"]
    finding: str


REFERENCE_FIELDS = ("studies", "templates")
STATE_FIELDS = ("reports", "communications")


class RadiologyDB(ForkableDB):
    REFERENCE_FIELDS: ClassVar[tuple[str, ...]] = REFERENCE_FIELDS
    STATE_FIELDS: ClassVar[tuple[str, ...]] = STATE_FIELDS
    studies: dict[str, Study]
    templates: dict[str, ReportTemplate]
    reports: dict[str, Report] = Field(default_factory=dict)
    communications: list[CriticalCommunication] = Field(default_factory=list)


    def decision_state(self) -> dict:
        """The graded state: per report its status and category; per communication the study and method."""
        return {"reports": {k: {"status": r.status, "category": r.category} for k, r in sorted(self.reports.items())},
                "communications": sorted({(c.study_id, c.method) for c in self.communications})}

    def content_hash(self) -> str:
        """SHA-256 of the decision state only: the read-only studies and templates are the same in
        every episode, so tasks can carry an expected hash that survives rebuilds of the study set."""
        state = json.dumps(self.decision_state(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(state.encode("utf-8")).hexdigest()
