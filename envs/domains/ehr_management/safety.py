"""`SafetyContext` of the EHR domain: allergies, the active medication orders of the current
admission, the active longitudinal conditions and the renal function from the latest creatinine;
drug facts from the shared drug reference (`envs/domains/clinical_diagnosis/safety.py`: the
authored formulary, then the drug-interaction database, then the reward's lexicon)."""

from __future__ import annotations

from envs.domains.clinical_diagnosis.safety import RecordSafetyContext, pregnant_in, renal_conditions


class EHRSafetyContext(RecordSafetyContext):
    def _patient(self, patient_id: str):
        if not patient_id:
            return None
        db = self.db
        return db.patients.get(str(patient_id).strip())

    @staticmethod
    def _current(p):
        return max(p.admissions, key=lambda a: a.admit_time) if p.admissions else None

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return self._expand_allergies(p.allergies) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        adm = self._current(p) if p else None
        return [m.drug for m in adm.medication_orders if m.status == "active"] if adm else []

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        active = [c.name for c in p.conditions if c.end is None]
        out = [c.lower() for c in active]
        adm = self._current(p)
        if adm is not None:
            out.append(adm.admission_diagnosis.lower())
            creatinine = sorted((e.time, e.value) for e in adm.lab_events if e.test == "creatinine")
            if creatinine:
                out += renal_conditions(self.reference, creatinine[-1][1], p.age, p.sex, p.weight_kg)
        if pregnant_in(active):
            out.append("pregnancy")
        return list(dict.fromkeys(out))
