"""`SafetyContext` of the clinical_diagnosis domain for the reward's violation detector, answered from
the episode's database; drug facts from the shared drug reference (`envs/domains/drug_reference.py`:
the authored formulary, then the drug-interaction database, then the reward's lexicon)."""

from __future__ import annotations

from envs.domains.drug_reference import RecordSafetyContext, pregnant_in, renal_conditions


class ClinicalDiagnosisSafetyContext(RecordSafetyContext):
    """Allergies, home medications and prescriptions, problem list and renal function of the clinic patients."""

    def _patient(self, patient_id: str):
        return self.db.patients.get(str(patient_id).strip()) if patient_id else None

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return self._expand_allergies([a.substance for a in p.allergies]) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        return list(dict.fromkeys([m.name for m in p.medications] + [x.drug for x in p.prescriptions]))

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        out = [c.lower() for c in p.past_medical_history]
        if pregnant_in([*p.past_medical_history, p.history_of_present_illness, p.chief_complaint]):
            out.append("pregnancy")
        creatinine = [r for r in sorted(p.lab_results, key=lambda r: r.time)
                      if r.test == "creatinine" and isinstance(r.value, (int, float))]
        if creatinine:
            out += renal_conditions(self.reference, float(creatinine[-1].value), p.age, p.sex, p.weight_kg)
        return list(dict.fromkeys(out))
