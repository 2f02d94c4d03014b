"""Radiology-report tools: worklist and study review, derived measurements, prior comparison, the
ACR classification systems (`envs.calculators`, filled from the study's findings), templates, and
the report lifecycle (draft, critical-result communication, finalisation)."""

from __future__ import annotations

import re
from typing import Literal

from envs.calculators import CALCULATORS
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool
from envs.domains.imaging_guidelines import KNOWN_MALIGNANCY_MANAGEMENT
from envs.domains.radiology_report.data_model import CriticalCommunication, Finding, RadiologyDB, Report, Study

SYSTEM_OF = {"thyroid": "ACR TI-RADS", "breast": "BI-RADS", "CT": "Fleischner 2017", "LDCT": "Lung-RADS v2022"}


def mean_diameter(long_mm: float, short_mm: float) -> float:
    """Mean of long and short axis, to 0.1 mm (Lung-RADS convention)."""
    return round((long_mm + short_mm) / 2.0 + 1e-9, 1)


_FLEISCHNER = ("no routine follow-up", "optional CT at 12 months", "CT at 6-12 months", "CT at 3-6 months",
               "CT at 3 months, PET/CT or tissue sampling")
# A staging CT's report recommends oncologic follow-up instead (Fleischner 2017 excludes known malignancy).
_FLEISCHNER += (KNOWN_MALIGNANCY_MANAGEMENT,)


def normalise_category(system: str, text: str) -> str | None:
    """The canonical spelling of an assessment ("tr 4" -> "TR4", "4b" -> "BI-RADS 4B"), or None."""
    t = " ".join(text.strip().split())
    if system == "ACR TI-RADS":
        m = re.match(r"(?i)^(?:acr\s*)?(?:ti-?rads\s*)?tr\s*([1-5])$", t)
        return f"TR{m.group(1)}" if m else None
    if system == "BI-RADS":
        m = re.match(r"(?i)^(?:bi-?rads\s*)?(?:category\s*)?([0-6][abc]?)$", t)
        return f"BI-RADS {m.group(1).upper()}" if m else None
    if system == "Lung-RADS v2022":
        m = re.match(r"(?i)^(?:lung-?rads\s*)?(?:v?2022\s*)?(?:category\s*)?([0-4][abx]?s?)$", t)
        return f"Lung-RADS {m.group(1).upper()}" if m else None
    for option in _FLEISCHNER:
        if t.lower() == option.lower():
            return option
    return None


def template_key(study: Study) -> str:
    if study.region == "chest":
        return "LDCT chest" if study.modality == "LDCT" else "CT chest"
    return f"{study.modality} {study.region}"


class RadiologyTools(BaseDomainTools):
    db: RadiologyDB

    def _study(self, study_id: str) -> Study:
        sid = (study_id or "").strip().upper()
        if sid not in self.db.studies:
            raise ToolError(f"study {study_id!r} not found; ids look like {min(self.db.studies)} ({len(self.db.studies)} studies)")
        return self.db.studies[sid]

    def _finding(self, study: Study, finding_id: str | None, kinds: tuple[str, ...]) -> Finding:
        candidates = [f for f in study.findings if f.kind in kinds]
        if not candidates:
            raise ToolError(f"study {study.study_id} has no {' or '.join(kinds)} finding")
        if finding_id is None:
            if len(candidates) > 1:
                raise ToolError(f"study {study.study_id} has {len(candidates)} such findings "
                                f"({', '.join(f.finding_id for f in candidates)}); give 'finding_id'")
            return candidates[0]
        for f in candidates:
            if f.finding_id.lower() == finding_id.strip().lower():
                return f
        raise ToolError(f"finding {finding_id!r} not in {study.study_id}; findings: {', '.join(f.finding_id for f in candidates)}")

    # -- worklist and study ---------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def list_worklist(self, region: Literal["thyroid", "breast", "chest"] | None = None, limit: int = 20) -> dict:
        """List studies awaiting a final report (urgent first), optionally for one body region.

        Args:
            region: "thyroid", "breast" or "chest".
            limit: Maximum number of studies (1-100).
        """
        if not 1 <= limit <= 100:
            raise ToolError("argument 'limit' must be between 1 and 100")
        rows = [s for s in self.db.studies.values() if (region is None or s.region == region)
                and (s.study_id not in self.db.reports or self.db.reports[s.study_id].status != "final")]
        rows.sort(key=lambda s: (s.priority != "urgent", s.study_id))
        return {"count": len(rows), "studies": [{"study_id": s.study_id, "exam": s.exam, "priority": s.priority,
                                                  "report_status": self.db.reports[s.study_id].status if s.study_id in self.db.reports else "unread"}
                                                 for s in rows[:limit]]}

    @is_tool(ToolType.READ)
    def get_study(self, study_id: str) -> dict:
        """Return a study's exam, indication, technique, priority, completeness, prior study and findings as recorded.

        Args:
            study_id: Study identifier, e.g. "RAD-104".
        """
        s = self._study(study_id)
        return {"study_id": s.study_id, "exam": s.exam, "modality": s.modality, "region": s.region, "indication": s.indication,
                "technique": s.technique, "priority": s.priority, "exam_complete": s.exam_complete,
                "known_biopsy_proven_malignancy": s.known_biopsy_proven_malignancy,
                "prior_study": {"study_id": s.prior.study_id, "months_ago": s.prior.months_ago} if s.prior else None,
                "findings": [f.model_dump(exclude_none=True, exclude_defaults=True) | {"finding_id": f.finding_id, "kind": f.kind}
                             for f in s.findings]}

    @is_tool(ToolType.READ)
    def get_patient_history(self, study_id: str) -> dict:
        """Return the patient's age, sex, relevant history, smoking and lung-cancer risk factors.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        return {"study_id": s.study_id, **s.patient.model_dump()}

    @is_tool(ToolType.READ)
    def analyze_findings(self, study_id: str) -> dict:
        """Summarise the findings with derived measurements (maximum diameter, mean diameter, solid component) and the applicable ACR system.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        rows = []
        for f in s.findings:
            row = {"finding_id": f.finding_id, "kind": f.kind, "location": f.location}
            if f.kind == "thyroid_nodule" and f.dimensions_cm:
                row["max_diameter_cm"] = round(max(f.dimensions_cm), 2)
                row["features"] = {k: getattr(f, k) for k in ("composition", "echogenicity", "shape", "margin", "echogenic_foci")}
            elif f.kind == "lung_nodule" and f.long_axis_mm is not None:
                row["nodule_type"] = f.nodule_type
                row["mean_diameter_mm"] = mean_diameter(f.long_axis_mm, f.short_axis_mm)
                row["mean_diameter_rounded_mm"] = int((f.long_axis_mm + f.short_axis_mm) / 2 + 0.5)
                if f.solid_long_mm is not None:
                    row["solid_component_mean_mm"] = mean_diameter(f.solid_long_mm, f.solid_short_mm)
                if f.suspicious_features:
                    row["suspicious_features"] = f.suspicious_features
            elif f.kind.startswith("breast"):
                row["features"] = {k: v for k, v in {"mass_shape": f.mass_shape, "mass_margin": f.mass_margin,
                                                     "typically_benign": f.mass_typically_benign, "stable_2_years": f.stable_2_years,
                                                     "calcification_morphology": f.calcification_morphology, "size_mm": f.size_mm}.items()
                                   if v is not None}
            if f.description:
                row["description"] = f.description
            rows.append(row)
        lung = [f for f in s.findings if f.kind == "lung_nodule"]
        system = SYSTEM_OF.get(s.region) if s.region != "chest" else SYSTEM_OF[s.modality if s.modality == "LDCT" else "CT"]
        out = {"study_id": s.study_id, "exam": s.exam, "applicable_system": system, "template": template_key(s), "findings": rows}
        if lung:
            out["lung_nodule_count"] = len(lung)
            big = max(lung, key=lambda f: (f.long_axis_mm + f.short_axis_mm))
            out["largest_lung_nodule"] = big.finding_id
        if not s.exam_complete:
            out["note"] = "work-up incomplete: additional imaging or comparison needed"
        return out

    @is_tool(ToolType.READ)
    def get_prior_report(self, study_id: str) -> dict:
        """Return the prior comparison study's report, its category and its findings.

        Args:
            study_id: Study identifier (of the current study).
        """
        s = self._study(study_id)
        if s.prior is None:
            raise ToolError(f"study {s.study_id} has no prior comparison study")
        return {"study_id": s.study_id, **s.prior.model_dump()}

    @is_tool(ToolType.READ)
    def compare_with_prior(self, study_id: str) -> dict:
        """Compare findings with the prior study: size change per matching finding, growth rate, new and resolved findings.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        if s.prior is None:
            return {"study_id": s.study_id, "prior": None, "context": "baseline", "changes": [],
                    "note": "no prior study: this is a baseline examination"}
        prior = {f.finding_id: f for f in s.prior.findings}
        changes = []
        for f in s.findings:
            p = prior.get(f.finding_id)
            if f.kind == "lung_nodule":
                now = mean_diameter(f.long_axis_mm, f.short_axis_mm)
                if p is None:
                    changes.append({"finding_id": f.finding_id, "status": "new", "mean_diameter_mm": now})
                    continue
                before = mean_diameter(p.long_axis_mm, p.short_axis_mm)
                delta = round(now - before, 1)
                per_12 = round(delta * 12.0 / s.prior.months_ago, 1) if s.prior.months_ago else None
                status = "growing" if (delta > 1.5 and s.prior.months_ago <= 12.5) else "stable" if abs(delta) <= 1.5 else (
                    "growing" if delta > 0 else "decreased")
                changes.append({"finding_id": f.finding_id, "status": status, "prior_mean_mm": before, "mean_diameter_mm": now,
                                "change_mm": delta, "change_per_12_months_mm": per_12})
            elif f.kind == "thyroid_nodule" and p is not None and p.dimensions_cm and f.dimensions_cm:
                change = round(max(f.dimensions_cm) - max(p.dimensions_cm), 2)
                changes.append({"finding_id": f.finding_id, "status": "changed" if abs(change) >= 0.2 else "stable",
                                "change_max_diameter_cm": change})
            else:
                changes.append({"finding_id": f.finding_id, "status": "new" if p is None else "unchanged description"})
        resolved = [fid for fid in prior if fid not in {f.finding_id for f in s.findings}]
        return {"study_id": s.study_id, "prior": s.prior.study_id, "months_ago": s.prior.months_ago,
                "prior_category": s.prior.category, "changes": changes, "resolved": resolved}

    @is_tool(ToolType.READ)
    def get_report_template(self, modality: Literal["US", "MG", "CT", "LDCT"],
                            region: Literal["thyroid", "breast", "chest"]) -> dict:
        """Return the structured report template for a modality and region: sections, required elements, category system.

        Args:
            modality: "US", "MG", "CT" or "LDCT".
            region: "thyroid", "breast" or "chest".
        """
        key = ("LDCT chest" if modality == "LDCT" else "CT chest") if region == "chest" else f"{modality} {region}"
        tpl = self.db.templates.get(key)
        if tpl is None:
            raise ToolError(f"no template for {modality} {region}; templates: {', '.join(sorted(self.db.templates))}")
        return tpl.model_dump(exclude={"category_pattern"})

    # -- classification systems (envs.calculators, filled from the study) ----------------------
    @is_tool(ToolType.READ)
    def calculate_tirads(self, study_id: str | None = None, finding_id: str | None = None, composition: str | None = None,
                         echogenicity: str | None = None, shape: str | None = None, margin: str | None = None,
                         echogenic_foci: list[str] | None = None, max_diameter_cm: float | None = None) -> dict:
        """ACR TI-RADS points, TR level and FNA/follow-up advice for a thyroid nodule; features not given come from the study.

        Args:
            study_id: Study whose thyroid nodule fills the features not given.
            finding_id: Which nodule when the study has several.
            composition: cystic, spongiform, mixed, solid or cannot_determine.
            echogenicity: anechoic, hyperechoic, isoechoic, hypoechoic, very_hypoechoic or cannot_determine.
            shape: wider_than_tall or taller_than_wide.
            margin: smooth, ill_defined, lobulated_irregular, extrathyroidal_extension or cannot_determine.
            echogenic_foci: all that apply: none, large_comet_tail, macrocalcifications, peripheral_rim, punctate.
            max_diameter_cm: maximum diameter in cm.
        """
        given = {"composition": composition, "echogenicity": echogenicity, "shape": shape, "margin": margin,
                 "echogenic_foci": echogenic_foci, "max_diameter_cm": max_diameter_cm}
        if study_id is not None:
            f = self._finding(self._study(study_id), finding_id, ("thyroid_nodule",))
            record = {"composition": f.composition, "echogenicity": f.echogenicity, "shape": f.shape, "margin": f.margin,
                      "echogenic_foci": f.echogenic_foci, "max_diameter_cm": round(max(f.dimensions_cm), 2) if f.dimensions_cm else None}
            given = {k: (v if v is not None else record[k]) for k, v in given.items()}
        missing = [k for k, v in given.items() if v is None and k != "max_diameter_cm"]
        if missing:
            raise ToolError(f"missing TI-RADS features {missing}: give them or a 'study_id'")
        return CALCULATORS["calculate_tirads"](**given).model_dump(mode="json")

    @is_tool(ToolType.READ)
    def calculate_birads(self, study_id: str | None = None, mass_shape: str | None = None, mass_margin: str | None = None,
                         mass_typically_benign: bool | None = None, mass_stable_2_years: bool | None = None,
                         calcification_morphology: str | None = None, architectural_distortion: bool | None = None,
                         exam_complete: bool | None = None, known_biopsy_proven_malignancy: bool | None = None) -> dict:
        """BI-RADS assessment category from the breast findings (mass, calcifications, distortion); inputs not given come from the study.

        Args:
            study_id: Breast study whose findings fill the inputs not given.
            mass_shape: none, oval, round or irregular.
            mass_margin: none, circumscribed, obscured, microlobulated, indistinct or spiculated.
            mass_typically_benign: the mass is characteristically benign (cyst, lipoma, lymph node...).
            mass_stable_2_years: a circumscribed mass unchanged for >= 2 years.
            calcification_morphology: none, typically_benign, coarse_heterogeneous, amorphous, fine_pleomorphic or fine_linear_branching.
            architectural_distortion: distortion without a surgical explanation.
            exam_complete: False when additional views or prior films are needed.
            known_biopsy_proven_malignancy: the finding is a known cancer.
        """
        given = {"mass_shape": mass_shape, "mass_margin": mass_margin, "mass_typically_benign": mass_typically_benign,
                 "mass_stable_2_years": mass_stable_2_years, "calcification_morphology": calcification_morphology,
                 "architectural_distortion": architectural_distortion, "exam_complete": exam_complete,
                 "known_biopsy_proven_malignancy": known_biopsy_proven_malignancy}
        if study_id is not None:
            s = self._study(study_id)
            if s.region != "breast":
                raise ToolError(f"study {s.study_id} is a {s.region} study; BI-RADS applies to breast imaging")
            mass = next((f for f in s.findings if f.kind == "breast_mass"), None)
            calc = next((f for f in s.findings if f.kind == "breast_calcifications"), None)
            record = {"mass_shape": mass.mass_shape if mass else "none", "mass_margin": mass.mass_margin if mass else "none",
                      "mass_typically_benign": bool(mass and mass.mass_typically_benign),
                      "mass_stable_2_years": bool(mass and mass.stable_2_years),
                      "calcification_morphology": calc.calcification_morphology if calc else "none",
                      "architectural_distortion": any(f.kind == "breast_distortion" for f in s.findings),
                      "exam_complete": s.exam_complete, "known_biopsy_proven_malignancy": s.known_biopsy_proven_malignancy}
            given = {k: (v if v is not None else record[k]) for k, v in given.items()}
        given = {k: v for k, v in given.items() if v is not None}
        return CALCULATORS["calculate_birads"](**given).model_dump(mode="json")

    @is_tool(ToolType.READ)
    def fleischner_recommendation(self, study_id: str | None = None, finding_id: str | None = None,
                                  nodule_type: Literal["solid", "ground_glass", "part_solid"] | None = None,
                                  size_mm: float | None = None, multiple: bool | None = None,
                                  risk: Literal["low", "high"] | None = None) -> dict:
        """Fleischner 2017 follow-up for an incidental pulmonary nodule; inputs not given come from the study and patient risk.

        Args:
            study_id: CT study whose nodule (the largest, or finding_id) fills the inputs not given.
            finding_id: Which nodule.
            nodule_type: solid, ground_glass or part_solid.
            size_mm: average of long and short axis in mm.
            multiple: more than one nodule.
            risk: patient lung-cancer risk, low or high.
        """
        given = {"nodule_type": nodule_type, "size_mm": size_mm, "multiple": multiple, "risk": risk}
        if study_id is not None:
            s = self._study(study_id)
            nodules = [f for f in s.findings if f.kind == "lung_nodule"]
            if not nodules:
                raise ToolError(f"study {s.study_id} has no lung nodule")
            f = self._finding(s, finding_id, ("lung_nodule",)) if finding_id else max(nodules, key=lambda n: n.long_axis_mm + n.short_axis_mm)
            record = {"nodule_type": f.nodule_type if f.nodule_type in ("solid", "ground_glass", "part_solid") else "solid",
                      "size_mm": (f.long_axis_mm + f.short_axis_mm) / 2, "multiple": len(nodules) > 1, "risk": s.patient.lung_cancer_risk}
            given = {k: (v if v is not None else record[k]) for k, v in given.items()}
            if s.patient.known_malignancy:  # outside the guideline's population (MacMahon et al., Radiology 2017)
                return {"study_id": s.study_id, "applicable": False, "category": KNOWN_MALIGNANCY_MANAGEMENT,
                        "reason": f"Fleischner 2017 excludes patients with known malignancy ({s.patient.known_malignancy}); "
                                  "follow the nodule within the cancer's staging and surveillance imaging"}
        missing = [k for k, v in given.items() if v is None]
        if missing:
            raise ToolError(f"missing inputs {missing}: give them or a 'study_id'")
        return CALCULATORS["fleischner_recommendation"](**given).model_dump(mode="json")

    @is_tool(ToolType.READ)
    def calculate_lung_rads(self, study_id: str | None = None, finding_id: str | None = None, nodule_type: str | None = None,
                            size_mm: float | None = None, solid_component_mm: float | None = None,
                            context: Literal["baseline", "new", "growing", "stable"] | None = None,
                            prior_category: Literal["2", "3", "4A", "4B"] | None = None,
                            suspicious_features: bool | None = None) -> dict:
        """ACR Lung-RADS v2022 category of a screening-CT nodule; inputs not given come from the study and its prior.

        Args:
            study_id: Screening study whose nodule (the largest, or finding_id) fills the inputs not given.
            finding_id: Which nodule.
            nodule_type: none, benign_calcified_or_fat, solid, part_solid, ground_glass, perifissural, airway_subsegmental, airway_segmental_or_proximal.
            size_mm: mean diameter to 0.1 mm.
            solid_component_mm: mean diameter of the solid component (part-solid).
            context: baseline, new, growing or stable (compared with the prior screen).
            prior_category: the prior screen's category: 2, 3, 4A or 4B.
            suspicious_features: additional features raising suspicion (spiculation, lymphadenopathy).
        """
        given = {"nodule_type": nodule_type, "size_mm": size_mm, "solid_component_mm": solid_component_mm, "context": context,
                 "prior_category": prior_category, "suspicious_features": suspicious_features}
        if study_id is not None:
            s = self._study(study_id)
            nodules = [f for f in s.findings if f.kind == "lung_nodule"]
            record: dict = {"nodule_type": "none", "size_mm": 0.0, "solid_component_mm": 0.0, "context": "baseline",
                            "prior_category": None, "suspicious_features": False}
            if nodules:
                f = self._finding(s, finding_id, ("lung_nodule",)) if finding_id else max(nodules, key=lambda n: n.long_axis_mm + n.short_axis_mm)
                record.update(nodule_type=f.nodule_type, size_mm=mean_diameter(f.long_axis_mm, f.short_axis_mm),
                              solid_component_mm=mean_diameter(f.solid_long_mm, f.solid_short_mm) if f.solid_long_mm else 0.0,
                              suspicious_features=bool(f.suspicious_features))
                if s.prior is not None:
                    change = next((c for c in self.compare_with_prior(s.study_id)["changes"] if c["finding_id"] == f.finding_id), None)
                    record["context"] = {"new": "new", "growing": "growing"}.get(change["status"] if change else "new", "stable")
                    record["prior_category"] = s.prior.category if record["context"] == "stable" else None
            given = {k: (v if v is not None else record[k]) for k, v in given.items()}
        given = {k: v for k, v in given.items() if v is not None}
        if "nodule_type" not in given:
            raise ToolError("give 'nodule_type' (and size) or a 'study_id'")
        return CALCULATORS["calculate_lung_rads"](**given).model_dump(mode="json")

    # -- report lifecycle (WRITE) ---------------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def draft_report(self, study_id: str, findings: str, impression: str, category: str, recommendation: str) -> dict:
        """Write (or revise) the draft report: findings, impression, the system's category and the recommendation.

        Args:
            study_id: Study identifier.
            findings: The findings section.
            impression: The impression; it must state the category.
            category: The assessment in the study's system: "TR1".."TR5", "BI-RADS 0".."BI-RADS 6" (4A/4B/4C),
                a Fleischner 2017 recommendation (e.g. "CT at 6-12 months"), or "Lung-RADS 1".."Lung-RADS 4X".
            recommendation: The management recommendation.
        """
        s = self._study(study_id)
        tpl = self.db.templates[template_key(s)]
        cat = normalise_category(tpl.category_system, category)
        if cat is None or not re.match(tpl.category_pattern, cat):
            raise ToolError(f"category {category!r} is not a valid {tpl.category_system} assessment for {s.exam}")
        for name, value in (("findings", findings), ("impression", impression), ("recommendation", recommendation)):
            if not value.strip():
                raise ToolError(f"argument {name!r} is empty")
        core = cat.split()[-1] if tpl.category_system != "Fleischner 2017" else cat
        if core.lower() not in impression.lower():
            raise ToolError(f"the impression must state the assessment ({cat})")
        if s.study_id in self.db.reports and self.db.reports[s.study_id].status == "final":
            raise ToolError(f"the report of {s.study_id} is final; it cannot be redrafted")
        revisions = self.db.reports[s.study_id].revisions + 1 if s.study_id in self.db.reports else 0
        self.db.reports[s.study_id] = Report(study_id=s.study_id, status="draft", category=cat, findings_text=findings.strip(),
                                             impression=impression.strip(), recommendation=recommendation.strip(), revisions=revisions)
        critical = cat in tpl.critical_categories
        return {"study_id": s.study_id, "status": "draft", "category": cat, "revision": revisions,
                "critical_result": critical, "next": "communicate the critical result, then finalize" if critical else "finalize"}

    @is_tool(ToolType.WRITE)
    def communicate_critical_result(self, study_id: str, recipient: str, method: Literal["phone", "in person", "secure message"],
                                    finding: str) -> dict:
        """Document direct communication of a critical or suspicious result to the referring clinician.

        Args:
            study_id: Study identifier.
            recipient: Who received the result (name or role).
            method: "phone", "in person" or "secure message".
            finding: What was communicated.
        """
        s = self._study(study_id)
        if not recipient.strip() or not finding.strip():
            raise ToolError("arguments 'recipient' and 'finding' must not be empty")
        self.db.communications.append(CriticalCommunication(study_id=s.study_id, recipient=recipient.strip(), method=method,
                                                            finding=finding.strip()))
        return {"documented": True, "study_id": s.study_id, "method": method}

    @is_tool(ToolType.WRITE)
    def finalize_report(self, study_id: str) -> dict:
        """Sign the draft report as final; a suspicious or critical category needs a documented communication first.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        report = self.db.reports.get(s.study_id)
        if report is None:
            raise ToolError(f"no draft report for {s.study_id}: call draft_report first")
        if report.status == "final":
            raise ToolError(f"the report of {s.study_id} is already final")
        tpl = self.db.templates[template_key(s)]
        if report.category in tpl.critical_categories and not any(c.study_id == s.study_id for c in self.db.communications):
            raise ToolError(f"{report.category} requires documented communication to the referring clinician before "
                            "finalisation (communicate_critical_result)")
        report.status = "final"
        return {"study_id": s.study_id, "status": "final", "category": report.category}
