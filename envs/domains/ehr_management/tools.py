"""EHR tools: timelines, lab and vital trends computed from timestamped events, SOFA / APACHE II /
NEWS2 computed from the record (worst values in a window, via `envs.calculators`), medication and
order management, notes and ICD-10-CM coding."""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Literal

from envs.calculators import calculate_apache2, calculate_news2, calculate_sofa
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool

from .data_model import EHRDB, Admission, EHRPatient, Escalation, MedicationOrder, Note, Order

VASOPRESSORS = ("norepinephrine", "epinephrine", "dopamine", "dobutamine")
FMT = "%Y-%m-%dT%H:%M"


def _t(text: str) -> datetime:
    try:
        return datetime.strptime(text[:16], FMT)
    except ValueError:
        raise ToolError(f"time {text!r} is not in the format YYYY-MM-DDTHH:MM") from None


def _icd():
    from envs.domains.clinical_diagnosis import knowledge

    return knowledge.icd10_index()


class EHRTools(BaseDomainTools):
    """Tools over an :class:`EHRDB`."""

    db: EHRDB

    # -- helpers ---------------------------------------------------------------------------------
    def _patient(self, patient_id: str) -> EHRPatient:
        p = self.db.patients.get(patient_id.strip())
        if p is None:
            raise ToolError(f"patient_id {patient_id!r} not found; e.g. {', '.join(sorted(self.db.patients)[:15])}")
        return p

    def _admission(self, p: EHRPatient, hadm_id: str | None) -> Admission:
        if not p.admissions:
            raise ToolError(f"patient {p.patient_id} has no admissions")
        if hadm_id is None:
            return max(p.admissions, key=lambda a: a.admit_time)
        for a in p.admissions:
            if a.hadm_id == hadm_id:
                return a
        raise ToolError(f"hadm_id {hadm_id!r} not found for {p.patient_id}; admissions: "
                        f"{', '.join(a.hadm_id for a in p.admissions)}")

    def _window(self, adm: Admission, start: str | None, hours: float) -> tuple[datetime, datetime]:
        if start is None:
            begin = _t(adm.icu_stays[0].intime) if adm.icu_stays else _t(adm.admit_time)
        else:
            begin = _t(start)
        if not 0 < hours <= 240:
            raise ToolError(f"window_hours must be in (0, 240], got {hours}")
        return begin, begin + timedelta(hours=hours)

    @staticmethod
    def _in(time: str, begin: datetime, end: datetime) -> bool:
        return begin <= _t(time) < end

    def _labs(self, adm: Admission, test: str, begin: datetime, end: datetime) -> list[float]:
        return [e.value for e in adm.lab_events if e.test == test and self._in(e.time, begin, end)]

    def _vitals(self, adm: Admission, field: str, begin: datetime, end: datetime) -> list[float]:
        return [getattr(v, field) for v in adm.vital_events
                if getattr(v, field) is not None and self._in(v.time, begin, end)]

    def _next_id(self, prefix: str) -> str:
        oid = f"{prefix}-{self.db.next_order_number:04d}"
        self.db.next_order_number += 1
        return oid

    # -- record reads ------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_timeline(self, patient_id: str) -> dict:
        """Return the patient's demographics, allergies, longitudinal conditions and admissions with ICU stays.

        Args:
            patient_id: The patient identifier, e.g. "EHR-001".
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "name": p.name, "age": p.age, "sex": p.sex, "weight_kg": p.weight_kg,
                "allergies": p.allergies, "source": p.source,
                "conditions": [c.model_dump(exclude_none=True) for c in sorted(p.conditions, key=lambda c: c.start)],
                "admissions": [{"hadm_id": a.hadm_id, "admit_time": a.admit_time, "discharge_time": a.discharge_time,
                                "admission_type": a.admission_type, "diagnosis": a.admission_diagnosis,
                                "icd10_codes": a.icd10_codes, "icu_stays": [s.model_dump() for s in a.icu_stays],
                                "n_lab_events": len(a.lab_events), "n_vital_events": len(a.vital_events)}
                               for a in sorted(p.admissions, key=lambda a: a.admit_time)]}

    @is_tool(ToolType.READ)
    def get_lab_events(self, patient_id: str, test: str | None = None, hadm_id: str | None = None) -> dict:
        """Return timestamped lab events of an admission (default: the latest), optionally one test.

        Args:
            patient_id: The patient identifier.
            test: Optional test name, e.g. "creatinine", "potassium", "lactate".
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        events = [e for e in adm.lab_events if test is None or e.test == test.strip().lower()]
        if test is not None and not events:
            raise ToolError(f"no {test!r} results in {adm.hadm_id}; tests: {', '.join(sorted({e.test for e in adm.lab_events}))}")
        return {"hadm_id": adm.hadm_id, "events": [e.model_dump() for e in sorted(events, key=lambda e: (e.time, e.test))]}

    @is_tool(ToolType.READ)
    def get_lab_trend(self, patient_id: str, test: str, hadm_id: str | None = None) -> dict:
        """Compute a lab test's trend over an admission: first, last, delta, min, max, and the least-squares slope per day.

        Args:
            patient_id: The patient identifier.
            test: The lab test, e.g. "creatinine".
            hadm_id: Optional admission id (default: the latest admission).
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        events = sorted((e for e in adm.lab_events if e.test == test.strip().lower()), key=lambda e: e.time)
        if len(events) < 2:
            raise ToolError(f"test {test!r} needs at least 2 results in {adm.hadm_id} for a trend (found {len(events)})")
        return {"hadm_id": adm.hadm_id, "test": events[0].test, "unit": events[0].unit, **trend([(e.time, e.value) for e in events])}

    @is_tool(ToolType.READ)
    def get_vital_trend(self, patient_id: str, vital: Literal["heart_rate", "systolic_bp", "diastolic_bp", "map_mmhg",
                                                              "respiratory_rate", "temperature_c", "spo2", "fio2", "gcs",
                                                              "urine_output_ml"],
                        hadm_id: str | None = None) -> dict:
        """Compute a charted vital sign's trend over an admission (first, last, delta, min, max, slope per day).

        Args:
            patient_id: The patient identifier.
            vital: The charted variable.
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        points = [(v.time, getattr(v, vital)) for v in sorted(adm.vital_events, key=lambda v: v.time)
                  if getattr(v, vital) is not None]
        if len(points) < 2:
            raise ToolError(f"{vital} has fewer than 2 charted values in {adm.hadm_id}")
        return {"hadm_id": adm.hadm_id, "vital": vital, **trend(points)}

    @is_tool(ToolType.READ)
    def get_medication_orders(self, patient_id: str, status: Literal["active", "discontinued", "completed", "all"] = "all",
                              hadm_id: str | None = None) -> dict:
        """Return the admission's medication orders (drug, dose, route, frequency, start/stop, status).

        Args:
            patient_id: The patient identifier.
            status: Filter by status, or "all".
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        rows = [m.model_dump() for m in adm.medication_orders if status == "all" or m.status == status]
        return {"hadm_id": adm.hadm_id, "medication_orders": rows, "other_orders": [o.model_dump() for o in adm.orders]}

    @is_tool(ToolType.READ)
    def summarize_admission(self, patient_id: str, hadm_id: str | None = None) -> dict:
        """Summarise an admission from the record: diagnosis, ICU days, ventilation and vasopressor hours, and
        each lab's first/last/worst values.

        Args:
            patient_id: The patient identifier.
            hadm_id: Optional admission id.
        """
        p = self._patient(patient_id)
        adm = self._admission(p, hadm_id)
        labs: dict[str, dict] = {}
        for test in sorted({e.test for e in adm.lab_events}):
            pts = sorted((e.time, e.value) for e in adm.lab_events if e.test == test)
            vals = [v for _, v in pts]
            labs[test] = {"first": vals[0], "last": vals[-1], "min": min(vals), "max": max(vals), "n": len(vals)}
        vent_h = sum(((_t(v.end) if v.end else _t(self.db.clock)) - _t(v.start)).total_seconds() / 3600 for v in adm.ventilation)
        pressor_h = sum(((_t(m.stop) if m.stop else _t(self.db.clock)) - _t(m.start)).total_seconds() / 3600
                        for m in adm.medication_orders if m.drug in VASOPRESSORS)
        return {"patient_id": p.patient_id, "hadm_id": adm.hadm_id, "diagnosis": adm.admission_diagnosis,
                "icd10_codes": adm.icd10_codes, "icu_stays": [s.model_dump() for s in adm.icu_stays],
                "ventilation_hours": round(vent_h, 1), "vasopressor_hours": round(pressor_h, 1),
                "active_medications": [m.drug for m in adm.medication_orders if m.status == "active"],
                "labs": labs, "notes": len(adm.notes), "escalations": [e.model_dump() for e in adm.escalations]}

    # -- scores from the record ------------------------------------------------------------------
    def _pressor(self, adm: Admission, drug: str, begin: datetime, end: datetime) -> float:
        doses = [m.dose for m in adm.medication_orders if m.drug == drug and m.dose_unit == "mcg/kg/min"
                 and _t(m.start) < end and (m.stop is None or _t(m.stop) > begin)]
        return max(doses, default=0.0)

    def _ventilated(self, adm: Admission, begin: datetime, end: datetime) -> bool:
        return any(_t(v.start) < end and (v.end is None or _t(v.end) > begin) for v in adm.ventilation)

    @is_tool(ToolType.READ)
    def calculate_sofa(self, patient_id: str, window_start: str | None = None, window_hours: float = 24.0,
                       hadm_id: str | None = None) -> dict:
        """SOFA score computed from the record: the worst value of each organ system in a time window
        (default: the first 24 h of the ICU stay). PaO2/FiO2 pairs each PaO2 with the FiO2 charted at or before it.

        Args:
            patient_id: The patient identifier.
            window_start: Window start "YYYY-MM-DDTHH:MM" (default: ICU admission time).
            window_hours: Window length in hours (default 24).
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        begin, end = self._window(adm, window_start, window_hours)
        ratios = []
        charted = sorted((v.time, v.fio2) for v in adm.vital_events if v.fio2 is not None)
        for e in adm.lab_events:
            if e.test == "pao2" and self._in(e.time, begin, end):
                fio2 = [f for t, f in charted if t <= e.time]
                ratios.append(e.value / (fio2[-1] if fio2 else 0.21))
        needed = {"pao2_fio2_ratio": ratios, "platelets": self._labs(adm, "platelets", begin, end),
                  "total_bilirubin": self._labs(adm, "total_bilirubin", begin, end),
                  "map_mmhg": self._vitals(adm, "map_mmhg", begin, end), "gcs": self._vitals(adm, "gcs", begin, end),
                  "creatinine": self._labs(adm, "creatinine", begin, end)}
        missing = [k for k, v in needed.items() if not v]
        if missing:
            raise ToolError(f"no {', '.join(missing)} recorded between {begin:%Y-%m-%dT%H:%M} and {end:%Y-%m-%dT%H:%M}")
        urine = self._vitals(adm, "urine_output_ml", begin, end)
        inputs = {"pao2_fio2_ratio": round(min(needed["pao2_fio2_ratio"]), 1),
                  "on_mechanical_ventilation": self._ventilated(adm, begin, end),
                  "platelets_k_per_ul": min(needed["platelets"]), "bilirubin_mg_dl": max(needed["total_bilirubin"]),
                  "map_mmhg": min(needed["map_mmhg"]), "gcs": int(min(needed["gcs"])),
                  "creatinine_mg_dl": max(needed["creatinine"]),
                  **{f"{d}_mcg_kg_min": self._pressor(adm, d, begin, end) for d in VASOPRESSORS},
                  "urine_output_ml_day": round(sum(urine) * 24 / window_hours, 0) if urine and window_hours >= 24 else None}
        result = calculate_sofa(**inputs)
        return {"hadm_id": adm.hadm_id, "window": [begin.strftime(FMT), end.strftime(FMT)], "inputs": inputs,
                **result.model_dump(mode="json")}

    @is_tool(ToolType.READ)
    def calculate_apache2(self, patient_id: str, hadm_id: str | None = None) -> dict:
        """APACHE II computed from the first 24 h of the ICU stay: for each variable the charted minimum or
        maximum that scores more points (the worst value), age, chronic health and admission type from the record.

        Args:
            patient_id: The patient identifier.
            hadm_id: Optional admission id.
        """
        p = self._patient(patient_id)
        adm = self._admission(p, hadm_id)
        begin, end = self._window(adm, None, 24.0)
        sources = {"temperature_c": self._vitals(adm, "temperature_c", begin, end),
                   "map_mmhg": self._vitals(adm, "map_mmhg", begin, end),
                   "heart_rate": self._vitals(adm, "heart_rate", begin, end),
                   "respiratory_rate": self._vitals(adm, "respiratory_rate", begin, end),
                   "sodium_mmol_l": self._labs(adm, "sodium", begin, end),
                   "potassium_mmol_l": self._labs(adm, "potassium", begin, end),
                   "creatinine_mg_dl": self._labs(adm, "creatinine", begin, end),
                   "hematocrit_percent": self._labs(adm, "hematocrit", begin, end),
                   "wbc_k_per_ul": self._labs(adm, "wbc", begin, end),
                   "arterial_ph": self._labs(adm, "ph_arterial", begin, end)}
        missing = [k for k, v in sources.items() if not v]
        pao2 = self._labs(adm, "pao2", begin, end)
        paco2 = self._labs(adm, "paco2", begin, end)
        fio2s = self._vitals(adm, "fio2", begin, end)
        gcs = self._vitals(adm, "gcs", begin, end)
        if missing or not pao2 or not fio2s or not gcs:
            raise ToolError(f"first-24-h record lacks {', '.join(missing + [x for x, v in (('pao2', pao2), ('fio2', fio2s), ('gcs', gcs)) if not v])}")
        fixed = {"fio2": max(fio2s), "pao2_mmhg": min(pao2), "paco2_mmhg": paco2[pao2.index(min(pao2))] if len(paco2) == len(pao2) else (paco2[0] if paco2 else None),
                 "gcs": int(min(gcs)), "age": p.age,
                 "acute_renal_failure": max(sources["creatinine_mg_dl"]) >= 1.5 and bool(self._vitals(adm, "urine_output_ml", begin, end))
                 and sum(self._vitals(adm, "urine_output_ml", begin, end)) < 410,
                 "severe_organ_insufficiency_or_immunocompromised": bool(adm.comorbidities.get("chronic_organ_insufficiency")
                                                                         or adm.comorbidities.get("immunocompromised")),
                 "admission_type": "nonoperative"}
        chosen = {k: (min(v) + max(v)) / 2 for k, v in sources.items()}  # provisional, replaced below
        for k, values in sources.items():
            chosen[k] = min(values)
        # Additive score: choose per variable the extreme (min or max) that scores more, holding the others.
        for k, values in sources.items():
            best_value, best_score = None, -1
            for candidate in (min(values), max(values)):
                score = calculate_apache2(**{**chosen, k: candidate}, **fixed).score
                if score > best_score:
                    best_value, best_score = candidate, score
            chosen[k] = best_value
        result = calculate_apache2(**chosen, **fixed)
        return {"hadm_id": adm.hadm_id, "window": [begin.strftime(FMT), end.strftime(FMT)],
                "inputs": {**chosen, **fixed}, **result.model_dump(mode="json")}

    @is_tool(ToolType.READ)
    def calculate_news2(self, patient_id: str, at_time: str | None = None, hadm_id: str | None = None) -> dict:
        """NEWS2 from the charted vital-sign set at (or last before) a time (default: the latest set);
        consciousness is taken as alert for GCS 15, new confusion for GCS 13-14, voice for 9-12, pain for 4-8, unresponsive below.

        Args:
            patient_id: The patient identifier.
            at_time: "YYYY-MM-DDTHH:MM" (default: the latest charted set).
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        rows = sorted(adm.vital_events, key=lambda v: v.time)
        if at_time is not None:
            _t(at_time)
            rows = [v for v in rows if v.time <= at_time]
        if not rows:
            raise ToolError("no charted vital signs at or before that time")
        v = rows[-1]
        if None in (v.respiratory_rate, v.spo2, v.temperature_c, v.systolic_bp, v.heart_rate, v.gcs):
            raise ToolError(f"the vital-sign set at {v.time} is incomplete")
        g = v.gcs
        cons = "alert" if g == 15 else "new_confusion" if g >= 13 else "voice" if g >= 9 else "pain" if g >= 4 else "unresponsive"
        on_o2 = v.fio2 is not None and v.fio2 > 0.21
        result = calculate_news2(v.respiratory_rate, v.spo2, on_o2, v.temperature_c, v.systolic_bp, v.heart_rate, cons)
        return {"hadm_id": adm.hadm_id, "charted_at": v.time, "consciousness": cons, "on_supplemental_oxygen": on_o2,
                **result.model_dump(mode="json")}

    # -- coding ------------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def lookup_icd10(self, query: str, max_results: int = 10) -> dict:
        """Look up ICD-10-CM by code (description, hierarchy, children) or by words (matching codes).

        Args:
            query: A code ("N17.9") or words ("acute kidney failure").
            max_results: Maximum matches for a text query, 1-50.
        """
        import re

        index = _icd()
        q = query.strip()
        if re.fullmatch(r"[A-Za-z]\d[0-9A-Za-z]\.?[0-9A-Za-z]{0,4}", q):
            item = index.get(q)
            if item is None:
                raise ToolError(f"ICD-10-CM code {q!r} does not exist")
            return item
        matches = index.search(q, max(1, min(max_results, 50)))
        if not matches:
            raise ToolError(f"no ICD-10-CM code matches all words of {q!r}")
        return {"query": q, "matches": matches}

    @is_tool(ToolType.WRITE)
    def assign_icd10_code(self, patient_id: str, icd10_code: str, hadm_id: str | None = None) -> dict:
        """Add a billable ICD-10-CM code to an admission's coded diagnoses.

        Args:
            patient_id: The patient identifier.
            icd10_code: A billable ICD-10-CM code.
            hadm_id: Optional admission id.
        """
        from envs.domains.clinical_diagnosis.icd10 import normalise_code

        adm = self._admission(self._patient(patient_id), hadm_id)
        code = normalise_code(icd10_code)
        item = _icd().get(code)
        if item is None:
            raise ToolError(f"icd10_code {icd10_code!r} does not exist")
        if not item["billable"]:
            raise ToolError(f"{code} is not billable; children: {', '.join(c['code'] for c in item['children'][:8])}")
        if code in adm.icd10_codes:
            raise ToolError(f"{code} is already coded on {adm.hadm_id}")
        adm.icd10_codes.append(code)
        return {"hadm_id": adm.hadm_id, "icd10_codes": adm.icd10_codes, "description": item["description"]}

    # -- orders and notes --------------------------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def place_order(self, patient_id: str, kind: Literal["lab", "imaging", "consult", "nursing", "diet", "procedure"],
                    description: str, priority: Literal["routine", "urgent", "stat"] = "routine",
                    hadm_id: str | None = None) -> dict:
        """Place a non-medication order (lab, imaging, consult, nursing, diet, procedure) on the admission.

        Args:
            patient_id: The patient identifier.
            kind: The order type.
            description: What is ordered, e.g. "basic metabolic panel in 6 hours".
            priority: routine, urgent or stat.
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        text = description.strip()
        if len(text) < 3:
            raise ToolError("description is empty")
        if any(o.description.lower() == text.lower() and o.status == "active" for o in adm.orders):
            raise ToolError(f"an identical active order exists on {adm.hadm_id}")
        order = Order(order_id=self._next_id("ORD"), kind=kind, description=text, time=self.db.clock, priority=priority)
        adm.orders.append(order)
        return order.model_dump()

    @is_tool(ToolType.WRITE)
    def order_medication(self, patient_id: str, drug: str, dose: float, dose_unit: str, route: str, frequency: str,
                         indication: str = "", hadm_id: str | None = None) -> dict:
        """Order a medication on the admission (checked against the patient's allergies).

        Args:
            patient_id: The patient identifier.
            drug: Drug name.
            dose: Dose amount.
            dose_unit: Unit, e.g. "mg", "mcg/kg/min", "units".
            route: Route, e.g. "oral", "iv".
            frequency: Frequency, e.g. "daily", "q8h", "continuous".
            indication: Reason for the order.
            hadm_id: Optional admission id.
        """
        p = self._patient(patient_id)
        adm = self._admission(p, hadm_id)
        name = " ".join(drug.strip().lower().split())
        if len(name) < 3:
            raise ToolError("drug is empty")
        from envs.domains.clinical_diagnosis.safety import drug_reference

        # The same drug reference the reward's safety context uses: same drug, its class or allergy group.
        allergy = drug_reference().allergy_conflict(p.allergies, name)
        if allergy is not None:
            raise ToolError(f"allergy: {p.patient_id} is allergic to {allergy}; {drug} is covered by that allergy "
                            f"and is not allowed")
        if dose <= 0:
            raise ToolError("dose must be positive")
        if any(m.drug == name and m.status == "active" for m in adm.medication_orders):
            raise ToolError(f"{name} already has an active order on {adm.hadm_id}")
        order = MedicationOrder(order_id=self._next_id("MED"), drug=name, dose=dose, dose_unit=dose_unit, route=route.lower(),
                                frequency=frequency, start=self.db.clock, indication=indication)
        adm.medication_orders.append(order)
        return order.model_dump()

    @is_tool(ToolType.READ)
    def check_drug_interactions(self, patient_id: str, drug: str, hadm_id: str | None = None) -> dict:
        """Check a proposed drug against the admission's active medication orders: ANSM interaction rules
        (severity and rule), same-class duplications, and a recorded allergy that covers it.

        Args:
            patient_id: The patient identifier.
            drug: The proposed drug (generic or brand name).
            hadm_id: Optional admission id (default: the latest admission).
        """
        from envs.domains.clinical_diagnosis.safety import drug_reference

        p = self._patient(patient_id)
        adm = self._admission(p, hadm_id)
        if len(drug.strip()) < 3:
            raise ToolError("drug is empty")
        reference = drug_reference()
        report = reference.interaction_report(drug, [m.drug for m in adm.medication_orders if m.status == "active"])
        out = {"patient_id": p.patient_id, "hadm_id": adm.hadm_id, **report}
        allergy = reference.allergy_conflict(p.allergies, drug)
        if allergy is not None:  # present only when a recorded allergy covers the drug
            out["allergy_conflict"] = f"{p.patient_id} is allergic to {allergy}"
        return out

    @is_tool(ToolType.WRITE)
    def discontinue_order(self, patient_id: str, order_id: str, reason: str, hadm_id: str | None = None) -> dict:
        """Discontinue an active medication or other order (stop time = now).

        Args:
            patient_id: The patient identifier.
            order_id: The order id (from get_medication_orders).
            reason: Why it is stopped.
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        for m in adm.medication_orders:
            if m.order_id == order_id:
                if m.status != "active":
                    raise ToolError(f"order {order_id} is {m.status}, not active")
                m.status, m.stop = "discontinued", self.db.clock
                return {"order_id": order_id, "drug": m.drug, "status": "discontinued", "reason": reason}
        for o in adm.orders:
            if o.order_id == order_id:
                if o.status != "active":
                    raise ToolError(f"order {order_id} is {o.status}, not active")
                o.status = "discontinued"
                return {"order_id": order_id, "description": o.description, "status": "discontinued", "reason": reason}
        raise ToolError(f"order_id {order_id!r} not found on {adm.hadm_id}")

    @is_tool(ToolType.WRITE)
    def write_clinical_note(self, patient_id: str, note_type: Literal["progress", "event", "transfer", "discharge", "consult"],
                            text: str, hadm_id: str | None = None) -> dict:
        """Write a note into the admission's record.

        Args:
            patient_id: The patient identifier.
            note_type: progress, event, transfer, discharge or consult.
            text: The note text.
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        if len(text.strip()) < 20:
            raise ToolError("text is too short for a note (at least 20 characters)")
        note = Note(note_id=f"{adm.hadm_id}-N{len(adm.notes) + 1}", time=self.db.clock, note_type=note_type, text=text.strip())
        adm.notes.append(note)
        return {"note_id": note.note_id, "note_type": note_type}

    @is_tool(ToolType.WRITE)
    def escalate_care(self, patient_id: str, team: Literal["critical_care_outreach", "rapid_response", "icu_attending",
                                                           "nephrology", "gastroenterology", "cardiology",
                                                           "cardiac_surgery", "general_surgery", "neurology",
                                                           "endocrinology", "infectious_diseases"],
                      reason: str, hadm_id: str | None = None) -> dict:
        """Escalate now: call a senior or specialist team to the bedside for an emergency (recorded on the admission).

        Args:
            patient_id: The patient identifier.
            team: The team called.
            reason: The emergency and what is needed, e.g. "K 6.8 with AKI: urgent dialysis review".
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        text = " ".join(reason.split())
        if len(text) < 10:
            raise ToolError("reason must state the emergency and what is needed (at least 10 characters)")
        escalation = Escalation(time=self.db.clock, team=team, reason=text)
        adm.escalations.append(escalation)
        return {"hadm_id": adm.hadm_id, **escalation.model_dump(), "escalations_this_admission": len(adm.escalations)}

    @is_tool(ToolType.READ)
    def get_clinical_notes(self, patient_id: str, hadm_id: str | None = None) -> dict:
        """Return the admission's notes in time order.

        Args:
            patient_id: The patient identifier.
            hadm_id: Optional admission id.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        return {"hadm_id": adm.hadm_id, "notes": [n.model_dump() for n in sorted(adm.notes, key=lambda n: n.time)]}


def trend(points: list[tuple[str, float]]) -> dict:
    """first/last/delta/min/max/percent change and the least-squares slope per day of (time, value) points."""
    times = [_t(t) for t, _ in points]
    values = [float(v) for _, v in points]
    days = [(t - times[0]).total_seconds() / 86400 for t in times]
    n = len(values)
    mx, my = sum(days) / n, sum(values) / n
    sxx = sum((d - mx) ** 2 for d in days)
    slope = sum((d - mx) * (v - my) for d, v in zip(days, values)) / sxx if sxx else 0.0
    first, last = values[0], values[-1]
    direction = "rising" if slope > 0 and abs(last - first) > 0.1 * max(abs(first), 1e-9) else \
        "falling" if slope < 0 and abs(last - first) > 0.1 * max(abs(first), 1e-9) else "stable"
    return {"n": n, "first": first, "first_time": points[0][0], "last": last, "last_time": points[-1][0],
            "delta": round(last - first, 4), "percent_change": round(100 * (last - first) / first, 1) if first else None,
            "min": min(values), "max": max(values), "slope_per_day": round(slope, 4), "direction": direction}
