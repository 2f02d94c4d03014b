"""`SafetyContext` of the triage domain: the ED patients' allergies, home medications and the
medications given at triage, and their history; drug facts from the shared drug reference
(`envs/domains/drug_reference.py`: the authored formulary, then the drug-interaction
database, then the reward's lexicon)."""

from __future__ import annotations

from envs.domains.drug_reference import RecordSafetyContext, pregnant_in


class TriageSafetyContext(RecordSafetyContext):
    def _patient(self, patient_id: str):
        return self.db.patients.get(str(patient_id).strip()) if patient_id else None

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return self._expand_allergies(p.allergies) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        return list(dict.fromkeys([*p.medications, *(m.drug for m in p.medications_given)]))

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        out = [c.lower() for c in p.medical_history]
        if pregnant_in([*p.medical_history, p.chief_complaint, p.history]):
            out.append("pregnancy")
        return list(dict.fromkeys(out))
