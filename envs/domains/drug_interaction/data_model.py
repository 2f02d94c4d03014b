"""The drug-interaction database: reference tables built from registry packages, plus patients.

Reference tables (drugs, classes, ANSM interaction rules, dose ranges, renal adjustments) are
read-only: no tool writes them, so environments share one parsed copy and only the patient state
(`patients`, `medication_changes`) is copied per episode. That keeps `get_environment()` and the
toolkit's pre-WRITE snapshot cheap, and `content_hash()` reuses the reference part's hash.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Literal

from pydantic import BaseModel, Field, PrivateAttr, TypeAdapter

from envs.core.db import DB
from envs.core.models import StrictModel

Severity = Literal["none", "minor", "moderate", "major", "contraindicated"]
PartyKind = Literal["substance", "class", "non_drug", "route_group"]


class Provenance(StrictModel):
    """Where a record comes from: a pinned registry package (and the file inside it), or us."""

    package: str
    version: str
    license: str
    file: str | None = None
    record: str | None = None


class LocalizedText(StrictModel):
    """Source text in its own language; French ANSM text is kept as is, never machine-translated."""

    text: str
    language: Literal["fr", "en"]


class Drug(StrictModel):
    id: str = Field(description="canonical English name in the drug-named-entity-recognition vocabulary")
    name: str
    brand_names: list[str] = Field(default_factory=list)
    synonyms: list[str] = Field(default_factory=list)
    drugbank_id: str | None = None
    medline_plus_id: str | None = None
    mesh_id: str | None = None
    mesh_tree_numbers: list[str] = Field(default_factory=list)
    names_fr: list[str] = Field(default_factory=list, description="ANSM thesaurus substance names")
    class_ids: list[str] = Field(default_factory=list, description="ANSM classes (English ids)")
    descriptive_classes: list[str] = Field(default_factory=list, description="class text of drugdose / open-medicine")
    provenance: list[Provenance]


class DrugClass(StrictModel):
    id: str
    name: str
    name_fr: str
    kind: Literal["class", "non_drug", "route_group"] = "class"
    therapeutic: bool = False
    other_of: str | None = Field(default=None, description="for ANSM 'autres ...' classes: the class they complement")
    members: list[str] = Field(default_factory=list)
    unmatched_members_fr: list[str] = Field(default_factory=list)
    provenance: list[Provenance]


class Party(StrictModel):
    """One side of an ANSM rule: a substance (drug id) or a class, or a non-drug party."""

    kind: PartyKind
    id: str | None = Field(default=None, description="drug id or class id; None for an untranslated substance")
    name: str
    name_fr: str

    @property
    def key(self) -> str | None:
        return f"{'drug' if self.kind == 'substance' else 'class'}:{self.id}" if self.id else None


class DoseBand(StrictModel):
    """A level that applies at a daily dose of one drug of the pair, in mg/day: min <= dose < max."""
    drug: str
    min_daily_mg: float | None = None
    max_daily_mg: float | None = None


class RenalBand(StrictModel):
    """A level that applies at the patient's eGFR (CKD-EPI 2021, mL/min/1.73 m2): min <= eGFR < max."""
    egfr_min: float | None = None
    egfr_max: float | None = None


class SeverityLevel(StrictModel):
    label_fr: str
    label: str = Field(description="English translation of the ANSM level")
    level: Severity = Field(description="normalised level used by the reward")
    condition: LocalizedText | None = Field(default=None, description="ANSM conduct / conditions text")
    mentions: list[str] = Field(default_factory=list,
                                description="drug ids whose ANSM French name appears in the condition text")
    mentions_classes: list[str] = Field(default_factory=list,
                                        description="class ids whose ANSM French label appears in the condition text")
    mentions_other_substances: bool = Field(default=False,
                                            description="the condition names a thesaurus substance with no English match")
    dose_band: DoseBand | None = Field(default=None, description="US overlay: the daily-dose band this level applies to")
    renal_band: RenalBand | None = Field(default=None, description="US overlay: the eGFR band this level applies to")


class InteractionRule(StrictModel):
    id: str
    party_a: Party
    party_b: Party
    levels: list[SeverityLevel]
    severity: str = Field(description="English label of the most severe ANSM level")
    severity_level: Severity
    mechanism: LocalizedText
    see_also: LocalizedText | None = None
    summary: LocalizedText = Field(description="English summary derived from the structured fields only")
    source_entries: int = Field(description="thesaurus entries merged (the thesaurus lists most pairs twice)")
    provenance: list[Provenance]
    source: Literal["ansm", "us_overlay"] = Field(default="ansm", description="ANSM thesaurus, or the curated US overlay")
    evidence: str | None = Field(default=None, description="US overlay: the FDA label section or guideline the level follows")
    reviews: list[str] = Field(default_factory=list, description="US overlay: the ANSM rule ids this rule re-rates")


class RouteDose(StrictModel):
    route: str
    dose_min: float
    dose_max: float
    dose_unit: str
    per_kg: bool
    max_single_dose: float | None = None
    pediatric_max_dose: float | None = None
    cap_unit: str | None = Field(default=None, description="unit of max_single_dose / pediatric_max_dose")
    frequency: str = ""
    continuous_infusion: bool = False
    notes: str = ""


class DoseProfile(StrictModel):
    drug_id: str
    source_name: str
    display_name: str
    drug_class: str
    indication: str
    pregnancy_category: str | None = None
    renal_caution: bool = False
    hepatic_caution: bool = False
    controlled_substance: str | None = None
    reversal_agent: str | None = None
    contraindications: list[str] = Field(default_factory=list)
    allergy_cross_reactions: list[str] = Field(default_factory=list)
    min_age_years: float | None = None
    routes: list[RouteDose]
    provenance: list[Provenance]


class RenalTier(StrictModel):
    min: float
    max: float | None = None
    dose: str
    adjustment_type: str
    dialysis_note: str | None = None
    warnings: list[str] = Field(default_factory=list)


class RenalProfile(StrictModel):
    drug_id: str
    source_name: str
    drug_class: str
    route: str
    metric: Literal["crcl", "egfr"]
    normal_dose: str
    requires_tdm: bool = False
    monitoring: list[str] = Field(default_factory=list)
    hepatic_flag: bool = False
    source_doi: str | None = None
    source_description: str | None = None
    evidence_level: str | None = None
    tiers: list[RenalTier]
    provenance: list[Provenance]


class Allergy(StrictModel):
    allergen: str
    kind: Literal["substance", "class"]
    drug_id: str | None = None
    class_id: str | None = None
    reaction: str
    severity: Literal["mild", "moderate", "severe"]


class MedicationOrder(StrictModel):
    drug_id: str
    dose: float
    unit: str
    route: str
    frequency: str
    indication: str | None = None
    status: Literal["active", "discontinued"] = "active"


class Patient(StrictModel):
    patient_id: str
    name: str
    age: int
    sex: Literal["female", "male"]
    weight_kg: float
    height_cm: float | None = None
    serum_creatinine_mg_dl: float
    child_pugh_class: Literal["A", "B", "C"] | None = Field(default=None, description="None: no chronic liver disease")
    pregnant: bool = False
    gestational_age_weeks: int | None = None
    breastfeeding: bool = False
    conditions: list[str] = Field(default_factory=list)
    allergies: list[Allergy] = Field(default_factory=list)
    medications: list[MedicationOrder] = Field(default_factory=list)
    notes: str = ""
    provenance: list[Provenance]

    def active_medications(self) -> list[MedicationOrder]:
        return [m for m in self.medications if m.status == "active"]


class MedicationChange(StrictModel):
    change_id: str
    patient_id: str
    action: Literal["add", "discontinue", "dose_change"]
    drug_id: str
    details: dict[str, Any] = Field(default_factory=dict)
    reason: str = ""


class BuildInfo(StrictModel):
    builder_version: str
    inputs_hash: str
    sources: list[Provenance]
    counts: dict[str, int]
    unmatched_substances_fr: list[str] = Field(default_factory=list)


REFERENCE_FIELDS = ("build", "drugs", "name_index", "classes", "class_index", "interactions", "party_index",
                    "dose_profiles", "renal_profiles")
STATE_FIELDS = ("patients", "medication_changes")


class DrugInteractionDB(DB):
    """Formulary, ANSM interaction rules, dose and renal tables, and the patients (episode state)."""

    build: BuildInfo
    drugs: dict[str, Drug]
    name_index: dict[str, str] = Field(description="folded generic/brand/synonym/French name -> drug id")
    classes: dict[str, DrugClass]
    class_index: dict[str, str] = Field(description="folded English/French class name -> class id")
    interactions: dict[str, InteractionRule]
    party_index: dict[str, list[str]] = Field(description="'drug:<id>' / 'class:<id>' -> rule ids")
    dose_profiles: dict[str, DoseProfile]
    renal_profiles: dict[str, RenalProfile]
    patients: dict[str, Patient]
    medication_changes: list[MedicationChange] = Field(default_factory=list)

    _reference_hash: str | None = PrivateAttr(default=None)

    # -- cheap copies and hashes -----------------------------------------------------------------
    def state_json(self) -> bytes:
        """The episode state (patients, medication changes) as JSON, in a fixed field order."""
        return _STATE.dump_json((self.patients, self.medication_changes))

    def with_state(self, state_json: bytes) -> "DrugInteractionDB":
        """A new database sharing the read-only reference tables, with its own copy of the state."""
        patients, changes = _STATE.validate_json(state_json)
        data: dict[str, Any] = {name: getattr(self, name) for name in REFERENCE_FIELDS}
        clone = type(self).model_construct(**data, patients=patients, medication_changes=changes)
        clone._reference_hash = self._reference_hash
        return clone

    def fork(self) -> "DrugInteractionDB":
        return self.with_state(self.state_json())

    def __deepcopy__(self, memo: dict | None = None) -> "DrugInteractionDB":
        return self.fork()

    def reference_hash(self) -> str:
        if self._reference_hash is None:
            self._reference_hash = _hash({name: _dump(getattr(self, name)) for name in REFERENCE_FIELDS})
        return self._reference_hash

    def content_hash(self) -> str:
        """SHA-256 over the reference tables' hash and the state JSON (patients are keyed in build
        order and tools never add or reorder them, so equal states serialise identically)."""
        digest = hashlib.sha256(self.reference_hash().encode())
        digest.update(self.state_json())
        return digest.hexdigest()


def _dump(value: Any) -> Any:
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if isinstance(value, dict):
        return {k: _dump(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_dump(v) for v in value]
    return value


def _hash(payload: Any) -> str:
    canonical = json.dumps(payload, sort_keys=True, ensure_ascii=False, separators=(",", ":"))
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


_STATE = TypeAdapter(tuple[dict[str, Patient], list[MedicationChange]])
