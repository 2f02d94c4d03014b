"""`SafetyContext` of the EHR domain: allergies, the active medication orders of the current
admission, the active longitudinal conditions and the renal function from the latest creatinine;
drug facts from the shared drug reference (`envs/domains/drug_reference.py`: the
authored formulary, then the drug-interaction database, then the reward's lexicon)."""

from __future__ import annotations

from typing import Any, Callable

from envs.domains.drug_reference import DrugReference, RecordSafetyContext, pregnant_in, renal_conditions


class EHRSafetyContext(RecordSafetyContext):
    """`lookup(patient_id)` returns the chart as the episode sees it (`EHRTools.chart`: the episode's copy,
    else the built record), or None."""

    def __init__(self, lookup: Callable[[str], Any], reference: DrugReference | None = None) -> None:
        super().__init__(lambda: None, reference)
        self._lookup = lookup

    def _patient(self, patient_id: str):
        return self._lookup(str(patient_id).strip()) if patient_id else None

    @staticmethod
    def _current(p):
        return max(p.admissions, key=lambda a: a.admit_time) if p.admissions else None

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return self._expand_allergies(p.allergies) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        """The current admission's active orders; for a longitudinal record without admissions, the drug
        exposures active on the record's last date."""
        p = self._patient(patient_id)
        if p is None:
            return []
        adm = self._current(p)
        if adm is not None:
            return [m.drug for m in adm.medication_orders if m.status == "active"]
        end = p.record_end or ""
        return list(dict.fromkeys(x.name for x in p.drug_exposures
                                  if x.vocabulary != "CVX" and x.start[:10] <= end[:10] <= (x.end or x.start)[:10]))

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
