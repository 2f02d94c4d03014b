"""Clinical-diagnosis tools: history, vitals, examination, labs (with reference ranges and flags),
lab orders that release the case's held-back results, a phenotype-driven differential (HPO),
ICD-10-CM lookup, diagnosis recording, allergy-checked prescribing and clinical notes."""

from __future__ import annotations

import re
from datetime import datetime, timedelta
from typing import Literal

from envs.core.common_tools import BaseDomainTools
from envs.core.icd10 import normalise_code
from envs.core.tools import ToolError, ToolType, is_tool

from . import knowledge
from .data_model import (
    ClinicalDiagnosisDB, ClinicalNote, DiagnosisRecord, FollowUp, LabOrder, LabResult, Patient, Prescription,
)

# Doses per day for the usual frequency abbreviations (None: as needed / single dose).
FREQUENCY_PER_DAY: dict[str, int | None] = {
    "once": 1, "stat": 1, "daily": 1, "qd": 1, "od": 1, "nightly": 1, "qhs": 1, "bid": 2, "q12h": 2, "tid": 3,
    "q8h": 3, "qid": 4, "q6h": 4, "q4h": 6, "q24h": 1, "weekly": 1, "prn": None,
}
# Allergy groups with known clinical cross-reactivity: a warning, not a block.
CROSS_REACTIVE: dict[str, set[str]] = {"penicillin": {"cephalosporin"}, "cephalosporin": {"penicillin"}}


def _fold(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", " ", text.lower()).strip()


class ClinicalDiagnosisTools(BaseDomainTools):
    """Tools over a :class:`ClinicalDiagnosisDB`."""

    db: ClinicalDiagnosisDB

    # -- helpers ---------------------------------------------------------------------------------
    def _patient(self, patient_id: str) -> Patient:
        patient = self.db.patients.get(patient_id.strip())
        if patient is None:
            known = ", ".join(sorted(self.db.patients)[:30])
            raise ToolError(f"patient_id {patient_id!r} not found; known patients: {known}")
        return patient

    def _test_key(self, test: str) -> str:
        key = knowledge.lab_catalog().resolve(test)
        if key is None:
            raise ToolError(f"test {test!r} is not in the laboratory catalogue; call list_lab_tests to see the "
                            f"orderable tests")
        return key

    def _result_row(self, patient: Patient, result: LabResult) -> dict:
        catalog = knowledge.lab_catalog()
        row = {"test": result.test, "value": result.value, "unit": result.unit, "time": result.time}
        if result.test in catalog.analytes:
            desc = catalog.describe(result.test, patient.sex)
            row["name"] = desc["name"]
            row["reference"] = desc.get("reference_range") or f"normal: {desc.get('normal')}"
            row["flag"] = catalog.flag(result.test, result.value, patient.sex)
        return row

    def _visible_tests(self, patient: Patient) -> set[str]:
        return {r.test for r in patient.lab_results}

    def _known_findings(self, patient: Patient) -> list[dict]:
        visible = self._visible_tests(patient)
        return [f.model_dump() for f in patient.findings if f.requires_test is None or f.requires_test in visible]

    def _drug(self, name: str):
        folded = _fold(name)
        for key, drug in self.db.formulary.items():
            if folded == _fold(key) or folded in {_fold(a) for a in drug.aliases}:
                return drug
        raise ToolError(f"drug {name!r} is not in the formulary; examples: "
                        f"{', '.join(sorted(self.db.formulary)[:12])}, ...")

    def _allergy_groups(self, substance: str) -> set[str]:
        """The allergy groups a recorded allergy covers: a formulary drug's groups, or a group name."""
        folded = _fold(substance)
        groups: set[str] = set()
        for key, drug in self.db.formulary.items():
            if folded == _fold(key) or folded in {_fold(a) for a in drug.aliases}:
                groups |= set(drug.allergy_groups) | {key}
        all_groups = {g for drug in self.db.formulary.values() for g in drug.allergy_groups}
        groups |= {g for g in all_groups if _fold(g) == folded}
        return groups

    def _allergy_check(self, patient: Patient, drug) -> dict:
        """Match the patient's allergies against the drug: blocking conflicts and cross-reactivity warnings."""
        conflicts, warnings = [], []
        drug_groups = set(drug.allergy_groups) | {drug.name}
        for allergy in patient.allergies:
            covered = self._allergy_groups(allergy.substance)
            shared = drug_groups & covered
            if shared:
                conflicts.append({"allergy": allergy.substance, "reaction": allergy.reaction,
                                  "severity": allergy.severity, "shared_group": sorted(shared)})
                continue
            cross = {g for g in covered for x in CROSS_REACTIVE.get(g, ()) if x in drug_groups}
            if cross:
                warnings.append({"allergy": allergy.substance, "severity": allergy.severity,
                                 "note": f"possible cross-reactivity between {sorted(cross)[0]} and {drug.drug_class}"})
        return {"conflicts": conflicts, "warnings": warnings}

    def _clock(self, minutes: int = 0) -> str:
        return (datetime.fromisoformat(self.db.clock) + timedelta(minutes=minutes)).strftime("%Y-%m-%dT%H:%M")

    # -- patient data ----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_info(self, patient_id: str) -> dict:
        """Return a patient's demographics, presenting complaint, history, medications and allergies.

        Args:
            patient_id: The patient identifier, e.g. "CD-P01".
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "name": p.name, "age": p.age, "sex": p.sex, "weight_kg": p.weight_kg,
                "setting": p.setting, "chief_complaint": p.chief_complaint,
                "history_of_present_illness": p.history_of_present_illness,
                "past_medical_history": p.past_medical_history,
                "medications": [m.model_dump() for m in p.medications],
                "allergies": [a.model_dump() for a in p.allergies] or "no known drug allergies",
                "social_history": p.social_history, "family_history": p.family_history,
                "review_of_systems": p.review_of_systems}

    @is_tool(ToolType.READ)
    def get_vital_signs(self, patient_id: str) -> dict:
        """Return the patient's recorded vital signs (latest first) with out-of-range values marked.

        Args:
            patient_id: The patient identifier.
        """
        p = self._patient(patient_id)
        if not p.vitals:
            raise ToolError(f"no vital signs recorded for {patient_id}")
        rows = []
        for v in sorted(p.vitals, key=lambda v: v.time, reverse=True):
            row = v.model_dump(exclude_none=True)
            abnormal = []
            if v.heart_rate is not None and not 60 <= v.heart_rate <= 100:
                abnormal.append("heart_rate")
            if v.systolic_bp is not None and (v.systolic_bp < 90 or v.systolic_bp >= 140):
                abnormal.append("systolic_bp")
            if v.respiratory_rate is not None and not 12 <= v.respiratory_rate <= 20:
                abnormal.append("respiratory_rate")
            if v.temperature_c is not None and not 36.0 <= v.temperature_c <= 38.0:
                abnormal.append("temperature_c")
            if v.spo2 is not None and v.spo2 < 94:
                abnormal.append("spo2")
            if v.systolic_bp is not None and v.diastolic_bp is not None:
                row["mean_arterial_pressure"] = round((v.systolic_bp + 2 * v.diastolic_bp) / 3, 1)
            row["outside_adult_normal"] = abnormal
            rows.append(row)
        return {"patient_id": p.patient_id, "vitals": rows}

    @is_tool(ToolType.READ)
    def get_physical_exam(self, patient_id: str, system: str | None = None) -> dict:
        """Return the physical examination findings, for every system or one system.

        Args:
            patient_id: The patient identifier.
            system: Optional body system, e.g. "lungs", "abdomen", "neurologic".
        """
        p = self._patient(patient_id)
        if system is None:
            return {"patient_id": p.patient_id, "exam": p.physical_exam}
        key = _fold(system)
        hits = {k: v for k, v in p.physical_exam.items() if key in _fold(k) or _fold(k) in key}
        if not hits:
            raise ToolError(f"system {system!r} was not examined; examined systems: {', '.join(p.physical_exam)}")
        return {"patient_id": p.patient_id, "exam": hits}

    @is_tool(ToolType.READ)
    def get_patient_findings(self, patient_id: str) -> dict:
        """Return the patient's clinical findings coded to HPO terms (lab and imaging findings appear only
        once the test that shows them has a result).

        Args:
            patient_id: The patient identifier.
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "findings": self._known_findings(p)}

    @is_tool(ToolType.READ)
    def get_lab_results(self, patient_id: str, test: str | None = None) -> dict:
        """Return resulted laboratory and imaging tests with reference ranges and flags (low/high/critical).

        Args:
            patient_id: The patient identifier.
            test: Optional test name to filter on, e.g. "potassium".
        """
        p = self._patient(patient_id)
        results = sorted(p.lab_results, key=lambda r: r.time)
        if test is not None:
            key = self._test_key(test)
            results = [r for r in results if r.test == key]
            if not results:
                pending = [o.order_id for o in p.orders if o.test == key and o.status == "pending"]
                state = f"ordered ({', '.join(pending)}), not resulted" if pending else "not ordered"
                return {"patient_id": p.patient_id, "test": key, "results": [], "status": state}
        return {"patient_id": p.patient_id, "results": [self._result_row(p, r) for r in results],
                "pending_orders": [o.model_dump() for o in p.orders if o.status == "pending"]}

    @is_tool(ToolType.READ)
    def list_lab_tests(self, panel: str | None = None) -> list[dict]:
        """List the orderable tests with their units and adult reference ranges.

        Args:
            panel: Optional panel filter, e.g. "BMP", "CBC", "Coagulation", "ABG", "Lipids".
        """
        catalog = knowledge.lab_catalog()
        out = []
        for key in catalog.known():
            a = catalog.analytes[key]
            if panel is not None and _fold(a.get("panel") or "") != _fold(panel):
                continue
            d = catalog.describe(key, None)
            out.append({"test": key, "name": a["name"], "panel": a.get("panel"),
                        "reference": d.get("reference_range") or f"normal: {d.get('normal')}"})
        if not out:
            panels = sorted({a.get("panel") for a in catalog.analytes.values() if a.get("panel")})
            raise ToolError(f"panel {panel!r} not found; panels: {', '.join(panels)}")
        return out

    @is_tool(ToolType.WRITE)
    def order_lab(self, patient_id: str, test: str, priority: Literal["routine", "urgent", "stat"] = "routine",
                  indication: str = "") -> dict:
        """Order a laboratory or imaging test; its result appears in get_lab_results once resulted.

        Args:
            patient_id: The patient identifier.
            test: The test to order (name or catalogue key, e.g. "troponin_i", "chest x-ray").
            priority: "routine", "urgent" or "stat".
            indication: The clinical question the test answers.
        """
        p = self._patient(patient_id)
        key = self._test_key(test)
        if any(o.test == key for o in p.orders):
            existing = next(o for o in p.orders if o.test == key)
            raise ToolError(f"{key} is already ordered for {patient_id} ({existing.order_id}, {existing.status})")
        order_id = f"ORD-{self.db.next_order_number:04d}"
        self.db.next_order_number += 1
        hidden = p.hidden_results.get(key)
        order = LabOrder(order_id=order_id, test=key, priority=priority, indication=indication,
                         status="resulted" if hidden is not None else "pending")
        p.orders.append(order)
        out = {"order_id": order_id, "test": key, "priority": priority}
        if hidden is not None:
            # The case's result is released: urgent/stat tests come back faster.
            minutes = max(10, hidden.turnaround_min // (2 if priority != "routine" else 1))
            result = LabResult(test=key, value=hidden.value, unit=hidden.unit, time=self._clock(minutes),
                               order_id=order_id)
            p.lab_results.append(result)
            out.update(status="resulted", result=self._result_row(p, result))
        else:
            out.update(status="pending", note="specimen sent; no result is available during this encounter")
        return out

    # -- interpretation --------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def interpret_lab_value(self, test: str, value: float, sex: Literal["male", "female"] | None = None,
                            age: int | None = None, unit: str | None = None) -> dict:
        """Classify a numeric lab value against the adult reference range and critical limits.

        Args:
            test: Test name or key, e.g. "sodium", "hemoglobin".
            value: The measured value.
            sex: "male" or "female" for sex-specific ranges.
            age: Age in years (the ranges are adult ranges; under 18 is reported as a caveat).
            unit: The unit of the value when it is not the conventional unit (e.g. "umol/L" for
                creatinine); converted with the labunits factor.
        """
        catalog = knowledge.lab_catalog()
        key = self._test_key(test)
        a = catalog.analytes[key]
        if a.get("qualitative"):
            raise ToolError(f"{a['name']} is a qualitative test; interpret it from its report text")
        try:
            conventional, note = catalog.to_conventional(key, value, unit)
        except ValueError as exc:
            raise ToolError(f"unit: {exc}") from None
        flag = catalog.flag(key, conventional, sex)
        iv = catalog.interval(key, sex)
        out = {"test": key, "name": a["name"], "value": round(conventional, 4), "unit": a["unit"], "flag": flag,
               "reference_range": f"{iv.low:g}-{iv.high:g} {a['unit']}" if iv.low is not None and iv.high is not None else None,
               "critical_low": iv.critical_low, "critical_high": iv.critical_high}
        if note:
            out["conversion"] = note
        if iv.low is not None and iv.high is not None and iv.high > iv.low:
            out["deviation_from_range"] = round(conventional - iv.high if conventional > iv.high else
                                                conventional - iv.low if conventional < iv.low else 0.0, 4)
        if sex is None and "male" in a:
            out["caveat"] = "sex not given: the union of the male and female ranges was used"
        if age is not None and age < 18:
            out["caveat"] = "adult reference range; paediatric ranges differ"
        if flag.startswith("critical"):
            out["action"] = "critical value: notify the responsible clinician immediately"
        return out

    @is_tool(ToolType.READ)
    def generate_ddx(self, findings: list[str] | None = None, patient_id: str | None = None, top_k: int = 10,
                     scope: Literal["all", "rare", "common"] = "all") -> dict:
        """Rank candidate diseases for a set of phenotypic findings using HPO disease annotations.

        Args:
            findings: Findings as HPO ids ("HP:0001250") or HPO term names ("Seizure"). With a
                patient_id, these are added to the patient's known coded findings.
            patient_id: Optional patient whose known coded findings are used.
            top_k: Number of diseases to return, 1-50.
            scope: "rare" (OMIM/Orphanet/DECIPHER), "common" (the authored common-disease library) or "all".
        """
        if not 1 <= top_k <= 50:
            raise ToolError(f"top_k must be in 1..50, got {top_k}")
        index = knowledge.hpo_index()
        observed: list[str] = []
        if patient_id is not None:
            observed += [f["hpo_id"] for f in self._known_findings(self._patient(patient_id))]
        unresolved = []
        for item in findings or []:
            tid = index.resolve(item)
            if tid is None:
                unresolved.append(item)
            else:
                observed.append(tid)
        if unresolved:
            hints = {u: [f"{t} {index.terms[t]['name']}" for t in index.search(u, 3)] for u in unresolved}
            raise ToolError(f"findings not recognised as HPO terms: {hints} (use lookup_hpo_term)")
        if not observed:
            raise ToolError("no findings: give findings and/or a patient_id with coded findings")
        sources = {"rare": {"OMIM", "ORPHA", "DECIPHER"}, "common": {"authored"}, "all": None}[scope]
        ranked = index.rank(observed, limit=top_k, sources=sources)
        return {"findings_used": [f"{t} {index.terms[t]['name']}" for t in dict.fromkeys(observed)],
                "differential": ranked,
                "method": "IC-weighted HPO annotation match with annotation frequencies (HPO 2025-01-16)"}

    @is_tool(ToolType.READ)
    def lookup_hpo_term(self, query: str, max_results: int = 10) -> list[dict]:
        """Find Human Phenotype Ontology terms by id or by words of the name/synonyms.

        Args:
            query: An HPO id ("HP:0001166") or words ("long fingers").
            max_results: Maximum number of terms, 1-50.
        """
        index = knowledge.hpo_index()
        exact = index.resolve(query)
        hits = ([exact] if exact else []) + [t for t in index.search(query, max_results) if t != exact]
        if not hits:
            raise ToolError(f"no HPO term matches {query!r}")
        return [{"hpo_id": t, "name": index.terms[t]["name"], "synonyms": index.terms[t]["synonyms"][:5],
                 "definition": index.terms[t]["definition"][:300], "annotated_diseases": index.terms[t]["n_diseases"]}
                for t in hits[:max(1, min(max_results, 50))]]

    @is_tool(ToolType.READ)
    def get_disease_phenotypes(self, disease: str, max_results: int = 40) -> dict:
        """Return a disease's phenotype annotations (HPO) with their frequencies, most frequent first.

        Args:
            disease: A disease id ("OMIM:154700", "ORPHA:558", "CD:pneumonia") or an exact disease name.
            max_results: Maximum number of phenotypes, 1-200.
        """
        index = knowledge.hpo_index()
        did = disease.strip() if disease.strip() in index.diseases else index.disease_by_name.get(_fold(disease))
        if did is None:
            raise ToolError(f"disease {disease!r} not found; use the disease_id returned by generate_ddx")
        d = index.diseases[did]
        from .hpo import frequency_label

        rows = sorted(d["phenotypes"], key=lambda hf: -(hf[1] if hf[1] is not None else 0.5))
        return {"disease_id": did, "name": d["name"], "source": d["source"], "icd10": d.get("icd10"),
                "n_phenotypes": len(rows),
                "phenotypes": [{"hpo_id": h, "name": index.terms[h]["name"], "frequency": frequency_label(f)}
                               for h, f in rows[:max(1, min(max_results, 200))]],
                "excluded": [index.terms[h]["name"] for h in d["excluded"]]}

    @is_tool(ToolType.READ)
    def lookup_icd10(self, query: str, max_results: int = 10, billable_only: bool = False) -> dict:
        """Look up ICD-10-CM: a code returns its description, hierarchy and children; text returns matching codes.

        Args:
            query: A code ("E11.21") or words ("type 2 diabetes nephropathy").
            max_results: Maximum number of matches for a text query, 1-50.
            billable_only: Only return billable (valid for claims) codes for a text query.
        """
        index = knowledge.icd10_index()
        query = query.strip()
        if re.fullmatch(r"[A-Za-z]\d[0-9A-Za-z]\.?[0-9A-Za-z]{0,4}", query):
            item = index.get(query)
            if item is None:
                raise ToolError(f"ICD-10-CM code {query!r} does not exist")
            return item
        matches = index.search(query, max(1, min(max_results, 50)), billable_only)
        if not matches:
            raise ToolError(f"no ICD-10-CM code matches all words of {query!r}; try fewer or other words")
        return {"query": query, "matches": matches}

    # -- actions -----------------------------------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def record_diagnosis(self, patient_id: str, icd10_code: str,
                         certainty: Literal["confirmed", "provisional", "differential"] = "provisional") -> dict:
        """Record a diagnosis in the patient's problem list with a billable ICD-10-CM code.

        Args:
            patient_id: The patient identifier.
            icd10_code: A billable ICD-10-CM code, e.g. "J18.9".
            certainty: "confirmed", "provisional" or "differential".
        """
        p = self._patient(patient_id)
        code = normalise_code(icd10_code)
        item = knowledge.icd10_index().get(code)
        if item is None:
            raise ToolError(f"icd10_code {icd10_code!r} does not exist in ICD-10-CM")
        if not item["billable"]:
            kids = ", ".join(c["code"] for c in item["children"][:8])
            raise ToolError(f"icd10_code {code} ({item['description']}) is a header, not billable; pick a child: {kids}")
        if any(d.icd10_code == code for d in p.diagnoses):
            raise ToolError(f"{code} is already recorded for {patient_id}")
        p.diagnoses.append(DiagnosisRecord(icd10_code=code, description=item["description"], certainty=certainty))
        return {"recorded": code, "description": item["description"], "certainty": certainty,
                "problem_list": [d.icd10_code for d in p.diagnoses]}

    @is_tool(ToolType.READ)
    def check_drug_allergy(self, patient_id: str, drug: str) -> dict:
        """Check a drug against the patient's recorded allergies (same drug, same class, cross-reactivity).

        Args:
            patient_id: The patient identifier.
            drug: The drug name (generic or brand).
        """
        p = self._patient(patient_id)
        d = self._drug(drug)
        result = self._allergy_check(p, d)
        return {"drug": d.name, "drug_class": d.drug_class, "safe_to_prescribe": not result["conflicts"], **result}

    @is_tool(ToolType.READ)
    def check_drug_interactions(self, patient_id: str, drug: str) -> dict:
        """Check a proposed drug against the patient's home medications and this encounter's prescriptions:
        ANSM interaction rules (severity and rule) and same-class duplications.

        Args:
            patient_id: The patient identifier.
            drug: The proposed drug (generic or brand name).
        """
        from envs.domains.drug_reference import drug_reference

        p = self._patient(patient_id)
        d = self._drug(drug)
        current = [m.name for m in p.medications] + [x.drug for x in p.prescriptions]
        return {"patient_id": p.patient_id, **drug_reference().interaction_report(d.name, current)}

    @is_tool(ToolType.WRITE)
    def prescribe_medication(self, patient_id: str, drug: str, dose_mg: float,
                             route: str, frequency: str, duration_days: int | None = None,
                             indication: str = "") -> dict:
        """Prescribe a drug after checking allergies and the usual maximum single and daily dose.

        Args:
            patient_id: The patient identifier.
            drug: Drug name (generic or brand).
            dose_mg: Dose per administration in mg (insulin and heparin: units).
            route: Route, e.g. "oral", "intravenous", "subcutaneous".
            frequency: One of once, daily, bid, tid, qid, q4h, q6h, q8h, q12h, q24h, nightly, weekly, prn.
            duration_days: Planned duration in days.
            indication: What the drug treats.
        """
        p = self._patient(patient_id)
        d = self._drug(drug)
        if dose_mg <= 0:
            raise ToolError(f"dose_mg must be positive, got {dose_mg}")
        freq = _fold(frequency).replace(" ", "")
        if freq not in FREQUENCY_PER_DAY:
            raise ToolError(f"frequency {frequency!r} not recognised; use one of {', '.join(FREQUENCY_PER_DAY)}")
        if _fold(route) not in {_fold(r) for r in d.routes}:
            raise ToolError(f"route {route!r} is not available for {d.name}; routes: {', '.join(d.routes)}")
        allergy = self._allergy_check(p, d)
        if allergy["conflicts"]:
            c = allergy["conflicts"][0]
            raise ToolError(f"allergy: {p.patient_id} is allergic to {c['allergy']} ({c['reaction'] or c['severity']}); "
                            f"{d.name} shares {', '.join(c['shared_group'])}. Choose an alternative.")
        if d.max_single_dose_mg is not None and dose_mg > d.max_single_dose_mg:
            raise ToolError(f"dose_mg {dose_mg:g} exceeds the maximum single dose of {d.name} ({d.max_single_dose_mg:g} mg)")
        per_day = FREQUENCY_PER_DAY[freq]
        if d.max_daily_dose_mg is not None and per_day and dose_mg * per_day > d.max_daily_dose_mg:
            raise ToolError(f"daily dose {dose_mg * per_day:g} mg exceeds the maximum daily dose of {d.name} "
                            f"({d.max_daily_dose_mg:g} mg)")
        if any(_fold(x.drug) == _fold(d.name) for x in p.prescriptions):
            raise ToolError(f"{d.name} is already prescribed for {patient_id}")
        rx_id = f"RX-{p.patient_id}-{len(p.prescriptions) + 1}"
        p.prescriptions.append(Prescription(prescription_id=rx_id, drug=d.name, dose=f"{dose_mg:g} mg", route=_fold(route),
                                            frequency=freq, duration_days=duration_days, indication=indication))
        out = {"prescription_id": rx_id, "drug": d.name, "drug_class": d.drug_class, "dose_mg": dose_mg,
               "route": route, "frequency": freq, "status": "prescribed"}
        if allergy["warnings"]:
            out["warnings"] = allergy["warnings"]
        return out

    @is_tool(ToolType.READ)
    def get_medication_list(self, patient_id: str) -> dict:
        """Return the patient's home medications and the prescriptions written in this encounter.

        Args:
            patient_id: The patient identifier.
        """
        p = self._patient(patient_id)
        return {"home_medications": [m.model_dump() for m in p.medications],
                "prescriptions": [x.model_dump() for x in p.prescriptions],
                "allergies": [a.model_dump() for a in p.allergies]}

    @is_tool(ToolType.WRITE)
    def write_clinical_note(self, patient_id: str, note_type: Literal["progress", "consult", "admission", "discharge",
                                                                      "procedure"], content: str) -> dict:
        """Write a note into the patient's chart.

        Args:
            patient_id: The patient identifier.
            note_type: "progress", "consult", "admission", "discharge" or "procedure".
            content: The note text (assessment and plan).
        """
        p = self._patient(patient_id)
        if len(content.strip()) < 20:
            raise ToolError("content is too short for a clinical note (at least 20 characters)")
        note_id = f"NOTE-{p.patient_id}-{len(p.notes) + 1}"
        p.notes.append(ClinicalNote(note_id=note_id, note_type=note_type, content=content.strip()))
        return {"note_id": note_id, "note_type": note_type, "characters": len(content.strip())}

    @is_tool(ToolType.WRITE)
    def escalate_care(self, patient_id: str, reason: str,
                      team: Literal["rapid_response", "icu", "cardiology", "surgery", "endocrinology",
                                    "nephrology", "other"] = "rapid_response") -> dict:
        """Escalate an unstable or emergency patient to a senior team now (recorded in the chart).

        Args:
            patient_id: The patient identifier.
            reason: The emergency, e.g. "critical potassium 7.1 with ECG changes".
            team: The team called: rapid_response, icu, cardiology, surgery, endocrinology, nephrology, other.
        """
        p = self._patient(patient_id)
        if len(reason.strip()) < 5:
            raise ToolError("reason must say what the emergency is")
        note_id = f"NOTE-{p.patient_id}-{len(p.notes) + 1}"
        p.notes.append(ClinicalNote(note_id=note_id, note_type="escalation", content=f"Escalated to {team}: {reason.strip()}"))
        return {"escalated_to": team, "reason": reason.strip(), "note_id": note_id, "time": self._clock()}

    @is_tool(ToolType.WRITE)
    def schedule_follow_up(self, patient_id: str, service: str, within_days: int, reason: str) -> dict:
        """Book a follow-up appointment (a clinic, a specialty or primary care) within a number of days; recorded in the chart.

        Args:
            patient_id: The patient identifier.
            service: Who sees the patient, e.g. "gynaecology", "primary care", "cardiology clinic".
            within_days: Within how many days, 1-365.
            reason: What the follow-up is for, e.g. "repeat haemoglobin after 4 weeks of iron".
        """
        p = self._patient(patient_id)
        if not 1 <= within_days <= 365:
            raise ToolError(f"within_days must be 1-365, got {within_days}")
        if len(service.strip()) < 3:
            raise ToolError("service must name the clinic or specialty")
        if len(reason.strip()) < 5:
            raise ToolError("reason must say what the follow-up is for")
        appointment = FollowUp(appointment_id=f"FU-{p.patient_id}-{len(p.follow_ups) + 1}", service=service.strip(),
                               within_days=within_days, reason=reason.strip())
        p.follow_ups.append(appointment)
        return {**appointment.model_dump(), "by_date": self._clock(within_days * 24 * 60)[:10]}

    @is_tool(ToolType.READ)
    def get_clinical_notes(self, patient_id: str) -> dict:
        """Return the notes in the patient's chart and the recorded diagnoses.

        Args:
            patient_id: The patient identifier.
        """
        p = self._patient(patient_id)
        return {"notes": [n.model_dump() for n in p.notes], "diagnoses": [d.model_dump() for d in p.diagnoses],
                "follow_ups": [f.model_dump() for f in p.follow_ups]}
