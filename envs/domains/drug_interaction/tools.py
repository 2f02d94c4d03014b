"""The drug-interaction toolkit: every tool computes its answer from the database.

Names follow the reward's tool conventions (`envs/rewards/conventions.py`): `check_patient_interactions`
covers the whole medication list, `add_medication` prescribes, `discontinue_medication` stops,
arguments are called `drug`, `dose`, `route`, `patient_id`.
"""

from __future__ import annotations

from typing import Literal

from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool

from . import logic as L
from .data_model import DrugInteractionDB, MedicationChange, MedicationOrder, Patient
from .translate import SEVERITY_RANK


def _fail(exc: Exception) -> ToolError:
    return ToolError(str(exc))


class DrugInteractionTools(BaseDomainTools):
    """Pharmacovigilance tools over the ANSM thesaurus, dose, renal, hepatic and pregnancy data."""

    db: DrugInteractionDB

    # -- helpers -----------------------------------------------------------------------------------
    def _patient(self, patient_id: str) -> Patient:
        try:
            return L.get_patient(self.db, patient_id)
        except L.LookupFailure as exc:
            raise _fail(exc) from None

    def _drug(self, name: str):
        try:
            return L.resolve_drug(self.db, name)
        except L.LookupFailure as exc:
            raise _fail(exc) from None

    def _party(self, name: str):
        try:
            return L.resolve_party(self.db, name)[1]
        except L.LookupFailure as exc:
            raise _fail(exc) from None

    def _med_view(self, patient: Patient) -> list[dict]:
        return [{"drug": m.drug_id, "dose": m.dose, "unit": m.unit, "route": m.route, "frequency": m.frequency,
                 "indication": m.indication, "status": m.status} for m in patient.medications]

    # -- patient -----------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_patient_details(self, patient_id: str) -> dict:
        """Get a patient's demographics, renal and hepatic status, pregnancy status, conditions and allergies.

        Args:
            patient_id: The patient identifier, e.g. "P001".
        """
        p = self._patient(patient_id)
        return {
            "patient_id": p.patient_id, "name": p.name, "age": p.age, "sex": p.sex, "weight_kg": p.weight_kg,
            "height_cm": p.height_cm, "serum_creatinine_mg_dl": p.serum_creatinine_mg_dl,
            "child_pugh_class": p.child_pugh_class or "none (no chronic liver disease)",
            "pregnant": p.pregnant, "gestational_age_weeks": p.gestational_age_weeks, "breastfeeding": p.breastfeeding,
            "conditions": p.conditions,
            "allergies": [{"allergen": a.allergen, "type": a.kind, "reaction": a.reaction, "severity": a.severity}
                          for a in p.allergies] or "no known drug allergies",
            "active_medication_count": len(p.active_medications()), "notes": p.notes,
        }

    @is_tool(ToolType.READ)
    def get_patient_medications(self, patient_id: str) -> dict:
        """Get a patient's medication list (generic names, doses, routes, frequencies, status).

        Args:
            patient_id: The patient identifier, e.g. "P001".
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "medications": self._med_view(p),
                "active": [m.drug_id for m in p.active_medications()]}

    @is_tool(ToolType.READ)
    def check_allergy(self, patient_id: str, drug: str) -> dict:
        """Check a drug against a patient's recorded allergies (same drug, allergy to its class, listed cross-reactions).

        Args:
            patient_id: The patient identifier.
            drug: Generic or brand name of the drug to check.
        """
        p, d = self._patient(patient_id), self._drug(drug)
        conflicts = L.allergy_conflicts(self.db, p, d)
        # Key names avoid warning words when nothing conflicts, so a clean check reads as clean.
        return {"patient_id": p.patient_id, "drug": d.id, "conflict": bool(conflicts), "matches": conflicts,
                "chart_entries_checked": len(p.allergies)}

    # -- drugs and classes -------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def lookup_drug(self, name: str) -> dict:
        """Look up a drug by generic, brand or French name: its generic name, classes and available data.

        Args:
            name: A generic name ("warfarin"), brand name ("Coumadin") or ANSM French name ("warfarine").
        """
        d = self._drug(name)
        return {
            "query": name, "generic_name": d.id, "display_name": d.name,
            "brand_names": d.brand_names[:15], "other_names": d.synonyms[:15],
            "ansm_names_fr": d.names_fr,
            "classes": [{"id": c, "name": self.db.classes[c].name, "therapeutic": self.db.classes[c].therapeutic}
                        for c in d.class_ids],
            "descriptive_classes": d.descriptive_classes,
            "drugbank_id": d.drugbank_id, "mesh_id": d.mesh_id,
            "data_available": {"ansm_interactions": bool(d.names_fr), "dose_ranges": d.id in self.db.dose_profiles,
                               "renal_dosing": d.id in self.db.renal_profiles,
                               "pregnancy_category": bool(self.db.dose_profiles.get(d.id) and
                                                          self.db.dose_profiles[d.id].pregnancy_category)},
        }

    @is_tool(ToolType.READ)
    def get_class_members(self, drug_class: str) -> dict:
        """List the drugs in an ANSM drug class (class rules of the thesaurus apply to every member).

        Args:
            drug_class: English class name or id ("vitamin K antagonists", "penicillins") or French ANSM label.
        """
        try:
            cls = L.resolve_class(self.db, drug_class)
        except L.LookupFailure as exc:
            raise _fail(exc) from None
        return {"class_id": cls.id, "name": cls.name, "name_fr": cls.name_fr, "therapeutic": cls.therapeutic,
                "complements_class": self.db.classes[cls.other_of].name if cls.other_of else None,
                "members": cls.members, "members_without_english_match_fr": cls.unmatched_members_fr,
                "interaction_rules": len(self.db.party_index.get(f"class:{cls.id}", []))}

    @is_tool(ToolType.READ)
    def search_drug_classes(self, query: str) -> dict:
        """Find ANSM drug classes whose English or French name contains all the words of a query.

        Args:
            query: Words to look for, e.g. "statin", "beta-blockers", "serotonin".
        """
        hits = L.search_classes(self.db, query)
        return {"query": query, "classes": [{"id": c.id, "name": c.name, "members": len(c.members),
                                             "therapeutic": c.therapeutic} for c in hits[:25]],
                "total": len(hits)}

    # -- interactions ------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def check_interaction(self, drugs: list[str]) -> dict:
        """Check a pair of drugs (or a drug and grapefruit/alcohol): ANSM thesaurus rules (class-level included) and the
        US overlay, whose FDA-label level is the pair's severity where it has one.

        Args:
            drugs: Exactly two names, in any order: generic or brand names, or a non-drug party such as
                "grapefruit" or "alcohol", e.g. ["warfarin", "ibuprofen"].
        """
        if len(drugs) != 2:
            raise ToolError(f"give exactly two names in 'drugs', got {len(drugs)}: {drugs}")
        a, b = self._party(drugs[0]), self._party(drugs[1])
        if a.id == b.id:
            raise ToolError(f"{drugs[0]!r} and {drugs[1]!r} are the same drug ({a.id}); give two different drugs")
        return L.pair_report(self.db, a, b)

    @is_tool(ToolType.READ)
    def get_interaction_rule(self, rule_id: str) -> dict:
        """Get the full rule (ANSM or US overlay): parties, every severity level with its conditions, mechanism, evidence, provenance.

        Args:
            rule_id: A rule id returned by an interaction check, e.g. "ANSM-0177" or "US-001".
        """
        rule = self.db.interactions.get(rule_id.strip().upper())
        if rule is None:
            ansm = sum(1 for r in self.db.interactions.values() if r.source == "ansm")
            raise ToolError(f"interaction rule {rule_id!r} not found; rule ids look like ANSM-0001 .. ANSM-{ansm:04d} "
                            f"(ANSM thesaurus) or US-001, US-R01 (US overlay)")
        return rule.model_dump(mode="json")

    @is_tool(ToolType.READ)
    def check_patient_interactions(self, patient_id: str, drug: str | None = None) -> dict:
        """Check every pair in a patient's active medication list, plus a proposed new drug against each of them.

        Args:
            patient_id: The patient identifier.
            drug: Optional proposed drug to add (generic or brand name).
        """
        p = self._patient(patient_id)
        proposed = self._drug(drug) if drug else None
        findings = L.medication_list_findings(self.db, p, proposed)
        out = {
            "patient_id": p.patient_id, "active_medications": [m.drug_id for m in p.active_medications()],
            "proposed_drug": proposed.id if proposed else None,
            "interacting_pairs": [{"drug_a": f.drug_a, "drug_b": f.drug_b, "severity_level": f.severity_level,
                                   "rule_ids": list(f.rule_ids), "involves_proposed_drug": f.involves_proposed,
                                   "conditional_levels": f.multi_level} for f in findings],
            "pair_count": len(findings),
            "highest_severity": L.max_severity(f.severity_level for f in findings),
        }
        if proposed is not None:
            mine = [f for f in findings if f.involves_proposed]
            out["highest_severity_with_proposed_drug"] = L.max_severity(f.severity_level for f in mine)
            blocking = sorted(f.drug_b for f in mine if f.severity_level == "contraindicated")
            # present only when non-empty: an empty "contraindicated" list next to a drug name reads as a warning
            if blocking:
                out["contraindicated_with_proposed_drug"] = blocking
            allergy = L.allergy_conflicts(self.db, p, proposed)
            if allergy:
                out["allergy_conflicts_of_proposed_drug"] = allergy
        return out

    @is_tool(ToolType.READ)
    def find_safer_alternatives(self, drug: str, patient_id: str, drug_class: str | None = None) -> dict:
        """Rank drugs of the same therapeutic class by their worst interaction with the patient's other medications.

        Args:
            drug: The drug to replace (generic or brand name).
            patient_id: The patient identifier.
            drug_class: Optional class to search instead of the drug's own therapeutic classes.
        """
        p, d = self._patient(patient_id), self._drug(drug)
        within = None
        if drug_class:
            try:
                within = L.resolve_class(self.db, drug_class)
            except L.LookupFailure as exc:
                raise _fail(exc) from None
        elif not any(self.db.classes[c].therapeutic for c in d.class_ids):
            raise ToolError(f"{d.id} has no therapeutic ANSM class to search; give drug_class "
                            "(search_drug_classes finds one)")
        result = L.alternatives(self.db, d, p, within)
        result["safer_alternatives"] = result["safer_alternatives"][:10]
        result["other_candidates"] = result["other_candidates"][:10]
        return result

    # -- dosing ------------------------------------------------------------------------------------
    def _weight_age(self, weight_kg: float | None, patient_id: str | None) -> tuple[float | None, float | None]:
        if patient_id:
            p = self._patient(patient_id)
            return (weight_kg if weight_kg is not None else p.weight_kg), p.age
        return weight_kg, None

    def _dose_profile(self, drug):
        profile = self.db.dose_profiles.get(drug.id)
        if profile is None:
            raise ToolError(f"no dose range for {drug.id} in the formulary (drugdose covers "
                            f"{len(self.db.dose_profiles)} emergency drugs: {', '.join(list(self.db.dose_profiles)[:12])}, ...)")
        return profile

    @is_tool(ToolType.READ)
    def get_dose_range(self, drug: str, route: str | None = None, weight_kg: float | None = None,
                       patient_id: str | None = None) -> dict:
        """Get a drug's dose range per route; with a weight (or patient), the absolute range and max single dose.

        Args:
            drug: Generic or brand name.
            route: Route such as "IV", "IM", "PO", "IN", "IV_DRIP"; all routes when omitted.
            weight_kg: Body weight for weight-based doses.
            patient_id: A patient whose weight (and age, for paediatric caps) to use.
        """
        d = self._drug(drug)
        profile = self._dose_profile(d)
        weight, age = self._weight_age(weight_kg, patient_id)
        try:
            routes = [L.find_route(profile, route)] if route else profile.routes
            ranges = []
            for r in routes:
                if r.per_kg and weight is None:
                    ranges.append({"route": r.route, "dose_per_kg": f"{r.dose_min}-{r.dose_max} {r.dose_unit}",
                                   "max_single_dose_cap": r.max_single_dose, "cap_unit": r.cap_unit,
                                   "frequency": r.frequency, "note": "give weight_kg or patient_id for absolute doses"})
                else:
                    ranges.append(L.dose_range(r, weight, age))
        except (L.LookupFailure, ValueError) as exc:
            raise _fail(exc) from None
        return {"drug": d.id, "weight_kg": weight, "age_years": age, "ranges": ranges,
                "indication": profile.indication, "contraindications": profile.contraindications,
                "source": profile.provenance[0].model_dump()}

    @is_tool(ToolType.READ)
    def check_dose(self, drug: str, dose: float, unit: str, route: str, weight_kg: float | None = None,
                   patient_id: str | None = None) -> dict:
        """Check a single dose against the drug's range for the route and weight (below, within, above, over the cap).

        Args:
            drug: Generic or brand name.
            dose: The dose amount, e.g. 5.
            unit: Its unit: "mg", "mcg", "g", "units", "mEq", or a rate such as "mcg/min".
            route: Route such as "IV", "IM", "PO", "IN", "IV_DRIP".
            weight_kg: Body weight for weight-based doses.
            patient_id: A patient whose weight (and age) to use.
        """
        d = self._drug(drug)
        profile = self._dose_profile(d)
        weight, age = self._weight_age(weight_kg, patient_id)
        try:
            result = L.dose_check(L.find_route(profile, route), dose, unit, weight, age)
        except (L.LookupFailure, ValueError) as exc:
            raise _fail(exc) from None
        return {"drug": d.id, "weight_kg": weight, "age_years": age, "dose": dose, "unit": unit, **result}

    # -- organ function and pregnancy ----------------------------------------------------------------
    @is_tool(ToolType.READ)
    def calculate_renal_function(self, patient_id: str) -> dict:
        """Compute a patient's creatinine clearance (Cockcroft-Gault) and eGFR (CKD-EPI 2021).

        Args:
            patient_id: The patient identifier.
        """
        p = self._patient(patient_id)
        return {"patient_id": p.patient_id, "age": p.age, "sex": p.sex, "weight_kg": p.weight_kg,
                "serum_creatinine_mg_dl": p.serum_creatinine_mg_dl,
                "creatinine_clearance_ml_min": L.cockcroft_gault(p),
                "egfr_ml_min_1_73m2": L.ckd_epi_2021(p),
                "methods": {"creatinine_clearance": "Cockcroft-Gault, actual body weight, x0.85 if female",
                            "egfr": "CKD-EPI 2021 creatinine (race-free)"}}

    @is_tool(ToolType.READ)
    def get_renal_dose_adjustment(self, drug: str, renal_value: float | None = None,
                                  metric: Literal["crcl", "egfr"] | None = None, patient_id: str | None = None) -> dict:
        """Get the renal dose adjustment for a drug at a given renal function (or the patient's own).

        Args:
            drug: Generic or brand name.
            renal_value: Creatinine clearance (mL/min) or eGFR (mL/min/1.73 m2); omit to use the patient's.
            metric: "crcl" or "egfr"; defaults to the metric the drug's label uses.
            patient_id: A patient whose renal function to compute when renal_value is omitted.
        """
        d = self._drug(drug)
        profile = self.db.renal_profiles.get(d.id)
        if profile is None:
            return {"drug": d.id, "adjustment_type": "no_data",
                    "note": "no renal dosing table for this drug in the formulary sources",
                    "drugs_with_renal_tables": sorted(self.db.renal_profiles)}
        used = metric or profile.metric
        if renal_value is None:
            if not patient_id:
                raise ToolError("give renal_value (with metric) or patient_id")
            p = self._patient(patient_id)
            renal_value = L.cockcroft_gault(p) if used == "crcl" else L.ckd_epi_2021(p)
        try:
            tier = L.renal_tier(profile, renal_value)
        except ValueError as exc:
            raise _fail(exc) from None
        out = {"drug": d.id, "renal_value": renal_value, "metric": used, "label_metric": profile.metric,
               "normal_dose": profile.normal_dose, "adjustment_type": tier["adjustment_type"],
               "recommended_dose": tier["dose"], "tier": {"min": tier["min"], "max": tier["max"]},
               "dialysis_note": tier["dialysis_note"], "warnings": tier["warnings"],
               "requires_tdm": profile.requires_tdm, "monitoring": profile.monitoring,
               "evidence": profile.source_description, "doi": profile.source_doi,
               "source": profile.provenance[0].model_dump()}
        if "label_rule" in tier:  # the package's tier word differs from the US label's
            out.update(label_rule=tier["label_rule"], source_adjustment_type=tier["source_adjustment_type"],
                       source_recommended_dose=tier["source_dose"])
        if used != profile.metric:
            out["metric_note"] = (f"the label for {d.id} uses {profile.metric}; {used} was given and may differ "
                                  "in elderly, obese or malnourished patients")
        return out

    @is_tool(ToolType.READ)
    def check_hepatic_adjustment(self, drug: str, child_pugh_class: Literal["A", "B", "C"] | None = None,
                                 patient_id: str | None = None) -> dict:
        """Check hepatic cautions for a drug and its recommendation for a Child-Pugh class (or the patient's):
        the drug's US-label rule where the formulary has one, else the default convention for flagged drugs.

        Args:
            drug: Generic or brand name.
            child_pugh_class: "A", "B" or "C"; omit for no liver disease or to use the patient's.
            patient_id: A patient whose Child-Pugh class to use.
        """
        d = self._drug(drug)
        if child_pugh_class is None and patient_id:
            child_pugh_class = self._patient(patient_id).child_pugh_class  # type: ignore[assignment]
        result = L.hepatic_assessment(self.db, d, child_pugh_class)
        result["default_convention"] = {"no liver disease": "no_adjustment", "A": "use_with_caution",
                                        "B": "reduce_dose_and_monitor", "C": "avoid_or_specialist_review",
                                        "applies_to": "drugs with a hepatic caution flag in drugdose or open-medicine "
                                                      "and no drug-specific label rule"}
        return result

    @is_tool(ToolType.READ)
    def check_pregnancy_safety(self, drug: str, patient_id: str | None = None) -> dict:
        """Get a drug's pregnancy conclusion: its US label's risk summary and section where the formulary has it (a letter only with its date), else the FDA letter category from package data, and the patient's pregnancy status.

        Args:
            drug: Generic or brand name.
            patient_id: Optional patient, to report pregnancy and gestational age.
        """
        d = self._drug(drug)
        result = L.pregnancy_assessment(self.db, d)
        if patient_id:
            p = self._patient(patient_id)
            result["patient"] = {"patient_id": p.patient_id, "pregnant": p.pregnant,
                                 "gestational_age_weeks": p.gestational_age_weeks, "breastfeeding": p.breastfeeding}
        return result

    # -- writes ------------------------------------------------------------------------------------
    def _log(self, patient: Patient, action: str, drug_id: str, details: dict, reason: str) -> str:
        change_id = f"CHG-{len(self.db.medication_changes) + 1:04d}"
        self.db.medication_changes.append(MedicationChange(change_id=change_id, patient_id=patient.patient_id,
                                                           action=action, drug_id=drug_id, details=details, reason=reason))
        return change_id

    def _active(self, patient: Patient, drug_id: str) -> MedicationOrder | None:
        return next((m for m in patient.active_medications() if m.drug_id == drug_id), None)

    def _dose_guard(self, drug, dose: float, unit: str, route: str, patient: Patient) -> dict | None:
        profile = self.db.dose_profiles.get(drug.id)
        if profile is None:
            return None
        try:
            result = L.dose_check(L.find_route(profile, route), dose, unit, patient.weight_kg, patient.age)
        except (L.LookupFailure, ValueError):
            return None
        if result["status"] == "exceeds_max_single_dose":
            raise ToolError(f"blocked: {dose} {unit} {route} {drug.id} exceeds the maximum single dose "
                            f"({result['max_single_dose_cap']} {result['unit']}); order not recorded")
        return result

    @is_tool(ToolType.WRITE)
    def add_medication(self, patient_id: str, drug: str, dose: float, unit: str, route: str, frequency: str,
                       indication: str = "") -> dict:
        """Prescribe a drug: add it to the patient's active list. Blocked on an allergy, a contraindicated combination or an overdose.

        Args:
            patient_id: The patient identifier.
            drug: Generic or brand name.
            dose: Dose amount per administration.
            unit: Dose unit ("mg", "mcg", "g", "units").
            route: Route ("PO", "IV", "IM", "SC", "INH", ...).
            frequency: How often, e.g. "once daily".
            indication: Why it is prescribed.
        """
        p, d = self._patient(patient_id), self._drug(drug)
        if dose <= 0:
            raise ToolError(f"dose must be positive, got {dose}")
        if not unit.strip() or not route.strip() or not frequency.strip():
            raise ToolError("unit, route and frequency are required")
        if self._active(p, d.id):
            raise ToolError(f"{d.id} is already on {p.patient_id}'s active list; use adjust_medication_dose")
        conflicts = [c for c in L.allergy_conflicts(self.db, p, d) if c["match"] != "cross-reaction listed by drugdose"]
        if conflicts:
            raise ToolError(f"blocked: {p.patient_id} is allergic to {conflicts[0]['allergen']} "
                            f"({conflicts[0]['match']}, {conflicts[0]['reaction']}); order not recorded")
        # dose-conditional levels are evaluated at this order's daily dose (aspirin 81 mg daily with apixaban)
        findings = [f for f in L.medication_list_findings(self.db, p, d, L.daily_dose_mg(dose, unit, frequency))
                    if f.involves_proposed]
        contraindicated = [f for f in findings if f.severity_level == "contraindicated"]
        if contraindicated:
            f = contraindicated[0]
            raise ToolError(f"blocked: {d.id} + {f.drug_b} is contraindicated ({', '.join(f.rule_ids)}); "
                            f"stop {f.drug_b} first or choose an alternative; order not recorded")
        dose_result = self._dose_guard(d, dose, unit, route, p)
        p.medications.append(MedicationOrder(drug_id=d.id, dose=dose, unit=unit, route=route, frequency=frequency,
                                             indication=indication or None))
        change_id = self._log(p, "add", d.id, {"dose": dose, "unit": unit, "route": route, "frequency": frequency}, indication)
        return {"status": "recorded", "change_id": change_id, "patient_id": p.patient_id, "drug": d.id,
                "warnings": [{"with": f.drug_b, "severity_level": f.severity_level, "rule_ids": list(f.rule_ids)}
                             for f in sorted(findings, key=lambda f: -SEVERITY_RANK[f.severity_level])],
                "dose_check": dose_result["status"] if dose_result else "no dose range available"}

    @is_tool(ToolType.WRITE)
    def discontinue_medication(self, patient_id: str, drug: str, reason: str) -> dict:
        """Stop one of the patient's active medications.

        Args:
            patient_id: The patient identifier.
            drug: Generic or brand name of the active medication.
            reason: Why it is stopped.
        """
        p, d = self._patient(patient_id), self._drug(drug)
        order = self._active(p, d.id)
        if order is None:
            raise ToolError(f"{d.id} is not an active medication of {p.patient_id}; active: "
                            f"{', '.join(m.drug_id for m in p.active_medications()) or 'none'}")
        if not reason.strip():
            raise ToolError("a reason is required to discontinue a medication")
        order.status = "discontinued"
        change_id = self._log(p, "discontinue", d.id, {}, reason)
        return {"status": "discontinued", "change_id": change_id, "patient_id": p.patient_id, "drug": d.id,
                "active_medications": [m.drug_id for m in p.active_medications()]}

    @is_tool(ToolType.WRITE)
    def adjust_medication_dose(self, patient_id: str, drug: str, dose: float, unit: str, reason: str,
                               frequency: str | None = None) -> dict:
        """Change the dose (and optionally the frequency) of an active medication; blocked above the maximum single dose.

        Args:
            patient_id: The patient identifier.
            drug: Generic or brand name of the active medication.
            dose: New dose amount per administration.
            unit: Dose unit.
            reason: Why the dose changes (e.g. "CrCl 25 mL/min").
            frequency: New frequency, e.g. "twice daily"; unchanged when omitted.
        """
        p, d = self._patient(patient_id), self._drug(drug)
        order = self._active(p, d.id)
        if order is None:
            raise ToolError(f"{d.id} is not an active medication of {p.patient_id}")
        if dose <= 0:
            raise ToolError(f"dose must be positive, got {dose}")
        if not reason.strip():
            raise ToolError("a reason is required to change a dose")
        self._dose_guard(d, dose, unit, order.route, p)
        before = {"dose": order.dose, "unit": order.unit, "frequency": order.frequency}
        order.dose, order.unit = dose, unit
        if frequency and frequency.strip():
            order.frequency = frequency.strip()
        after = {"dose": order.dose, "unit": order.unit, "frequency": order.frequency}
        change_id = self._log(p, "dose_change", d.id, {"from": before, "to": after}, reason)
        return {"status": "dose changed", "change_id": change_id, "patient_id": p.patient_id, "drug": d.id,
                "from": before, "to": after}
