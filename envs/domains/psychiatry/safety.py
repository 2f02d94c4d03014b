"""What the safety reward needs to know about the psychiatry world: the patients' medications and
allergies, drug names and classes from the formulary, and interactions graded as the tool grades them
(`interactions.pair_findings`: the drug_interaction domain's level where it grades the pair)."""

from __future__ import annotations

from typing import Callable

from envs.rewards.safety import BaseSafetyContext

from . import interactions as IX
from .data_model import PsychiatryDB

# Rule groups -> the class names the reward's duplication check understands.
GROUP_CLASSES = {"ssri": "ssris", "snri": "snris", "maoi": "maois", "benzodiazepine": "benzodiazepines", "opioid": "opioids",
                 "nsaid": "nsaids", "ace_inhibitor": "ace inhibitors", "arb": "arbs", "antipsychotic": "antipsychotics",
                 "tca": "tricyclic antidepressants", "lithium": "lithium"}
SEVERITY_ORDER = IX.SEVERITY_ORDER


class PsychiatrySafetyContext(BaseSafetyContext):
    use_builtin_fallback = True

    def __init__(self, db: Callable[[], PsychiatryDB]) -> None:
        self._db = db

    def _patient(self, patient_id: str):
        return self._db().patients.get((patient_id or "").strip().upper())

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return list(p.allergies) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return [m.name for m in p.medications] if p else []

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        out = list(p.history.diagnoses)
        if p.pregnant:
            out.append("pregnancy")
        return out

    def normalise_drug(self, name: str) -> str | None:
        key = " ".join(str(name).lower().split())
        for drug, rec in self._db().formulary.items():
            if key == drug or key in {b.lower() for b in rec.brands}:
                return drug
        return None

    def drug_classes(self, drug: str) -> list[str]:
        rec = self._db().formulary.get(self.normalise_drug(drug) or "")
        if rec is None:
            return []
        return [GROUP_CLASSES[g] for g in rec.groups if g in GROUP_CLASSES] + [c.lower() for c in rec.fda_classes]

    def interaction(self, drug_a: str, drug_b: str) -> tuple[str, str] | None:
        db = self._db()
        a, b = self.normalise_drug(drug_a), self.normalise_drug(drug_b)
        if not a or not b or a == b:
            return None
        groups = {a: db.formulary[a].groups, b: db.formulary[b].groups}
        findings = IX.pair_findings(a, b, groups, db.interaction_rules, IX.label_index(db.label_graded_pairs))
        if not findings:
            return None
        worst = max(findings, key=lambda f: SEVERITY_ORDER[f["severity"]])
        return worst["severity"], f"{worst['rule']} {worst['name']}: {worst['mechanism']}"
