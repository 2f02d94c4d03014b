"""What the safety reward needs to know about the obstetrics world: allergies, medications, the
pregnancy itself as a condition, and maximum single doses from the obstetric formulary."""

from __future__ import annotations

from typing import Callable

from envs.rewards.safety import BaseSafetyContext

from .data_model import ObstetricsDB


class ObstetricsSafetyContext(BaseSafetyContext):
    use_builtin_fallback = True

    def __init__(self, db: Callable[[], ObstetricsDB]) -> None:
        self._db = db

    def _patient(self, patient_id: str):
        return self._db().patients.get((patient_id or "").strip().upper())

    def patient_allergies(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return list(p.allergies) if p else []

    def patient_medications(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        return list(p.medications) if p else []

    def patient_conditions(self, patient_id: str) -> list[str]:
        p = self._patient(patient_id)
        if p is None:
            return []
        out = ["pregnancy"] if not p.newborn else ["postpartum"]
        if p.chronic_hypertension:
            out.append("chronic hypertension")
        return out + [c.lower() for c in p.conditions]

    def contraindicated_conditions(self, drug: str) -> list[str]:
        key = self.normalise_drug(drug)
        rec = self._db().formulary.get(key.replace(" ", "_")) if key else None
        return [c.lower() for c in rec.contraindications] if rec else []

    def normalise_drug(self, name: str) -> str | None:
        key = " ".join(str(name).lower().replace("_", " ").split())
        for drug_key, rec in self._db().formulary.items():
            if key in (drug_key.replace("_", " "), rec.name.lower()) or rec.name.lower().startswith(key + " "):
                return drug_key.replace("_", " ")
        return None

    def max_dose_mg(self, drug: str, route: str | None = None) -> float | None:
        key = self.normalise_drug(drug)
        rec = self._db().formulary.get(key.replace(" ", "_")) if key else None
        if rec is None or (route and route.upper() not in rec.routes):
            return None
        return rec.max_single_dose_mg

    def interaction(self, drug_a: str, drug_b: str) -> tuple[str, str] | None:
        a, b = self.normalise_drug(drug_a), self.normalise_drug(drug_b)
        if not a or not b or a == b:
            return None
        pair = {a.replace(" ", "_"), b.replace(" ", "_")}
        for inter in self._db().interactions:
            if set(inter.drugs) == pair:
                return inter.severity, inter.effect
        return None
