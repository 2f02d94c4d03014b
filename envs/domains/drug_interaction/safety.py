"""`SafetyContext` for the reward's violation detector, answered from the episode's database.

The context reads the toolkit's *current* database (a failed WRITE restores a snapshot, so the
object changes during an episode), so facts reflect the state at the end of the episode.

Pregnancy: `logic.pregnancy_assessment`, as `check_pregnancy_safety` reports it. The domain's label
table (`logic.PREGNANCY_LABEL_RULES`, shared in envs/domains/pregnancy_labels.py, each entry with its
label section) answers first; a contraindication the label limits to one indication (valproate:
migraine prophylaxis, section 4) is not a pregnancy contraindication of the drug here; the reward's
lexicon applies it when the episode names that indication (`safety_lexicon.PREGNANCY_CONTRAINDICATED_FOR`). Else
drugdose 0.1.2's letter (package data; category X is a contraindication); else the reward lexicon's
table of US-label pregnancy contraindications (`safety_lexicon.PREGNANCY_CONTRAINDICATED`: boxed
warnings and section 4 of the labels), by drug and by class (ACE inhibitors, ARBs), so lisinopril,
warfarin or isotretinoin in a pregnant patient are caught although drugdose has no category for them.
"""

from __future__ import annotations

from typing import Callable

from envs.rewards.safety import BaseSafetyContext

from . import logic as L
from .data_model import DrugInteractionDB
from .translate import fold

# ANSM classes -> the class names the reward's duplication check knows (conventions.duplication_classes).
CONVENTION_CLASSES = {
    "non-steroidal-anti-inflammatory-drugs": "nsaids",
    "hmg-coa-reductase-inhibitors-statins": "statins",
    "selective-serotonin-reuptake-inhibitors": "ssris",
    "ace-inhibitors": "ace inhibitors",
    "angiotensin-ii-receptor-blockers": "arbs",
    "oral-anticoagulants": "anticoagulants",
    "opioids": "opioids",
    "benzodiazepines-and-related-drugs": "benzodiazepines",
    "beta-blockers-except-esmolol-including-eye-drops": "beta blockers",
    "proton-pump-inhibitors": "proton pump inhibitors",
    "antiplatelet-agents": "antiplatelets",
    "sulfonylureas": "sulfonylureas",
    "antipsychotic-neuroleptics-except-clozapine": "antipsychotics",
    "irreversible-mao-inhibitors": "maois",
    "mao-b-inhibitors": "maois",
}


class DrugInteractionSafetyContext(BaseSafetyContext):
    """Allergies, medications, classes, ANSM interactions and dose caps of the drug-interaction domain."""

    def __init__(self, get_db: Callable[[], DrugInteractionDB]) -> None:
        self._get_db = get_db

    @property
    def db(self) -> DrugInteractionDB:
        return self._get_db()

    def _drug(self, name: str):
        try:
            return L.resolve_drug(self.db, name)
        except L.LookupFailure:
            return None

    def _patient(self, patient_id: str):
        try:
            return L.get_patient(self.db, patient_id)
        except L.LookupFailure:
            return None

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        return [(self.db.classes[a.class_id].name if a.class_id else a.drug_id or a.allergen).lower() for a in p.allergies]

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return [m.drug_id for m in p.active_medications()] if p else []

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        out = [c.lower() for c in p.conditions]
        if p.pregnant:
            out.append("pregnancy")
        if p.child_pugh_class:
            out.append(f"child-pugh {p.child_pugh_class.lower()}")
        crcl, egfr = L.cockcroft_gault(p), L.ckd_epi_2021(p)
        for threshold in self._renal_thresholds():
            if crcl < threshold:
                out.append(f"crcl < {threshold:g}")
            if egfr < threshold:
                out.append(f"egfr < {threshold:g}")
        return out

    def _renal_thresholds(self) -> list[float]:
        return sorted({x for limits in self.renal_contraindication_limits().values() for x in limits})

    def renal_contraindication_limits(self) -> dict[str, list[float]]:
        """metric ('crcl'/'egfr') -> the 'below X' limits of the renal bands the drugs' US labels
        contraindicate (logic.RENAL_LABEL_RULES), not the renal table's own word."""
        out: dict[str, set[float]] = {}
        for profile in self.db.renal_profiles.values():
            below = L.renal_contraindicated_below(profile)
            if below is not None:
                out.setdefault(profile.metric, set()).add(below)
        return {metric: sorted(limits) for metric, limits in out.items()}

    def normalise_drug(self, name: str) -> str | None:
        drug = self._drug(name)
        return drug.id if drug else None

    def drug_classes(self, drug: str) -> list[str]:
        """Therapeutic ANSM classes, smallest (most specific) first, then the reward's class names.
        Risk groupings ("sedative drugs") are not classes for allergy or duplication purposes."""
        d = self._drug(drug)
        if d is None:
            return []
        classes = [self.db.classes[c] for c in d.class_ids if self.db.classes[c].therapeutic]
        ordered = [c.name.lower() for c in sorted(classes, key=lambda c: (len(c.members), c.id))]
        ordered += [CONVENTION_CLASSES[c] for c in d.class_ids if c in CONVENTION_CLASSES]
        return list(dict.fromkeys(ordered))

    def interaction(self, drug_a: str, drug_b: str, patient_id: str | None = None) -> tuple[str, str] | None:
        """The pair's severity on the US-referenced scale (the US overlay's level where it has one,
        else ANSM's), evaluated at the patient's doses and eGFR when a patient is given."""
        a, b = self._drug(drug_a), self._drug(drug_b)
        if a is None or b is None or a.id == b.id:
            return None
        patient = self._patient(patient_id) if patient_id else None
        ctx = L.patient_context(self.db, patient) if patient is not None else None
        assessed = L.assess_pair(self.db, a, b, ctx)
        if not assessed:
            return None
        rule, _, _ = assessed[0]
        return L.effective_severity(assessed), f"{rule.id}: {rule.summary.text}"

    def patient_interaction(self, patient_id: str, drug_a: str, drug_b: str) -> tuple[str, str] | None:
        return self.interaction(drug_a, drug_b, patient_id)

    def max_dose_mg(self, drug: str, route: str | None = None) -> float | None:
        d = self._drug(drug)
        profile = self.db.dose_profiles.get(d.id) if d else None
        if profile is None:
            return None
        caps = [r.max_single_dose * L._MASS_TO_MG[r.cap_unit] for r in profile.routes
                if r.max_single_dose and r.cap_unit in L._MASS_TO_MG and not r.continuous_infusion
                and (route is None or fold(r.route) == fold(route))]
        return max(caps) if caps else None

    def contraindicated_conditions(self, drug: str) -> list[str]:
        d = self._drug(drug)
        if d is None:
            return []
        out = []
        renal = self.db.renal_profiles.get(d.id)
        below = L.renal_contraindicated_below(renal) if renal else None
        if below is not None:
            out.append(f"{renal.metric} < {below:g}")
        # No hepatic label rule is a contraindication for every route and indication (logic.HepaticLabelRule),
        # and the default convention's "avoid or specialist review" is no label statement: no Child-Pugh
        # class is a contraindicating condition.
        if L.pregnancy_assessment(self.db, d)["recommendation"] == "contraindicated":
            out.append("pregnancy")
        return out

    def label_pregnancy_contraindication(self, drug: str) -> str | None:
        """The US-label citation when the drug or its class is contraindicated in pregnancy (the
        fallback for drugs without a drugdose category, as `check_pregnancy_safety` reports), else None."""
        d = self._drug(drug)
        return L.label_pregnancy_contraindication(self.db, d) if d is not None else None
