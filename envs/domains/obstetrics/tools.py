"""Obstetrics tools: chart, vitals, labs, cervix, ultrasound and CTG review; CTG interpretation
(NICHD category computed from the FHR series); Bishop, Apgar and biophysical profile from
`envs.calculators`; gestational dating; hypertensive-disorder screening; orders and escalation."""

from __future__ import annotations

import re
from datetime import date
from typing import Literal

from envs.calculators import CALCULATORS
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool
from envs.domains.obstetrics import ctg as CTG
from envs.domains.obstetrics import rules
from envs.domains.obstetrics.data_model import (
    ClinicalNote, Escalation, LabOrder, MedicationOrder, ObstetricsDB, Patient,
)

ESCALATION_LEVELS = ("emergency cesarean delivery", "obstetric emergency team", "operative vaginal delivery",
                     "maternal-fetal medicine consult", "neonatal resuscitation team", "maternal ICU")
# Interpretations are pure functions of the (read-only) tracing: computed once per process.
_INTERPRETATIONS: dict[tuple, dict] = {}


def _key(text: str) -> str:
    return " ".join(re.findall(r"[a-z0-9]+", text.lower()))


class ObstetricsTools(BaseDomainTools):
    db: ObstetricsDB

    def _patient(self, patient_id: str) -> Patient:
        pid = (patient_id or "").strip().upper()
        if pid not in self.db.patients:
            raise ToolError(f"patient {patient_id!r} not found; ids look like {min(self.db.patients)} ({len(self.db.patients)} patients)")
        return self.db.patients[pid]

    def _today(self) -> date:
        return date.fromisoformat(self.db.today)

    def _ga_days(self, p: Patient) -> int | None:
        dating = next((u for u in p.ultrasounds if u.scan == "dating" and u.crown_rump_length_mm), None)
        lmp = date.fromisoformat(p.lmp_date) if p.lmp_date else None
        if lmp is None and dating is None:
            return None
        scan = None
        if dating is not None:
            scan = date.fromordinal(self._today().toordinal() - int(round(dating.weeks_ago * 7)))
        out = rules.gestational_age(self._today(), lmp, dating.crown_rump_length_mm if dating else None, scan)
        return out["best_estimate"]["days"]

    def _labs(self, p: Patient) -> list:
        ordered = [p.orderable_results[o.test] for o in self.db.lab_orders if o.patient_id == p.patient_id and o.status == "resulted"]
        return list(p.labs) + ordered

    # -- chart -----------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_summary(self, patient_id: str) -> dict:
        """Return demographics, gravidity/parity, presenting complaint, history, dating, medications and allergies.

        Args:
            patient_id: Patient identifier, e.g. "OB-004".
        """
        p = self._patient(patient_id)
        days = self._ga_days(p)
        return {"patient_id": p.patient_id, "name": p.name, "age": p.age, "gravida": p.gravida, "para": p.para,
                "setting": p.setting, "presenting_complaint": p.presenting_complaint, "history": p.history,
                "lmp_date": p.lmp_date, "gestational_age": rules.weeks_days(days) if days is not None else None,
                "chronic_hypertension": p.chronic_hypertension, "conditions": p.conditions, "prior_cesarean": p.prior_cesarean,
                "medications": p.medications, "allergies": p.allergies or ["no known drug allergies"],
                "symptoms": [k for k, v in p.symptoms.model_dump().items() if v is True] + p.symptoms.other,
                "available": {"ctg": [t.tracing_id for t in p.ctg], "ultrasounds": [u.scan for u in p.ultrasounds],
                              "cervical_exam": p.cervical_exam is not None, "newborn_observations": [n.minute for n in p.newborn]}}

    @is_tool(ToolType.READ)
    def get_vital_signs(self, patient_id: str) -> dict:
        """Return maternal vital signs with the blood-pressure series (hours before now).

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        v = p.vitals
        return {"patient_id": p.patient_id, "blood_pressures": [b.model_dump() for b in sorted(v.blood_pressures, key=lambda b: -b.hours_ago)],
                "heart_rate": v.heart_rate, "respiratory_rate": v.respiratory_rate, "temperature_c": v.temperature_c, "spo2": v.spo2}

    @is_tool(ToolType.READ)
    def get_lab_results(self, patient_id: str) -> dict:
        """Return resulted labs (including those ordered this episode) flagged against reference ranges.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        out = []
        for lab in self._labs(p):
            flag = "high" if lab.ref_high is not None and lab.value > lab.ref_high else \
                "low" if lab.ref_low is not None and lab.value < lab.ref_low else "normal"
            out.append({**lab.model_dump(), "flag": flag})
        return {"patient_id": p.patient_id, "results": out}

    @is_tool(ToolType.READ)
    def get_cervical_exam(self, patient_id: str) -> dict:
        """Return the latest vaginal examination: dilation, effacement, station, consistency, position, membranes.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        if p.cervical_exam is None:
            raise ToolError(f"no cervical examination recorded for {p.patient_id}")
        return {"patient_id": p.patient_id, **p.cervical_exam.model_dump()}

    @is_tool(ToolType.READ)
    def get_ultrasound_report(self, patient_id: str) -> dict:
        """Return the ultrasound reports (dating CRL, biophysical profile components, amniotic fluid).

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        if not p.ultrasounds:
            raise ToolError(f"no ultrasound on file for {p.patient_id}")
        return {"patient_id": p.patient_id, "reports": [u.model_dump(exclude_none=True) for u in p.ultrasounds]}

    @is_tool(ToolType.READ)
    def get_ctg_tracing(self, patient_id: str, tracing_id: str | None = None) -> dict:
        """Return a CTG tracing: the FHR series (one value every 2 s) and the contraction windows.

        Args:
            patient_id: Patient identifier.
            tracing_id: Which tracing; the latest when omitted.
        """
        t = self._tracing(self._patient(patient_id), tracing_id)
        return {"patient_id": patient_id.strip().upper(), **t.model_dump()}

    def _tracing(self, p: Patient, tracing_id: str | None):
        if not p.ctg:
            raise ToolError(f"no CTG tracing recorded for {p.patient_id}")
        if tracing_id is None:
            return p.ctg[-1]
        for t in p.ctg:
            if t.tracing_id == tracing_id.strip():
                return t
        raise ToolError(f"tracing {tracing_id!r} not found; tracings: {[t.tracing_id for t in p.ctg]}")

    # -- interpretation and scores -----------------------------------------------------------------
    @is_tool(ToolType.READ)
    def interpret_ctg(self, patient_id: str, tracing_id: str | None = None) -> dict:
        """Interpret a CTG from its FHR series: baseline, variability, accelerations, decelerations, contractions, NICHD category.

        Args:
            patient_id: Patient identifier.
            tracing_id: Which tracing; the latest when omitted.
        """
        p = self._patient(patient_id)
        t = self._tracing(p, tracing_id)
        days = self._ga_days(p)
        key = (p.patient_id, t.tracing_id, len(t.fhr), sum(t.fhr))
        if key not in _INTERPRETATIONS:
            _INTERPRETATIONS[key] = CTG.interpret(t.model_dump(), (days or 280) / 7)
        return {"patient_id": p.patient_id, "tracing_id": t.tracing_id, **_INTERPRETATIONS[key]}

    @is_tool(ToolType.READ)
    def assess_fetal_status(self, patient_id: str) -> dict:
        """Combine the latest CTG category, biophysical profile and amniotic fluid into a fetal status and next step.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        category = self.interpret_ctg(p.patient_id)["category"] if p.ctg else None
        bpp = next((u for u in reversed(p.ultrasounds) if u.scan == "biophysical profile"), None)
        score = maximum = None
        oligo = False
        if bpp is not None:
            res = CALCULATORS["calculate_biophysical_profile"](
                fetal_breathing=bpp.fetal_breathing, body_movements_count=bpp.body_movements_count, fetal_tone=bpp.fetal_tone,
                deepest_vertical_pocket_cm=bpp.deepest_vertical_pocket_cm, nst_reactive=bpp.nst_reactive)
            score, maximum = int(res.score), 10 if bpp.nst_reactive is not None else 8
            oligo = bpp.deepest_vertical_pocket_cm <= 2
        days = self._ga_days(p)
        out = rules.fetal_status(category, score, maximum, oligo, round((days or 0) / 7, 1))
        return {"patient_id": p.patient_id, "ctg_category": category, "biophysical_profile": score,
                "biophysical_profile_max": maximum, **out}

    @is_tool(ToolType.READ)
    def calculate_bishop_score(self, patient_id: str | None = None, dilation_cm: float | None = None,
                               effacement_percent: float | None = None, station: int | None = None,
                               consistency: Literal["firm", "medium", "soft"] | None = None,
                               position: Literal["posterior", "mid", "anterior"] | None = None) -> dict:
        """Bishop pre-induction cervical score (0-13); missing inputs come from the patient's latest cervical exam.

        Args:
            patient_id: Patient whose cervical exam fills any input not given.
            dilation_cm: Dilation in cm.
            effacement_percent: Effacement in percent.
            station: Station -5 to +5.
            consistency: "firm", "medium" or "soft".
            position: "posterior", "mid" or "anterior".
        """
        given = {"dilation_cm": dilation_cm, "effacement_percent": effacement_percent, "station": station,
                 "consistency": consistency, "position": position}
        if any(v is None for v in given.values()):
            if patient_id is None:
                raise ToolError("give all five components or a 'patient_id' with a cervical exam on file")
            exam = self._patient(patient_id).cervical_exam
            if exam is None:
                raise ToolError(f"no cervical exam on file for {patient_id}; give the components explicitly")
            given = {k: (v if v is not None else getattr(exam, k)) for k, v in given.items()}
        return CALCULATORS["calculate_bishop_score"](**given).model_dump(mode="json")

    @is_tool(ToolType.READ)
    def calculate_apgar(self, patient_id: str | None = None, minute: int | None = None, heart_rate: float | None = None,
                        respiratory_effort: Literal["absent", "weak", "strong"] | None = None,
                        muscle_tone: Literal["limp", "some_flexion", "active"] | None = None,
                        reflex_irritability: Literal["none", "grimace", "cry"] | None = None,
                        color: Literal["blue_pale", "acrocyanosis", "pink"] | None = None) -> dict:
        """Apgar score (0-10) of the newborn; missing signs come from the recorded observation at that minute.

        Args:
            patient_id: Mother's patient identifier (the newborn's observations are on her record).
            minute: 1, 5 or 10 (default: the latest recorded).
            heart_rate: Newborn heart rate, beats/min.
            respiratory_effort: "absent", "weak" or "strong".
            muscle_tone: "limp", "some_flexion" or "active".
            reflex_irritability: "none", "grimace" or "cry".
            color: "blue_pale", "acrocyanosis" or "pink".
        """
        given = {"heart_rate": heart_rate, "respiratory_effort": respiratory_effort, "muscle_tone": muscle_tone,
                 "reflex_irritability": reflex_irritability, "color": color}
        if any(v is None for v in given.values()):
            if patient_id is None:
                raise ToolError("give all five signs or a 'patient_id' with newborn observations on file")
            obs = self._patient(patient_id).newborn
            if not obs:
                raise ToolError(f"no newborn observations on file for {patient_id}")
            pick = obs[-1] if minute is None else next((o for o in obs if o.minute == minute), None)
            if pick is None:
                raise ToolError(f"no observation at minute {minute}; recorded minutes: {[o.minute for o in obs]}")
            given = {k: (v if v is not None else getattr(pick, k)) for k, v in given.items()}
            minute = pick.minute
        out = CALCULATORS["calculate_apgar"](**given).model_dump(mode="json")
        return {"minute": minute, **out}

    @is_tool(ToolType.READ)
    def calculate_biophysical_profile(self, patient_id: str | None = None, fetal_breathing: bool | None = None,
                                      body_movements_count: int | None = None, fetal_tone: bool | None = None,
                                      deepest_vertical_pocket_cm: float | None = None, nst_reactive: bool | None = None) -> dict:
        """Fetal biophysical profile (0-10 with NST, 0-8 without); missing components come from the latest BPP scan.

        Args:
            patient_id: Patient whose latest biophysical-profile ultrasound fills any component not given.
            fetal_breathing: Breathing episode >= 30 s within 30 min.
            body_movements_count: Discrete body/limb movements in 30 min.
            fetal_tone: Extension with return to flexion.
            deepest_vertical_pocket_cm: Deepest vertical pocket of amniotic fluid, cm.
            nst_reactive: Nonstress test reactive (omit when not performed).
        """
        given = {"fetal_breathing": fetal_breathing, "body_movements_count": body_movements_count, "fetal_tone": fetal_tone,
                 "deepest_vertical_pocket_cm": deepest_vertical_pocket_cm}
        if any(v is None for v in given.values()):
            if patient_id is None:
                raise ToolError("give the four ultrasound components or a 'patient_id' with a BPP scan on file")
            scan = next((u for u in reversed(self._patient(patient_id).ultrasounds) if u.scan == "biophysical profile"), None)
            if scan is None:
                raise ToolError(f"no biophysical-profile scan on file for {patient_id}")
            given = {k: (v if v is not None else getattr(scan, k)) for k, v in given.items()}
            if nst_reactive is None:
                nst_reactive = scan.nst_reactive
        return CALCULATORS["calculate_biophysical_profile"](**given, nst_reactive=nst_reactive).model_dump(mode="json")

    @is_tool(ToolType.READ)
    def calculate_gestational_age(self, patient_id: str | None = None, lmp_date: str | None = None,
                                  crown_rump_length_mm: float | None = None, scan_date: str | None = None,
                                  on_date: str | None = None) -> dict:
        """Gestational age and EDD from the LMP (Naegele) and/or a first-trimester CRL (Robinson), with ACOG redating.

        Args:
            patient_id: Patient whose LMP and dating scan fill the inputs not given.
            lmp_date: First day of the last menstrual period, YYYY-MM-DD.
            crown_rump_length_mm: Crown-rump length at the dating scan, mm.
            scan_date: Date of the dating scan, YYYY-MM-DD.
            on_date: Date to compute the gestational age for (default today).
        """
        if patient_id is not None:
            p = self._patient(patient_id)
            if lmp_date is None and p.lmp_date:
                lmp_date = p.lmp_date
            dating = next((u for u in p.ultrasounds if u.scan == "dating" and u.crown_rump_length_mm), None)
            if crown_rump_length_mm is None and dating is not None:
                crown_rump_length_mm = dating.crown_rump_length_mm
                if scan_date is None:
                    scan_date = date.fromordinal(self._today().toordinal() - int(round(dating.weeks_ago * 7))).isoformat()
        on = rules.parse_date(on_date, "on_date") if on_date else self._today()
        lmp = rules.parse_date(lmp_date, "lmp_date") if lmp_date else None
        scan = rules.parse_date(scan_date, "scan_date") if scan_date else None
        return rules.gestational_age(on, lmp, crown_rump_length_mm, scan)

    @is_tool(ToolType.READ)
    def screen_preeclampsia(self, patient_id: str) -> dict:
        """Classify hypertension in pregnancy (gestational hypertension, preeclampsia with/without severe features, HELLP, eclampsia) from BP series, labs and symptoms.

        Args:
            patient_id: Patient identifier.
        """
        p = self._patient(patient_id)
        days = self._ga_days(p)
        if days is None:
            raise ToolError(f"no dating for {p.patient_id}: record an LMP or a dating scan first")
        labs: dict[str, float] = {}
        for lab in self._labs(p):
            labs[lab.name] = lab.value
        on_antihypertensive = any(m.lower().split()[0] in ("labetalol", "nifedipine", "hydralazine") for m in p.medications) or any(
            o.patient_id == p.patient_id and o.drug in ("labetalol", "nifedipine", "hydralazine") for o in self.db.medication_orders)
        out = rules.hypertensive_disorder(days / 7, [b.model_dump() for b in p.vitals.blood_pressures], labs,
                                          p.symptoms.model_dump(), p.chronic_hypertension, on_antihypertensive)
        missing = [n for n in ("platelets", "creatinine", "AST", "ALT", "urine protein/creatinine ratio") if n not in labs]
        return {"patient_id": p.patient_id, "gestational_age": rules.weeks_days(days), **out, "labs_missing": missing}

    def _drug_key(self, drug: str) -> str:
        key = _key(drug).replace(" ", "_")
        if key in self.db.formulary:
            return key
        for k, rec in self.db.formulary.items():
            if _key(rec.name).startswith(_key(drug)):
                return k
        raise ToolError(f"{drug!r} is not on the obstetric formulary: {', '.join(sorted(self.db.formulary))}")

    def _current_drugs(self, p: Patient) -> list[str]:
        out = []
        for med in p.medications:
            for k, rec in self.db.formulary.items():
                if _key(rec.name.split(" (")[0]) in _key(med) or _key(k.replace("_", " ")) in _key(med):
                    out.append(k)
        out += [o.drug for o in self.db.medication_orders if o.patient_id == p.patient_id]
        return list(dict.fromkeys(out))

    @is_tool(ToolType.READ)
    def check_drug_interactions(self, patient_id: str, drug: str) -> dict:
        """Check a drug against the patient's allergies, conditions and current obstetric medications (including orders this episode).

        Args:
            patient_id: Patient identifier.
            drug: The drug being considered.
        """
        p = self._patient(patient_id)
        key = self._drug_key(drug)
        rec = self.db.formulary[key]
        current = [d for d in self._current_drugs(p) if d != key]
        found = []
        for inter in self.db.interactions:
            if key in inter.drugs:
                other = next(d for d in inter.drugs if d != key)
                if other in current:
                    found.append({"with": other.replace("_", " "), **inter.model_dump(exclude={"drugs"})})
        problems = [f"allergy: patient is allergic to {a}" for a in p.allergies
                    if _key(a) in _key(rec.name) or _key(rec.name) in _key(a)]
        problems += [f"contraindicated in {c}" for c in p.conditions if any(_key(c) == _key(x) for x in rec.contraindications)]
        out = {"drug": rec.name, "current_medications": [c.replace("_", " ") for c in current], "interactions": found,
               "safe_to_order": not problems and not any(f["severity"] in ("contraindicated", "major") for f in found)}
        if problems:  # only present when there is something to act on
            out["problems"] = problems
        return out

    # -- orders and escalation (WRITE) ---------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def order_lab(self, patient_id: str, test: str) -> dict:
        """Order a laboratory test (e.g. "platelets", "urine protein/creatinine ratio"); an available result appears in get_lab_results.

        Args:
            patient_id: Patient identifier.
            test: Test name.
        """
        p = self._patient(patient_id)
        match = next((n for n in p.orderable_results if _key(n) == _key(test)), None)
        self.db.lab_orders.append(LabOrder(patient_id=p.patient_id, test=match or test.strip(),
                                           status="resulted" if match else "not available"))
        return {"ordered": test, "patient_id": p.patient_id, "status": "resulted" if match else "not available"}

    @is_tool(ToolType.WRITE)
    def order_medication(self, patient_id: str, drug: str, dose_mg: float, route: Literal["IV", "IM", "PO", "SC"],
                         indication: str) -> dict:
        """Order an obstetric medication (magnesium sulfate, labetalol, nifedipine, hydralazine, betamethasone, oxytocin, terbutaline, calcium gluconate).

        Args:
            patient_id: Patient identifier.
            drug: Generic drug name.
            dose_mg: Single dose in mg (magnesium sulfate in mg: 4 g = 4000).
            route: "IV", "IM", "PO" or "SC".
            indication: Why it is given.
        """
        p = self._patient(patient_id)
        key = self._drug_key(drug)
        rec = self.db.formulary[key]
        if route not in rec.routes:
            raise ToolError(f"{rec.name} is not given {route} here; routes: {', '.join(rec.routes)}")
        if dose_mg <= 0:
            raise ToolError("argument 'dose_mg' must be positive")
        warnings = []
        if any(_key(a) in _key(rec.name) or _key(rec.name) in _key(a) for a in p.allergies):
            warnings.append(f"patient is allergic to {rec.name}")
        for cond in p.conditions:
            if any(_key(c) == _key(cond) for c in rec.contraindications):
                warnings.append(f"{rec.name} is contraindicated in {cond}")
        if rec.max_single_dose_mg is not None and dose_mg > rec.max_single_dose_mg:
            warnings.append(f"dose {dose_mg:g} mg exceeds the maximum single dose {rec.max_single_dose_mg:g} mg")
        self.db.medication_orders.append(MedicationOrder(patient_id=p.patient_id, drug=key, dose_mg=dose_mg, route=route,
                                                         indication=indication.strip(), warnings=warnings))
        return {"ordered": rec.name, "dose_mg": dose_mg, "route": route, "warnings": warnings, "usual_dose": rec.usual_dose}

    @is_tool(ToolType.WRITE)
    def escalate_care(self, patient_id: str,
                      level: Literal["emergency cesarean delivery", "obstetric emergency team", "operative vaginal delivery",
                                     "maternal-fetal medicine consult", "neonatal resuscitation team", "maternal ICU"],
                      reason: str) -> dict:
        """Escalate care: emergency cesarean, obstetric emergency team, operative delivery, MFM consult, neonatal team or maternal ICU.

        Args:
            patient_id: Patient identifier.
            level: The escalation requested.
            reason: The clinical reason.
        """
        p = self._patient(patient_id)
        if not reason.strip():
            raise ToolError("argument 'reason' is empty: state why care is escalated")
        self.db.escalations.append(Escalation(patient_id=p.patient_id, level=level, reason=reason.strip()))
        return {"escalated": True, "patient_id": p.patient_id, "level": level}

    @is_tool(ToolType.WRITE)
    def write_obstetric_note(self, patient_id: str, assessment: str, plan: str) -> dict:
        """Write an assessment and plan note in the obstetric record.

        Args:
            patient_id: Patient identifier.
            assessment: Clinical assessment.
            plan: Management plan.
        """
        p = self._patient(patient_id)
        if not assessment.strip() or not plan.strip():
            raise ToolError("arguments 'assessment' and 'plan' must not be empty")
        self.db.notes.append(ClinicalNote(patient_id=p.patient_id, assessment=assessment.strip(), plan=plan.strip()))
        return {"recorded": True, "patient_id": p.patient_id, "notes": sum(1 for n in self.db.notes if n.patient_id == p.patient_id)}
