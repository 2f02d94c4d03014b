"""EHR tools: timelines, lab and vital trends computed from timestamped events, SOFA / APACHE II /
NEWS2 computed from the record (worst values in a window, via `envs.calculators`), medication and
order management, notes and ICD-10-CM coding."""

from __future__ import annotations

from datetime import date, datetime, timedelta
from typing import TYPE_CHECKING, Literal

from envs.calculators import calculate_apache2, calculate_news2, calculate_sofa
from envs.core.common_tools import BaseDomainTools
from envs.core.icd10 import built_icd10_index, normalise_code
from envs.core.tools import ToolError, ToolType, is_tool

from .data_model import EHRDB, Admission, EHRPatient, Escalation, MedicationOrder, Note, Order

if TYPE_CHECKING:
    from .store import PatientStore

VASOPRESSORS = ("norepinephrine", "epinephrine", "dopamine", "dobutamine")
FMT = "%Y-%m-%dT%H:%M"


def _t(text: str) -> datetime:
    # seconds are kept when the record has them (imported MIMIC-III ICU times: LOS from the full timestamps)
    try:
        return datetime.strptime(text[:19], FMT + ":%S")
    except ValueError:
        pass
    try:
        return datetime.strptime(text[:16], FMT)
    except ValueError:
        raise ToolError(f"time {text!r} is not in the format YYYY-MM-DDTHH:MM") from None


def _icd():
    # clinical_diagnosis's built index: a declared built-data dependency (build.py BUILD_REQUIRES).
    return built_icd10_index("clinical_diagnosis")


class EHRTools(BaseDomainTools):
    """Tools over an :class:`EHRDB`.

    The episode database holds the charts under care: the task's patient (opened on reset) and any
    chart the agent writes to. Other patients of the built database are read from the `store`
    without entering the episode state, so reading a chart never changes the database hash.
    """

    db: EHRDB

    def __init__(self, db: EHRDB, store: "PatientStore | None" = None) -> None:
        super().__init__(db)
        self.store = store
        self._read_only: dict[str, EHRPatient] = {}

    # -- helpers ---------------------------------------------------------------------------------
    def chart(self, patient_id: str) -> EHRPatient | None:
        """The patient's chart: the episode's copy, else a read-only copy from the store, else None."""
        pid = str(patient_id).strip()
        p = self.db.patients.get(pid)
        if p is None and self.store is not None and pid in self.store:
            p = self._read_only.get(pid)
            if p is None:
                p = self._read_only[pid] = self.store.load(pid)
        return p

    def _patient(self, patient_id: str, write: bool = False) -> EHRPatient:
        pid = patient_id.strip()
        p = self.db.patients.get(pid)
        if p is not None:
            return p
        if self.store is not None and pid in self.store:
            if not write:
                return self.chart(pid)  # type: ignore[return-value]
            p = self.db.patients[pid] = self.store.load(pid)  # writing opens the chart in the episode
            self._read_only.pop(pid, None)
            return p
        known = sorted(self.db.patients) or (self.store.ids() if self.store is not None else [])
        raise ToolError(f"patient_id {patient_id!r} not found; e.g. {', '.join(known[:15])}")

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
        """Return the patient's demographics, allergies, the size of the longitudinal record, active conditions and
        the admissions with ICU stays.

        Args:
            patient_id: The patient identifier, e.g. "EHR-001".
        """
        p = self._patient(patient_id)
        longitudinal = {"condition_occurrences": len(p.conditions), "drug_exposures": len(p.drug_exposures),
                        "procedures": len(p.procedures), "inpatient_visits": len(p.visits),
                        "measurements": len(p.measurements), "observations": len(p.observations)}
        active = [c for c in p.conditions if c.end is None]
        return {"patient_id": p.patient_id, "name": p.name, "age": p.age, "sex": p.sex, "weight_kg": p.weight_kg,
                "birth_date": p.birth_date, "record_span": [p.record_start, p.record_end],
                "allergies": p.allergies, "source": p.source, "longitudinal_record": longitudinal,
                "active_conditions": sorted({c.name for c in active}),
                "conditions": ([c.model_dump(exclude_none=True, include={"start", "end", "name", "code"})
                                for c in sorted(p.conditions, key=lambda c: c.start)] if len(p.conditions) <= 20
                               else "more than 20 condition occurrences: use get_condition_history"),
                "admissions": [{"hadm_id": a.hadm_id, "admit_time": a.admit_time, "discharge_time": a.discharge_time,
                                "admission_type": a.admission_type, "diagnosis": a.admission_diagnosis,
                                "icd10_codes": a.icd10_codes, "icu_stays": [s.model_dump() for s in a.icu_stays],
                                "n_lab_events": len(a.lab_events), "n_vital_events": len(a.vital_events)}
                               for a in sorted(p.admissions, key=lambda a: a.admit_time)]}

    def _stay_window(self, adm: Admission, stay_id: str | None) -> tuple[str, str]:
        """The [intime, outtime] of an ICU stay of the admission as "YYYY-MM-DDTHH:MM" strings (whole range when None)."""
        if stay_id is None:
            return "0000", "9999"
        for stay in adm.icu_stays:
            if stay.stay_id == str(stay_id).strip():
                return stay.intime[:16], (stay.outtime or "9999")[:16]
        raise ToolError(f"stay_id {stay_id!r} is not an ICU stay of {adm.hadm_id}; stays: "
                        f"{', '.join(s.stay_id for s in adm.icu_stays) or 'none'}")

    @is_tool(ToolType.READ)
    def get_lab_events(self, patient_id: str, test: str | None = None, hadm_id: str | None = None,
                       stay_id: str | None = None) -> dict:
        """Return timestamped lab events of an admission (default: the latest), optionally one test, optionally only
        those charted during one ICU stay (intime to outtime, inclusive).

        Args:
            patient_id: The patient identifier.
            test: Optional test name, e.g. "creatinine", "potassium", "lactate".
            hadm_id: Optional admission id.
            stay_id: Optional ICU stay id of that admission.
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        begin, end = self._stay_window(adm, stay_id)
        events = [e for e in adm.lab_events if (test is None or e.test == test.strip().lower())
                  and begin <= e.time[:16] <= end]
        if test is not None and not events:
            where = f"ICU stay {stay_id} of {adm.hadm_id}" if stay_id else adm.hadm_id
            raise ToolError(f"no {test!r} results in {where}; tests: {', '.join(sorted({e.test for e in adm.lab_events}))}")
        return {"hadm_id": adm.hadm_id, "stay_id": stay_id,
                "events": [e.model_dump(exclude_none=True) for e in sorted(events, key=lambda e: (e.time, e.test))]}

    @is_tool(ToolType.READ)
    def get_lab_trend(self, patient_id: str, test: str, hadm_id: str | None = None, stay_id: str | None = None) -> dict:
        """Compute a lab test's trend over an admission, or over one ICU stay: first, last, delta, min, max, and the
        least-squares slope per day.

        Args:
            patient_id: The patient identifier.
            test: The lab test, e.g. "creatinine".
            hadm_id: Optional admission id (default: the latest admission).
            stay_id: Optional ICU stay id: only results charted during that stay (intime to outtime, inclusive).
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        begin, end = self._stay_window(adm, stay_id)
        events = sorted((e for e in adm.lab_events if e.test == test.strip().lower() and begin <= e.time[:16] <= end),
                        key=lambda e: e.time)
        if len(events) < 2:
            where = f"ICU stay {stay_id} of {adm.hadm_id}" if stay_id else adm.hadm_id
            raise ToolError(f"test {test!r} needs at least 2 results in {where} for a trend (found {len(events)})")
        out = {"hadm_id": adm.hadm_id, "test": events[0].test, "unit": events[0].unit,
               **trend([(e.time, e.value) for e in events])}
        if stay_id is not None:
            out["stay_id"] = stay_id
        return out

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
        """Summarise an admission from the record: diagnosis, hospital and ICU lengths of stay (days, from the
        admission/discharge and ICU in/out times), ventilation and vasopressor hours, and each lab's first/last/worst values.

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
        stays = [{**s.model_dump(), "los_days": round((_t(s.outtime) - _t(s.intime)).total_seconds() / 86400, 4)
                  if s.outtime else None} for s in adm.icu_stays]
        hospital_los = (round((_t(adm.discharge_time) - _t(adm.admit_time)).total_seconds() / 86400, 4)
                        if adm.discharge_time else None)
        return {"patient_id": p.patient_id, "hadm_id": adm.hadm_id, "diagnosis": adm.admission_diagnosis,
                "admit_time": adm.admit_time, "discharge_time": adm.discharge_time, "hospital_los_days": hospital_los,
                "icd10_codes": adm.icd10_codes, "icu_stays": stays,
                "ventilation_hours": round(vent_h, 1), "vasopressor_hours": round(pressor_h, 1),
                "active_medications": [m.drug for m in adm.medication_orders if m.status == "active"],
                "labs": labs, "notes": len(adm.notes), "escalations": [e.model_dump() for e in adm.escalations]}

    @is_tool(ToolType.READ)
    def get_admission_diagnoses(self, patient_id: str, hadm_id: str | None = None) -> dict:
        """Return the admission's coded diagnoses in sequence (sequence 1 / "primary" is the principal diagnosis), with
        the code system (ICD-9-CM or ICD-10-CM), titles, and the ICD-10-CM codes assigned in this record.

        Args:
            patient_id: The patient identifier.
            hadm_id: Optional admission id (default: the latest admission).
        """
        adm = self._admission(self._patient(patient_id), hadm_id)
        coded = sorted(adm.coded_diagnoses, key=lambda d: d.seq)  # stable: a row's codes keep their order
        primary = [d for d in coded if d.primary] or coded[:1]
        return {"patient_id": patient_id.strip(), "hadm_id": adm.hadm_id, "admission_diagnosis": adm.admission_diagnosis,
                "primary": primary[0].model_dump(exclude_none=True) if primary else None,
                "diagnoses": [d.model_dump(exclude_none=True) for d in coded],
                "assigned_icd10_codes": adm.icd10_codes}

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
        A set charted on invasive ventilation is refused: NEWS2 does not apply to a ventilated patient (use calculate_sofa).

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
        # NEWS2 (RCP 2017) scores spontaneous breathing, SpO2 on air or oxygen and ACVPU; on a ventilator the
        # rate is the machine's and the verbal response is not testable, so there is no NEWS2 to give.
        if any(w.mode == "invasive" and w.start <= v.time and (w.end is None or v.time < w.end) for w in adm.ventilation):
            raise ToolError(f"the vital-sign set at {v.time} was charted on invasive ventilation; NEWS2 does not apply to a "
                            "ventilated patient (use calculate_sofa)")
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
        adm = self._admission(self._patient(patient_id, write=True), hadm_id)
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
        adm = self._admission(self._patient(patient_id, write=True), hadm_id)
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
        p = self._patient(patient_id, write=True)
        adm = self._admission(p, hadm_id)
        name = " ".join(drug.strip().lower().split())
        if len(name) < 3:
            raise ToolError("drug is empty")
        from envs.domains.drug_reference import drug_reference

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
        from envs.domains.drug_reference import drug_reference

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
        adm = self._admission(self._patient(patient_id, write=True), hadm_id)
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
        adm = self._admission(self._patient(patient_id, write=True), hadm_id)
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
        adm = self._admission(self._patient(patient_id, write=True), hadm_id)
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


    # -- longitudinal record (conditions, drug exposures, procedures, visits, measurements) ----------------
    @staticmethod
    def _date(value: str, field: str) -> str:
        text = str(value).strip()[:10]
        try:
            return date.fromisoformat(text).isoformat()
        except ValueError:
            raise ToolError(f"{field} {value!r} is not a date in the format YYYY-MM-DD") from None

    def _span(self, start_date: str | None, end_date: str | None) -> tuple[str, str]:
        start = self._date(start_date, "start_date") if start_date else "0001-01-01"
        end = self._date(end_date, "end_date") if end_date else "9999-12-31"
        if start > end:
            raise ToolError(f"start_date {start} is after end_date {end}")
        return start, end

    @is_tool(ToolType.READ)
    def get_condition_history(self, patient_id: str, start_date: str | None = None, end_date: str | None = None) -> dict:
        """Return the condition occurrences whose onset (start date) lies in a window, inclusive, and a per-condition
        summary: code and vocabulary, first and last onset, number of occurrences, whether one is still active.

        Args:
            patient_id: The patient identifier, e.g. "SYN-000123".
            start_date: Window start "YYYY-MM-DD" (default: the start of the record).
            end_date: Window end "YYYY-MM-DD", inclusive (default: the end of the record).
        """
        p = self._patient(patient_id)
        start, end = self._span(start_date, end_date)
        rows = [c for c in p.conditions if start <= c.start[:10] <= end]
        summary: dict[str, dict] = {}
        for c in rows:
            key = str(c.concept_id) if c.concept_id is not None else c.name.lower()
            item = summary.setdefault(key, {"name": c.name, "code": c.code, "vocabulary": c.vocabulary,
                                            "first_onset": c.start[:10], "last_onset": c.start[:10],
                                            "occurrences": 0, "active": False})
            item["occurrences"] += 1
            item["first_onset"] = min(item["first_onset"], c.start[:10])
            item["last_onset"] = max(item["last_onset"], c.start[:10])
            item["active"] = item["active"] or c.end is None
        return {"patient_id": p.patient_id, "window": [start_date, end_date], "n_occurrences": len(rows),
                "distinct_conditions": len(summary),
                "conditions": sorted(summary.values(), key=lambda i: (i["first_onset"], i["name"])),
                "occurrences": [c.model_dump(include={"start", "end", "name", "code"}) for c in rows]}

    @staticmethod
    def _ingredients(x) -> list[str]:
        return x.ingredients or [x.name.lower()]

    @is_tool(ToolType.READ)
    def get_medications_on_date(self, patient_id: str, date: str) -> dict:
        """Return the drug exposures active on a date (start <= date <= end, vaccines excluded), their distinct
        RxNorm ingredients, and the vaccines given that day.

        Args:
            patient_id: The patient identifier.
            date: The date "YYYY-MM-DD".
        """
        p = self._patient(patient_id)
        day = self._date(date, "date")
        active = [x for x in p.drug_exposures if x.vocabulary != "CVX" and x.start[:10] <= day <= (x.end or x.start)[:10]]
        vaccines = [x.name for x in p.drug_exposures if x.vocabulary == "CVX" and x.start[:10] == day]
        ingredients = sorted({i for x in active for i in self._ingredients(x)})
        return {"patient_id": p.patient_id, "date": day, "n_active_ingredients": len(ingredients),
                "active_ingredients": ingredients,
                "active_exposures": [x.model_dump(include={"start", "end", "name", "ingredients", "days_supply"})
                                     for x in active],
                "vaccines_given": vaccines}

    @is_tool(ToolType.READ)
    def get_drug_exposures(self, patient_id: str, start_date: str | None = None, end_date: str | None = None,
                           ingredient: str | None = None) -> dict:
        """Return the drug exposures (dispensings, administrations, vaccinations) starting in a window, inclusive,
        optionally only those containing one ingredient, with their count and total days supply.

        Args:
            patient_id: The patient identifier.
            start_date: Window start "YYYY-MM-DD" (default: the start of the record).
            end_date: Window end "YYYY-MM-DD", inclusive (default: the end of the record).
            ingredient: Optional ingredient or drug name, e.g. "amoxicillin", "acetaminophen".
        """
        p = self._patient(patient_id)
        start, end = self._span(start_date, end_date)
        wanted = " ".join(ingredient.lower().split()) if ingredient else None

        def has(x) -> bool:
            return wanted is None or wanted in self._ingredients(x) or wanted in x.name.lower()

        if wanted and not any(has(x) for x in p.drug_exposures):
            known = sorted({i for x in p.drug_exposures for i in self._ingredients(x) if x.vocabulary != "CVX"})
            raise ToolError(f"no exposure to {ingredient!r} in {p.patient_id}'s record; ingredients: {', '.join(known[:25])}")
        rows = [x for x in p.drug_exposures if start <= x.start[:10] <= end and has(x)]
        return {"patient_id": p.patient_id, "window": [start_date, end_date], "ingredient": wanted,
                "n_exposures": len(rows), "total_days_supply": sum(x.days_supply or 0 for x in rows),
                "exposures": [x.model_dump(include={"start", "end", "name", "vocabulary", "ingredients", "days_supply"})
                              for x in rows]}

    @is_tool(ToolType.READ)
    def get_visit_history(self, patient_id: str, start_date: str | None = None, end_date: str | None = None) -> dict:
        """Return the inpatient visits starting in a window, inclusive, with each length of stay (days between
        admission and discharge date) and the total.

        Args:
            patient_id: The patient identifier.
            start_date: Window start "YYYY-MM-DD" (default: the start of the record).
            end_date: Window end "YYYY-MM-DD", inclusive (default: the end of the record).
        """
        p = self._patient(patient_id)
        start, end = self._span(start_date, end_date)
        rows = []
        for v in p.visits:
            if start <= v.start[:10] <= end:
                los = (date.fromisoformat((v.end or v.start)[:10]) - date.fromisoformat(v.start[:10])).days
                linked = sorted({c.name for c in p.conditions if c.visit_id == v.visit_id})
                rows.append({"visit_id": v.visit_id, "start": v.start, "end": v.end, "visit_type": v.visit_type,
                             "length_of_stay_days": los, "conditions": linked})
        return {"patient_id": p.patient_id, "window": [start_date, end_date], "n_visits": len(rows),
                "total_inpatient_days": sum(r["length_of_stay_days"] for r in rows), "visits": rows}

    @is_tool(ToolType.READ)
    def get_procedure_history(self, patient_id: str, start_date: str | None = None, end_date: str | None = None,
                              procedure: str | None = None) -> dict:
        """Return the procedures performed in a window, inclusive, optionally only those whose name contains a text,
        with their count and the first and most recent dates.

        Args:
            patient_id: The patient identifier.
            start_date: Window start "YYYY-MM-DD" (default: the start of the record).
            end_date: Window end "YYYY-MM-DD", inclusive (default: the end of the record).
            procedure: Optional text of the procedure name, e.g. "chest x-ray", "cardioversion".
        """
        p = self._patient(patient_id)
        start, end = self._span(start_date, end_date)
        wanted = " ".join(procedure.lower().split()) if procedure else None
        if wanted and not any(wanted in x.name.lower() for x in p.procedures):
            known = sorted({x.name for x in p.procedures})
            raise ToolError(f"no procedure matching {procedure!r} in {p.patient_id}'s record; procedures: "
                            f"{', '.join(known[:25]) or 'none'}")
        rows = [x for x in p.procedures if start <= x.date[:10] <= end and (wanted is None or wanted in x.name.lower())]
        return {"patient_id": p.patient_id, "window": [start_date, end_date], "procedure": wanted,
                "n_procedures": len(rows), "first": rows[0].date if rows else None,
                "most_recent": max((x.date for x in rows), default=None),
                "procedures": [x.model_dump(include={"date", "name", "code", "vocabulary"}) for x in rows]}

    @is_tool(ToolType.READ)
    def get_measurement_history(self, patient_id: str, measurement: str | None = None, start_date: str | None = None,
                                end_date: str | None = None) -> dict:
        """Return the measurement events (what was measured and when) in a window, inclusive. The longitudinal
        (Synthea) record stores no result values for them: none is reported.

        Args:
            patient_id: The patient identifier.
            measurement: Optional text of the measurement name, e.g. "oral temperature", "hemoglobin".
            start_date: Window start "YYYY-MM-DD" (default: the start of the record).
            end_date: Window end "YYYY-MM-DD", inclusive (default: the end of the record).
        """
        p = self._patient(patient_id)
        start, end = self._span(start_date, end_date)
        wanted = " ".join(measurement.lower().split()) if measurement else None
        if wanted and not any(wanted in m.name.lower() for m in p.measurements):
            known = sorted({m.name for m in p.measurements})
            raise ToolError(f"no measurement matching {measurement!r} in {p.patient_id}'s record; measured: "
                            f"{', '.join(known[:25]) or 'none'}")
        rows = [m for m in p.measurements if start <= m.date[:10] <= end and (wanted is None or wanted in m.name.lower())]
        return {"patient_id": p.patient_id, "window": [start_date, end_date], "measurement": wanted,
                "n_measurements": len(rows), "values_recorded": False,
                "note": "the source (Synthea in OMOP, OHDSI Eunomia) records that and when a measurement was taken, "
                        "not its result",
                "measurements": [m.model_dump(include={"date", "name", "code", "vocabulary"}) for m in rows]}


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
