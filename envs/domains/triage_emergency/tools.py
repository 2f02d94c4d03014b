"""Triage and emergency tools. The clinical instruments are the `envs.calculators` functions under
the same names; each tool here may also take a `patient_id` and fill the inputs it can read from the
patient's latest vital signs and results (explicit arguments win)."""

from __future__ import annotations

from typing import Literal

from envs.calculators import (
    calculate_centor,
    calculate_curb65,
    calculate_esi_level,
    calculate_gcs,
    calculate_heart_score,
    calculate_news2,
    calculate_parkland,
    calculate_qsofa,
    calculate_revised_trauma_score,
    calculate_shock_index,
    calculate_sirs,
)
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool

from .data_model import Alert, EDPatient, EDResult, EDVitals, GivenMedication, TriageAssignment, TriageDB

POC_TESTS = {"glucose": "mg/dL", "troponin_i": "ng/L", "lactate": "mmol/L", "wbc": "10^3/uL", "bun": "mg/dL",
             "hemoglobin": "g/dL", "potassium": "mmol/L", "beta_hcg": "mIU/mL", "bands_percent": "%",
             "neutrophil_percent": "%"}


def _result(score) -> dict:
    return score.model_dump(mode="json")


class TriageTools(BaseDomainTools):
    """Tools over a :class:`TriageDB`."""

    db: TriageDB

    # -- helpers ---------------------------------------------------------------------------------
    def _patient(self, patient_id: str) -> EDPatient:
        p = self.db.patients.get(patient_id.strip())
        if p is None:
            raise ToolError(f"patient_id {patient_id!r} not found; patients in the department: "
                            f"{', '.join(sorted(self.db.patients)[:40])}")
        return p

    @staticmethod
    def _latest(p: EDPatient) -> EDVitals | None:
        return max(p.vitals, key=lambda v: v.time) if p.vitals else None

    def _need(self, value, name: str, p: EDPatient | None):
        if value is None:
            where = f" and patient {p.patient_id} has no recorded value" if p else ""
            raise ToolError(f"argument {name!r} is required{where}")
        return value

    def _gcs_total(self, p: EDPatient) -> int | None:
        v = self._latest(p)
        if v and None not in (v.gcs_eye, v.gcs_verbal, v.gcs_motor):
            return v.gcs_eye + v.gcs_verbal + v.gcs_motor
        return None

    def _lab(self, p: EDPatient, test: str) -> float | None:
        for r in reversed(p.results):
            if r.test == test and isinstance(r.value, (int, float)):
                return float(r.value)
        return None

    def _opt_patient(self, patient_id: str | None) -> EDPatient | None:
        return self._patient(patient_id) if patient_id else None

    # -- patient data ----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_presentation(self, patient_id: str) -> dict:
        """Return the arrival details, chief complaint, history, medications and allergies.

        Args:
            patient_id: The ED patient identifier, e.g. "ED-101" or "ESI-014".
        """
        p = self._patient(patient_id)
        out = p.model_dump(include={"patient_id", "age", "age_months", "sex", "weight_kg", "arrival_mode",
                                    "chief_complaint", "history", "medical_history", "medications", "allergies",
                                    "burn_tbsa_percent", "last_known_well"}, exclude_none=True)
        out["triage_status"] = p.triage.model_dump() if p.triage else "not yet triaged"
        return out

    @is_tool(ToolType.READ)
    def get_vital_signs(self, patient_id: str) -> dict:
        """Return the recorded vital signs and GCS components (latest first); unmeasured values are absent.

        Args:
            patient_id: The ED patient identifier.
        """
        p = self._patient(patient_id)
        if not p.vitals:
            return {"patient_id": p.patient_id, "vitals": [], "note": "no vital signs recorded at triage"}
        rows = []
        for v in sorted(p.vitals, key=lambda v: v.time, reverse=True):
            row = v.model_dump(exclude_none=True)
            if None not in (v.gcs_eye, v.gcs_verbal, v.gcs_motor):
                row["gcs_total"] = v.gcs_eye + v.gcs_verbal + v.gcs_motor
            rows.append(row)
        return {"patient_id": p.patient_id, "vitals": rows}

    @is_tool(ToolType.READ)
    def get_ed_results(self, patient_id: str) -> dict:
        """Return the ECG and point-of-care results that have been ordered for the patient.

        Args:
            patient_id: The ED patient identifier.
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "results": [r.model_dump() for r in p.results],
                "alerts": [a.model_dump() for a in p.alerts],
                "medications_given": [m.model_dump() for m in p.medications_given], "notes": p.notes}

    # -- instruments -----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def calculate_esi_level(self, requires_immediate_lifesaving_intervention: bool, high_risk_situation: bool,
                            confused_lethargic_or_disoriented: bool, severe_pain_or_distress: bool,
                            expected_resources: int, patient_id: str | None = None, age_years: float | None = None,
                            heart_rate: float | None = None, respiratory_rate: float | None = None,
                            spo2: float | None = None) -> dict:
        """Emergency Severity Index v4 (1 most urgent - 5) from the ESI decision points; with a patient_id
        the age and danger-zone vitals are read from the chart.

        Args:
            requires_immediate_lifesaving_intervention: Decision A: needs immediate airway, emergency drugs or haemodynamic intervention.
            high_risk_situation: Decision B: high-risk situation that should not wait.
            confused_lethargic_or_disoriented: Decision B: new confusion, lethargy or disorientation.
            severe_pain_or_distress: Decision B: severe pain or distress (pain >= 7/10).
            expected_resources: Decision C: number of different resources expected (labs, imaging, IV
                fluids, IV/IM/nebulised medication, consult, simple or complex procedure), 0-10.
            patient_id: Optional patient whose age and vitals fill the missing inputs.
            age_years: Age in years (danger-zone limits depend on it).
            heart_rate: Heart rate in beats/min.
            respiratory_rate: Respiratory rate in breaths/min.
            spo2: Oxygen saturation in percent.
        """
        p = self._opt_patient(patient_id)
        v = self._latest(p) if p else None
        if p is not None:
            age_years = age_years if age_years is not None else (p.age_months / 12 if p.age_months is not None and p.age < 3 else p.age)
            heart_rate = heart_rate if heart_rate is not None else (v.heart_rate if v else None)
            respiratory_rate = respiratory_rate if respiratory_rate is not None else (v.respiratory_rate if v else None)
            spo2 = spo2 if spo2 is not None else (v.spo2 if v else None)
        return _result(calculate_esi_level(
            requires_immediate_lifesaving_intervention, high_risk_situation, confused_lethargic_or_disoriented,
            severe_pain_or_distress, expected_resources, self._need(age_years, "age_years", p), heart_rate,
            respiratory_rate, spo2))

    @is_tool(ToolType.READ)
    def calculate_gcs(self, eye: int | None = None, verbal: int | None = None, motor: int | None = None,
                      patient_id: str | None = None) -> dict:
        """Glasgow Coma Scale (3-15) from eye, verbal and motor responses, or from the patient's recorded components.

        Args:
            eye: Eye opening 1-4.
            verbal: Verbal response 1-5.
            motor: Motor response 1-6.
            patient_id: Optional patient whose latest recorded components fill the missing ones.
        """
        p = self._opt_patient(patient_id)
        v = self._latest(p) if p else None
        eye = eye if eye is not None else (v.gcs_eye if v else None)
        verbal = verbal if verbal is not None else (v.gcs_verbal if v else None)
        motor = motor if motor is not None else (v.gcs_motor if v else None)
        return _result(calculate_gcs(self._need(eye, "eye", p), self._need(verbal, "verbal", p),
                                     self._need(motor, "motor", p)))

    def _vital(self, p: EDPatient | None, explicit, attr: str):
        if explicit is not None:
            return explicit
        v = self._latest(p) if p else None
        return getattr(v, attr) if v else None

    def _altered(self, p: EDPatient | None, explicit: bool | None) -> bool | None:
        if explicit is not None:
            return explicit
        if p is None:
            return None
        gcs = self._gcs_total(p)
        v = self._latest(p)
        if gcs is not None:
            return gcs < 15
        if v is not None and v.avpu is not None:
            return v.avpu != "alert"
        return None

    @is_tool(ToolType.READ)
    def calculate_qsofa(self, respiratory_rate: float | None = None, systolic_bp: float | None = None,
                        altered_mentation: bool | None = None, patient_id: str | None = None) -> dict:
        """qSOFA (0-3) for suspected infection; with a patient_id, RR, SBP and mentation (GCS < 15 or AVPU) come from the chart.

        Args:
            respiratory_rate: Respiratory rate in breaths/min.
            systolic_bp: Systolic blood pressure in mmHg.
            altered_mentation: True if mentation is altered.
            patient_id: Optional patient whose latest vitals fill the missing inputs.
        """
        p = self._opt_patient(patient_id)
        return _result(calculate_qsofa(
            self._need(self._vital(p, respiratory_rate, "respiratory_rate"), "respiratory_rate", p),
            self._need(self._vital(p, systolic_bp, "systolic_bp"), "systolic_bp", p),
            self._need(self._altered(p, altered_mentation), "altered_mentation", p)))

    @is_tool(ToolType.READ)
    def calculate_news2(self, respiratory_rate: float | None = None, spo2: float | None = None,
                        on_supplemental_oxygen: bool | None = None, temperature_c: float | None = None,
                        systolic_bp: float | None = None, heart_rate: float | None = None,
                        consciousness: Literal["alert", "new_confusion", "voice", "pain", "unresponsive"] | None = None,
                        spo2_scale: Literal[1, 2] = 1, patient_id: str | None = None) -> dict:
        """National Early Warning Score 2; with a patient_id the latest vitals and AVPU fill missing inputs.

        Args:
            respiratory_rate: Respiratory rate in breaths/min.
            spo2: SpO2 in percent.
            on_supplemental_oxygen: True if on supplemental oxygen.
            temperature_c: Temperature in degrees C.
            systolic_bp: Systolic blood pressure in mmHg.
            heart_rate: Heart rate in beats/min.
            consciousness: ACVPU level.
            spo2_scale: 1 (default) or 2 (target 88-92% in hypercapnic respiratory failure).
            patient_id: Optional patient whose latest vitals fill the missing inputs.
        """
        p = self._opt_patient(patient_id)
        v = self._latest(p) if p else None
        if consciousness is None and v is not None:
            consciousness = v.avpu or ("alert" if self._gcs_total(p) == 15 else None)
        if on_supplemental_oxygen is None and v is not None:
            on_supplemental_oxygen = v.on_supplemental_oxygen
        return _result(calculate_news2(
            self._need(self._vital(p, respiratory_rate, "respiratory_rate"), "respiratory_rate", p),
            self._need(self._vital(p, spo2, "spo2"), "spo2", p),
            self._need(on_supplemental_oxygen, "on_supplemental_oxygen", p),
            self._need(self._vital(p, temperature_c, "temperature_c"), "temperature_c", p),
            self._need(self._vital(p, systolic_bp, "systolic_bp"), "systolic_bp", p),
            self._need(self._vital(p, heart_rate, "heart_rate"), "heart_rate", p),
            self._need(consciousness, "consciousness", p), spo2_scale))

    @is_tool(ToolType.READ)
    def calculate_heart_score(self, history: Literal["slightly", "moderately", "highly"],
                              ecg: Literal["normal", "nonspecific", "st_deviation"], risk_factor_count: int,
                              atherosclerotic_disease: bool, troponin_x_uln: float | None = None,
                              age: int | None = None, patient_id: str | None = None) -> dict:
        """HEART score (0-10) for chest pain; with a patient_id, age and the troponin result (vs the 34 ng/L limit) come from the chart.

        Args:
            history: Suspicion of the history: "slightly", "moderately" or "highly".
            ecg: "normal", "nonspecific" or "st_deviation".
            risk_factor_count: Number of cardiovascular risk factors.
            atherosclerotic_disease: True for known atherosclerotic disease.
            troponin_x_uln: Initial troponin as a multiple of the upper reference limit.
            age: Age in years.
            patient_id: Optional patient whose age and troponin fill the missing inputs.
        """
        p = self._opt_patient(patient_id)
        if p is not None:
            age = age if age is not None else p.age
            if troponin_x_uln is None and self._lab(p, "troponin_i") is not None:
                troponin_x_uln = round(self._lab(p, "troponin_i") / 34.0, 3)
        return _result(calculate_heart_score(history, ecg, self._need(age, "age", p), risk_factor_count,
                                             atherosclerotic_disease, self._need(troponin_x_uln, "troponin_x_uln", p)))

    @is_tool(ToolType.READ)
    def calculate_curb65(self, confusion: bool | None = None, bun_mg_dl: float | None = None,
                         respiratory_rate: float | None = None, systolic_bp: float | None = None,
                         diastolic_bp: float | None = None, age: int | None = None,
                         patient_id: str | None = None) -> dict:
        """CURB-65 (0-5) for pneumonia severity; with a patient_id, vitals, age, confusion (GCS/AVPU) and BUN come from the chart.

        Args:
            confusion: True for new confusion.
            bun_mg_dl: Blood urea nitrogen in mg/dL.
            respiratory_rate: Respiratory rate in breaths/min.
            systolic_bp: Systolic blood pressure in mmHg.
            diastolic_bp: Diastolic blood pressure in mmHg.
            age: Age in years.
            patient_id: Optional patient whose chart fills the missing inputs.
        """
        p = self._opt_patient(patient_id)
        if p is not None:
            age = age if age is not None else p.age
            bun_mg_dl = bun_mg_dl if bun_mg_dl is not None else self._lab(p, "bun")
        return _result(calculate_curb65(
            self._need(self._altered(p, confusion), "confusion", p), self._need(bun_mg_dl, "bun_mg_dl", p),
            self._need(self._vital(p, respiratory_rate, "respiratory_rate"), "respiratory_rate", p),
            self._need(self._vital(p, systolic_bp, "systolic_bp"), "systolic_bp", p),
            self._need(self._vital(p, diastolic_bp, "diastolic_bp"), "diastolic_bp", p),
            self._need(age, "age", p)))

    @is_tool(ToolType.READ)
    def calculate_revised_trauma_score(self, gcs: int | None = None, systolic_bp: float | None = None,
                                       respiratory_rate: float | None = None, patient_id: str | None = None) -> dict:
        """Revised Trauma Score (0-7.8408) from GCS, systolic BP and respiratory rate (or the patient's chart).

        Args:
            gcs: Glasgow Coma Scale total 3-15.
            systolic_bp: Systolic blood pressure in mmHg.
            respiratory_rate: Respiratory rate in breaths/min.
            patient_id: Optional patient whose chart fills the missing inputs.
        """
        p = self._opt_patient(patient_id)
        gcs = gcs if gcs is not None else (self._gcs_total(p) if p else None)
        return _result(calculate_revised_trauma_score(
            self._need(gcs, "gcs", p), self._need(self._vital(p, systolic_bp, "systolic_bp"), "systolic_bp", p),
            self._need(self._vital(p, respiratory_rate, "respiratory_rate"), "respiratory_rate", p)))

    @is_tool(ToolType.READ)
    def calculate_parkland(self, weight_kg: float | None = None, tbsa_percent: float | None = None,
                           patient_id: str | None = None) -> dict:
        """Parkland burn resuscitation volume (4 mL x kg x %TBSA over 24 h, half in the first 8 h).

        Args:
            weight_kg: Body weight in kg.
            tbsa_percent: Partial- and full-thickness burn area in percent of total body surface.
            patient_id: Optional patient whose weight and burn area fill the missing inputs.
        """
        p = self._opt_patient(patient_id)
        if p is not None:
            weight_kg = weight_kg if weight_kg is not None else p.weight_kg
            tbsa_percent = tbsa_percent if tbsa_percent is not None else p.burn_tbsa_percent
        return _result(calculate_parkland(self._need(weight_kg, "weight_kg", p),
                                          self._need(tbsa_percent, "tbsa_percent", p)))

    @is_tool(ToolType.READ)
    def calculate_shock_index(self, heart_rate: float | None = None, systolic_bp: float | None = None,
                              patient_id: str | None = None) -> dict:
        """Shock index (heart rate / systolic BP) from explicit values or the patient's latest vitals.

        Args:
            heart_rate: Heart rate in beats/min.
            systolic_bp: Systolic blood pressure in mmHg.
            patient_id: Optional patient whose vitals fill the missing inputs.
        """
        p = self._opt_patient(patient_id)
        return _result(calculate_shock_index(self._need(self._vital(p, heart_rate, "heart_rate"), "heart_rate", p),
                                             self._need(self._vital(p, systolic_bp, "systolic_bp"), "systolic_bp", p)))

    @is_tool(ToolType.READ)
    def calculate_centor(self, tonsillar_exudate_or_swelling: bool, tender_anterior_cervical_nodes: bool,
                         cough_absent: bool, temperature_c: float | None = None, age: int | None = None,
                         patient_id: str | None = None) -> dict:
        """Modified Centor (McIsaac) score for sore throat; with a patient_id, age and temperature come from the chart.

        Args:
            tonsillar_exudate_or_swelling: Tonsillar exudate or swelling.
            tender_anterior_cervical_nodes: Tender/swollen anterior cervical nodes.
            cough_absent: True if there is no cough.
            temperature_c: Highest temperature in degrees C.
            age: Age in years.
            patient_id: Optional patient whose chart fills the missing inputs.
        """
        p = self._opt_patient(patient_id)
        age = age if age is not None else (p.age if p else None)
        return _result(calculate_centor(self._need(age, "age", p), tonsillar_exudate_or_swelling,
                                        tender_anterior_cervical_nodes,
                                        self._need(self._vital(p, temperature_c, "temperature_c"), "temperature_c", p),
                                        cough_absent))

    @is_tool(ToolType.READ)
    def screen_sepsis(self, patient_id: str) -> dict:
        """Screen a patient for sepsis: SIRS criteria (with WBC/bands if resulted) and qSOFA, computed from the chart.

        Args:
            patient_id: The ED patient identifier.
        """
        p = self._patient(patient_id)
        v = self._latest(p)
        if v is None or None in (v.temperature_c, v.heart_rate, v.respiratory_rate, v.systolic_bp):
            raise ToolError(f"patient {p.patient_id} lacks temperature, heart rate, respiratory rate or systolic BP")
        wbc = self._lab(p, "wbc")
        out: dict = {"patient_id": p.patient_id}
        if wbc is not None:
            sirs = calculate_sirs(v.temperature_c, v.heart_rate, v.respiratory_rate, wbc,
                                  bands_percent=self._lab(p, "bands_percent"))
            sirs_count, sirs_detail = sirs.score, dict(sirs.components)
        else:  # the white-cell criterion cannot be judged without a count
            sirs_detail = {"temperature": int(v.temperature_c > 38 or v.temperature_c < 36),
                           "heart_rate": int(v.heart_rate > 90), "respiratory": int(v.respiratory_rate > 20),
                           "white_cells": None}
            sirs_count = sum(x for x in sirs_detail.values() if x is not None)
            out["note"] = "WBC not resulted: SIRS counted on 3 of 4 criteria (order a WBC to complete)"
        altered = self._altered(p, None)
        q = calculate_qsofa(v.respiratory_rate, v.systolic_bp, bool(altered))
        lactate = self._lab(p, "lactate")
        out.update(sirs_criteria_met=sirs_count, sirs_components=sirs_detail, qsofa=q.score,
                   qsofa_components=dict(q.components), lactate=lactate,
                   sirs_positive=sirs_count >= 2, qsofa_positive=q.score >= 2,
                   septic_shock_physiology=bool(v.systolic_bp < 90 or (lactate is not None and lactate >= 4)))
        out["screen"] = "positive: activate the sepsis pathway" if (sirs_count >= 2 and (q.score >= 2 or (lactate or 0) >= 2)) \
            or out["septic_shock_physiology"] and sirs_count >= 2 else \
            ("possible sepsis: reassess, obtain lactate and cultures" if sirs_count >= 2 or q.score >= 2 else "negative")
        return out

    # -- actions -----------------------------------------------------------------------------------
    def _order_id(self) -> str:
        oid = f"ED-ORD-{self.db.next_order_number:04d}"
        self.db.next_order_number += 1
        return oid

    @is_tool(ToolType.WRITE)
    def order_ecg(self, patient_id: str) -> dict:
        """Obtain a 12-lead ECG now; the tracing's interpretation is returned and kept in the results.

        Args:
            patient_id: The ED patient identifier.
        """
        p = self._patient(patient_id)
        if any(r.test == "ecg" for r in p.results):
            raise ToolError(f"an ECG was already obtained for {patient_id}")
        held = p.held_results.get("ecg")
        if held is None:
            raise ToolError(f"no ECG can be obtained for {patient_id} in this scenario")
        result = EDResult(test="ecg", value=held.value, unit=held.unit, order_id=self._order_id())
        p.results.append(result)
        return result.model_dump()

    @is_tool(ToolType.WRITE)
    def order_point_of_care_test(self, patient_id: str, test: Literal["glucose", "troponin_i", "lactate", "wbc", "bun",
                                                                      "hemoglobin", "potassium", "beta_hcg",
                                                                      "bands_percent", "neutrophil_percent"]) -> dict:
        """Run a point-of-care / stat test (glucose, troponin I, lactate, WBC, BUN, haemoglobin, potassium, hCG).

        Args:
            patient_id: The ED patient identifier.
            test: The test to run.
        """
        p = self._patient(patient_id)
        if any(r.test == test for r in p.results):
            raise ToolError(f"{test} was already resulted for {patient_id}")
        held = p.held_results.get(test)
        if held is None:
            raise ToolError(f"{test} is not available for {patient_id} in this scenario; available: "
                            f"{', '.join(k for k in p.held_results if k != 'ecg') or 'none'}")
        result = EDResult(test=test, value=held.value, unit=held.unit, order_id=self._order_id())
        p.results.append(result)
        return result.model_dump()

    @is_tool(ToolType.WRITE)
    def assign_triage_level(self, patient_id: str, esi_level: int, rationale: str = "") -> dict:
        """Record the patient's ESI triage level (1 resuscitation - 5 non-urgent) and its rationale.

        Args:
            patient_id: The ED patient identifier.
            esi_level: ESI level 1-5.
            rationale: The decision points that led to the level.
        """
        p = self._patient(patient_id)
        if not 1 <= esi_level <= 5:
            raise ToolError(f"esi_level must be 1-5, got {esi_level}")
        previous = p.triage.esi_level if p.triage else None
        p.triage = TriageAssignment(esi_level=esi_level, rationale=rationale.strip())
        area = {1: "resuscitation bay", 2: "acute care (seen within 10 minutes)", 3: "acute care",
                4: "fast track", 5: "fast track"}[esi_level]
        return {"patient_id": p.patient_id, "esi_level": esi_level, "area": area, "previous_level": previous}

    @is_tool(ToolType.WRITE)
    def activate_stemi_alert(self, patient_id: str, ecg_findings: str) -> dict:
        """Activate the STEMI alert (cardiac catheterisation laboratory); needs an ECG on record.

        Args:
            patient_id: The ED patient identifier.
            ecg_findings: The ST-elevation findings that justify activation.
        """
        p = self._patient(patient_id)
        if not any(r.test == "ecg" for r in p.results):
            raise ToolError("obtain a 12-lead ECG (order_ecg) before activating the STEMI alert")
        if any(a.kind == "stemi" for a in p.alerts):
            raise ToolError(f"the STEMI alert is already active for {patient_id}")
        p.alerts.append(Alert(kind="stemi", detail=ecg_findings.strip()))
        return {"patient_id": p.patient_id, "alert": "STEMI alert activated: cath lab team paged",
                "door_to_balloon_target_min": 90}

    @is_tool(ToolType.WRITE)
    def activate_stroke_code(self, patient_id: str, deficits: str, last_known_well: str | None = None) -> dict:
        """Activate the stroke code (stroke team, immediate non-contrast CT) for a suspected acute stroke.

        Args:
            patient_id: The ED patient identifier.
            deficits: The focal neurological deficits observed.
            last_known_well: Time last known well (HH:MM), if known.
        """
        p = self._patient(patient_id)
        if any(a.kind == "stroke" for a in p.alerts):
            raise ToolError(f"the stroke code is already active for {patient_id}")
        lkw = last_known_well or p.last_known_well
        p.alerts.append(Alert(kind="stroke", detail=f"{deficits.strip()}; last known well {lkw or 'unknown'}"))
        out = {"patient_id": p.patient_id, "alert": "stroke code activated: stroke team paged, CT scanner held"}
        if lkw:
            out["last_known_well"] = lkw
        return out

    @is_tool(ToolType.WRITE)
    def escalate_care(self, patient_id: str, reason: str,
                      level: Literal["resuscitation_team", "trauma_team", "sepsis_team", "physician_now",
                                     "rapid_response", "psychiatry_crisis"] = "physician_now") -> dict:
        """Escalate to a team now (resuscitation, trauma, sepsis, immediate physician review, psychiatric crisis).

        Args:
            patient_id: The ED patient identifier.
            reason: The emergency, e.g. "septic shock: SBP 78, lactate 5.1".
            level: resuscitation_team, trauma_team, sepsis_team, physician_now, rapid_response or psychiatry_crisis.
        """
        p = self._patient(patient_id)
        if len(reason.strip()) < 5:
            raise ToolError("reason must state the emergency")
        p.alerts.append(Alert(kind="escalation", detail=f"{level}: {reason.strip()}"))
        return {"patient_id": p.patient_id, "escalated_to": level, "reason": reason.strip()}

    @is_tool(ToolType.WRITE)
    def administer_medication(self, patient_id: str, drug: str, dose_mg: float,
                              route: Literal["oral", "sublingual", "intravenous", "intramuscular", "subcutaneous",
                                             "inhaled", "intranasal"],
                              indication: str) -> dict:
        """Give a medication at triage under a standing order (e.g. aspirin for suspected ACS, IM epinephrine for
        anaphylaxis, an antipyretic); checked against the recorded allergies (drug and class) and the maximum
        single dose, and recorded on the ED chart.

        Args:
            patient_id: The ED patient identifier.
            drug: The drug (generic or brand name).
            dose_mg: The dose in mg.
            route: oral, sublingual, intravenous, intramuscular, subcutaneous, inhaled or intranasal.
            indication: Why it is given, e.g. "suspected acute coronary syndrome".
        """
        from envs.domains.drug_reference import drug_reference

        p = self._patient(patient_id)
        reference = drug_reference()
        name = reference.resolve(drug)
        if name is None:
            raise ToolError(f"drug {drug!r} is not recognised (generic or brand name, e.g. aspirin, epinephrine)")
        if not dose_mg > 0:
            raise ToolError(f"dose_mg must be positive, got {dose_mg}")
        if len(indication.strip()) < 3:
            raise ToolError("indication must say why the drug is given")
        allergy = reference.allergy_conflict(p.allergies, name)
        if allergy is not None:
            raise ToolError(f"allergy: {p.patient_id} is allergic to {allergy}; {name} is covered by that allergy. "
                            f"Choose an alternative.")
        cap = reference.max_dose_mg(name, route)
        if cap is not None and dose_mg > cap:
            raise ToolError(f"dose_mg {dose_mg:g} exceeds the maximum single {route} dose of {name} ({cap:g} mg)")
        given = GivenMedication(drug=name, dose_mg=dose_mg, route=route, time=self.db.clock,
                                indication=indication.strip())
        p.medications_given.append(given)
        return {"patient_id": p.patient_id, **given.model_dump(), "max_single_dose_mg": cap,
                "doses_given_of_this_drug": sum(m.drug == name for m in p.medications_given)}

    @is_tool(ToolType.WRITE)
    def write_triage_note(self, patient_id: str, note: str) -> dict:
        """Add a triage note (assessment, interventions started, re-assessment plan) to the ED record.

        Args:
            patient_id: The ED patient identifier.
            note: The note text.
        """
        p = self._patient(patient_id)
        if len(note.strip()) < 15:
            raise ToolError("note is too short (at least 15 characters)")
        p.notes.append(note.strip())
        return {"patient_id": p.patient_id, "notes": len(p.notes)}
