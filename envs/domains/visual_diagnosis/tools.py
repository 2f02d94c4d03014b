"""Visual-diagnosis tools: metadata and history, image analysis computed from the PNG pixels
(`analysis.py`), lesion measurement from a seed point, region statistics, cardiothoracic ratio,
comparison with the prior image, similar-case retrieval from the archive, the Fleischner
recommendation from the measured nodule, a glossary of signs, and the reader's records."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy import ndimage

from envs.calculators import CALCULATORS
from envs.core.common_tools import BaseDomainTools
from envs.core.tools import ToolError, ToolType, is_tool
from envs.domains.visual_diagnosis import analysis as A
from envs.domains.imaging_guidelines import KNOWN_MALIGNANCY_MANAGEMENT
from envs.domains.visual_diagnosis.data_model import CriticalEscalation, RecordedFinding, Study, VisualDB
from envs.domains.visual_diagnosis.png import read_png

FINDINGS = ("nodule", "mass", "consolidation", "pleural effusion", "pneumothorax", "cardiomegaly", "normal")


@lru_cache(maxsize=512)
def _load(path: str, stamp: tuple[int, int]) -> np.ndarray:
    img = read_png(Path(path))
    img.setflags(write=False)
    return img


@lru_cache(maxsize=512)
def _analyse(path: str, stamp: tuple[int, int], modality: str, spacing: float) -> dict:
    img = _load(path, stamp)
    return A.analyze_cxr(img, spacing) if modality == "CR" else A.analyze_ct(img, spacing)


class VisualTools(BaseDomainTools):
    db: VisualDB

    def __init__(self, db: VisualDB, image_root: Path) -> None:
        super().__init__(db)
        self.image_root = Path(image_root)

    def _study(self, study_id: str) -> Study:
        sid = (study_id or "").strip().upper()
        if sid not in self.db.studies:
            raise ToolError(f"study {study_id!r} not found; ids look like {min(self.db.studies)} ({len(self.db.studies)} studies)")
        return self.db.studies[sid]

    def _key(self, s: Study) -> tuple[str, tuple[int, int]]:
        path = self.image_root / s.image_file
        if not path.exists():
            raise ToolError(f"image file of {s.study_id} is missing ({path}); rebuild the domain data")
        st = path.stat()
        return str(path), (st.st_mtime_ns, st.st_size)

    def image(self, s: Study) -> np.ndarray:
        return _load(*self._key(s))

    def analysis(self, s: Study) -> dict:
        return _analyse(*self._key(s), s.modality, s.pixel_spacing_mm)

    # -- metadata --------------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def get_study_metadata(self, study_id: str) -> dict:
        """Return a study's modality, view, image size, pixel spacing (mm), orientation, indication and prior study.

        Args:
            study_id: Study identifier, e.g. "VIS-104".
        """
        s = self._study(study_id)
        return {"study_id": s.study_id, "modality": s.modality, "body_part": s.body_part, "view": s.view,
                "image": s.image_file, "width": s.width, "height": s.height, "pixel_spacing_mm": s.pixel_spacing_mm,
                "orientation": s.orientation, "indication": s.indication, "acquired": s.acquired, "prior_study_id": s.prior_study_id}

    @is_tool(ToolType.READ)
    def get_clinical_history(self, study_id: str) -> dict:
        """Return the patient's age, sex, symptoms, history, smoking and lung-cancer risk for a study.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        return {"study_id": s.study_id, **s.patient.model_dump()}

    # -- image computation -----------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def analyze_medical_image(self, study_id: str) -> dict:
        """Analyse the study image's pixels: intensity statistics, segmented lung fields, detected opacities/lucencies or nodules with sizes in mm.

        Args:
            study_id: Study identifier.
        """
        s = self._study(study_id)
        img = self.image(s)
        try:
            out = self.analysis(s)
        except ValueError as exc:
            raise ToolError(f"{s.study_id}: {exc}") from None
        return {"study_id": s.study_id, "modality": s.modality, "pixel_spacing_mm": s.pixel_spacing_mm,
                "orientation": s.orientation, "image_statistics": A.intensity_stats(img), **out}

    @is_tool(ToolType.READ)
    def measure_lesion(self, study_id: str, x: int, y: int) -> dict:
        """Measure the lesion containing pixel (x, y): region grown at half the contrast to the surrounding lung; axes and diameter in mm.

        Args:
            study_id: Study identifier.
            x: Column of a pixel inside the lesion (0 = left edge of the image).
            y: Row of a pixel inside the lesion (0 = top).
        """
        s = self._study(study_id)
        img = self.image(s)
        if not (0 <= x < s.width and 0 <= y < s.height):
            raise ToolError(f"(x, y) = ({x}, {y}) is outside the {s.width} x {s.height} image")
        seed_value = float(img[y, x])
        y0, y1, x0, x1 = max(0, y - 25), min(s.height, y + 26), max(0, x - 25), min(s.width, x + 26)
        window = img[y0:y1, x0:x1].astype(float)
        background = float(np.percentile(window, 30)) if seed_value > np.median(window) else float(np.percentile(window, 70))
        if abs(seed_value - background) < 15:
            raise ToolError(f"pixel ({x}, {y}) (value {seed_value:g}) does not stand out from its surroundings "
                            f"({background:g}); give a point inside a lesion (see analyze_medical_image centroids)")
        cut = (seed_value + background) / 2
        # Grow within a 96 px window around the seed; fall back to the whole image if the region
        # reaches the window edge (a lesion larger than the window).
        for half in (48, max(s.width, s.height)):
            wy0, wy1, wx0, wx1 = max(0, y - half), min(s.height, y + half), max(0, x - half), min(s.width, x + half)
            sub = img[wy0:wy1, wx0:wx1]
            mask = sub >= cut if seed_value > background else sub <= cut
            labels, _ = ndimage.label(mask, structure=A.SQUARE)
            comp = labels == labels[y - wy0, x - wx0]
            touches = comp[0].any() or comp[-1].any() or comp[:, 0].any() or comp[:, -1].any()
            if not touches or half >= max(s.width, s.height):
                break
        area = int(comp.sum())
        if area > 0.05 * img.size or (touches and (wy0, wx0) != (0, 0)):
            raise ToolError(f"the region at ({x}, {y}) is not a focal lesion (it spans {area} pixels); pick a point inside a nodule or mass")
        filled = ndimage.binary_fill_holes(comp)
        ys, xs = np.nonzero(filled)
        long_px, short_px, angle = A._axes(ys, xs)
        sp = s.pixel_spacing_mm
        ring = ndimage.binary_dilation(filled, iterations=3) & ~filled
        return {"study_id": s.study_id, "seed": [x, y], "threshold": round(cut, 1), "area_mm2": round(len(ys) * sp * sp, 1),
                "equivalent_diameter_mm": round(2 * math.sqrt(len(ys) / math.pi) * sp, 1),
                "long_axis_mm": round(long_px * sp, 1), "short_axis_mm": round(short_px * sp, 1),
                "mean_diameter_mm": round((long_px + short_px) / 2 * sp, 1), "orientation_deg": round(angle, 1),
                "mean_intensity": round(float(sub[filled].mean()), 1), "surrounding_intensity": round(float(sub[ring].mean()), 1),
                "centroid_px": [round(float(xs.mean()) + wx0, 1), round(float(ys.mean()) + wy0, 1)]}

    @is_tool(ToolType.READ)
    def get_region_statistics(self, study_id: str, x0: int, y0: int, x1: int, y1: int) -> dict:
        """Intensity statistics of a rectangular region of interest (inclusive pixel bounds).

        Args:
            study_id: Study identifier.
            x0: Left column.
            y0: Top row.
            x1: Right column.
            y1: Bottom row.
        """
        s = self._study(study_id)
        if not (0 <= x0 <= x1 < s.width and 0 <= y0 <= y1 < s.height):
            raise ToolError(f"region ({x0},{y0})-({x1},{y1}) must satisfy 0 <= x0 <= x1 < {s.width} and 0 <= y0 <= y1 < {s.height}")
        img = self.image(s)
        roi = img[y0:y1 + 1, x0:x1 + 1]
        sp = s.pixel_spacing_mm
        return {"study_id": s.study_id, "region_mm": [round((x1 - x0 + 1) * sp, 1), round((y1 - y0 + 1) * sp, 1)],
                **A.intensity_stats(roi)}

    @is_tool(ToolType.READ)
    def measure_cardiothoracic_ratio(self, study_id: str) -> dict:
        """Measure the cardiothoracic ratio on a PA chest radiograph (maximal heart width / maximal internal thoracic width).

        Args:
            study_id: Study identifier (a PA chest radiograph).
        """
        s = self._study(study_id)
        if s.modality != "CR":
            raise ToolError(f"{s.study_id} is a {s.modality} study; the cardiothoracic ratio is measured on a PA chest radiograph")
        out = self.analysis(s)
        ctr = out["cardiothoracic_ratio"]
        return {"study_id": s.study_id, "cardiothoracic_ratio": ctr, "heart_width_mm": out["heart_width_mm"],
                "thoracic_width_mm": out["thoracic_width_mm"], "cardiomegaly": bool(ctr is not None and ctr > 0.5)}

    @is_tool(ToolType.READ)
    def compare_with_prior(self, study_id: str) -> dict:
        """Compare the nodules of a CT study with its prior image: matched by position, change in mean diameter, new and resolved nodules.

        Args:
            study_id: Study identifier (current study).
        """
        s = self._study(study_id)
        if s.prior_study_id is None:
            raise ToolError(f"{s.study_id} has no prior study")
        prior = self._study(s.prior_study_id)
        if s.modality != "CT":
            raise ToolError("prior comparison measures nodules on CT studies")
        now, before = self.analysis(s)["nodules"], self.analysis(prior)["nodules"]
        used: set[int] = set()
        rows = []
        for n in now:
            best = None
            for j, p in enumerate(before):
                d = math.dist(n["centroid_px"], p["centroid_px"])
                if j not in used and d < 12 and (best is None or d < best[0]):
                    best = (d, j)
            if best is None:
                rows.append({"index": n["index"], "status": "new", "mean_diameter_mm": n["mean_diameter_mm"], "side": n["side"]})
                continue
            used.add(best[1])
            p = before[best[1]]
            change = round(n["mean_diameter_mm"] - p["mean_diameter_mm"], 1)
            ratio = (n["mean_diameter_mm"] / p["mean_diameter_mm"]) ** 3 if p["mean_diameter_mm"] else None
            rows.append({"index": n["index"], "side": n["side"], "prior_mean_diameter_mm": p["mean_diameter_mm"],
                         "mean_diameter_mm": n["mean_diameter_mm"], "change_mm": change,
                         "volume_ratio": round(ratio, 2) if ratio else None,
                         "status": "growing" if change > 1.5 else "shrinking" if change < -1.5 else "stable"})
        resolved = [p["index"] for j, p in enumerate(before) if j not in used]
        return {"study_id": s.study_id, "prior_study_id": prior.study_id, "prior_acquired": prior.acquired,
                "nodules": rows, "resolved_prior_nodules": resolved}

    @is_tool(ToolType.READ)
    def fleischner_recommendation(self, study_id: str, nodule_index: int = 1) -> dict:
        """Fleischner 2017 follow-up for a CT nodule measured on the image (mean of its axes), the number of nodules and the patient's risk.

        Args:
            study_id: Study identifier (a CT study).
            nodule_index: Which nodule (1 = the largest, as numbered by analyze_medical_image).
        """
        s = self._study(study_id)
        if s.modality != "CT":
            raise ToolError("Fleischner recommendations apply to nodules measured on CT")
        nodules = self.analysis(s)["nodules"]
        if not nodules:
            raise ToolError(f"no nodule detected on {s.study_id}")
        if not 1 <= nodule_index <= len(nodules):
            raise ToolError(f"nodule_index must be between 1 and {len(nodules)}")
        n = nodules[nodule_index - 1]
        if s.patient.known_malignancy:  # outside the guideline's population (MacMahon et al., Radiology 2017)
            return {"study_id": s.study_id, "nodule": n, "applicable": False, "category": KNOWN_MALIGNANCY_MANAGEMENT,
                    "reason": f"Fleischner 2017 excludes patients with known malignancy ({s.patient.known_malignancy}); "
                              "follow the nodule within the cancer's staging and surveillance imaging"}
        size = min(max(n["mean_diameter_mm"], 1.0), 30.0)
        res = CALCULATORS["fleischner_recommendation"](nodule_type=n["type"], size_mm=size, multiple=len(nodules) > 1,
                                                       risk=s.patient.lung_cancer_risk)
        return {"study_id": s.study_id, "nodule": n, "risk": s.patient.lung_cancer_risk, "multiple": len(nodules) > 1,
                **res.model_dump(mode="json")}

    # -- knowledge -----------------------------------------------------------------------------
    @is_tool(ToolType.READ)
    def search_similar_cases(self, study_id: str | None = None, finding: str | None = None, side: str | None = None,
                             size_mm: float | None = None, age: int | None = None, limit: int = 5) -> dict:
        """Find archived cases with confirmed diagnoses nearest to a study's detected finding (or to given findings).

        Args:
            study_id: Study whose image analysis gives the query finding (the largest abnormality).
            finding: nodule, mass, consolidation, pleural effusion, pneumothorax, cardiomegaly or normal.
            side: left, right or central.
            size_mm: Lesion size in mm.
            age: Patient age.
            limit: Number of cases (1-20).
        """
        if not 1 <= limit <= 20:
            raise ToolError("argument 'limit' must be between 1 and 20")
        query = {"finding": finding, "side": side, "size_mm": size_mm, "age": age, "smoking": None, "modality": None}
        if study_id is not None:
            s = self._study(study_id)
            out = self.analysis(s)
            query["modality"] = s.modality
            if s.modality == "CR":
                f = max(out["findings"], key=lambda r: r.get("area_mm2", 0), default=None)
                if f is not None:
                    query.update(finding=query["finding"] or f["finding"], side=query["side"] or f["side"],
                                 size_mm=query["size_mm"] or f.get("diameter_mm"))
                else:
                    query["finding"] = query["finding"] or "normal"
            else:
                n = out["nodules"][0] if out["nodules"] else None
                query.update(finding=query["finding"] or ("nodule" if n else "normal"), side=query["side"] or (n and n["side"]),
                             size_mm=query["size_mm"] or (n and n["mean_diameter_mm"]))
            query["age"] = query["age"] or s.patient.age
            query["smoking"] = s.patient.smoking_pack_years
        if not query["finding"]:
            raise ToolError("give a 'study_id' or at least a 'finding'")
        if query["finding"] not in FINDINGS:
            raise ToolError(f"finding must be one of {', '.join(FINDINGS)}")
        scored = []
        for case in self.db.archive.values():
            d = 0.0 if case.finding == query["finding"] else 3.0
            d += 0.0 if query["modality"] in (None, case.modality) else 0.5
            d += 0.0 if not query["side"] or case.side == query["side"] else 0.3
            if query["size_mm"] and case.size_mm:
                d += abs(math.log(query["size_mm"] / case.size_mm))
            if query["age"]:
                d += abs(query["age"] - case.age) / 40
            if query["smoking"] is not None:
                d += min(abs(query["smoking"] - case.smoking_pack_years), 40) / 30
            scored.append((round(d, 3), case.case_id))
        scored.sort()
        top = [{"case_id": cid, "distance": d, "finding": self.db.archive[cid].finding,
                "confirmed_diagnosis": self.db.archive[cid].confirmed_diagnosis} for d, cid in scored[:limit]]
        counts: dict[str, int] = {}
        for row in top:
            counts[row["confirmed_diagnosis"]] = counts.get(row["confirmed_diagnosis"], 0) + 1
        return {"query": {k: v for k, v in query.items() if v is not None}, "cases": top,
                "diagnosis_counts": dict(sorted(counts.items(), key=lambda kv: -kv[1]))}

    @is_tool(ToolType.READ)
    def get_case_report(self, case_id: str) -> dict:
        """Return an archived reference case: findings, confirmed diagnosis and how it was confirmed.

        Args:
            case_id: Archive case identifier, e.g. "ARC-012".
        """
        case = self.db.archive.get(case_id.strip().upper())
        if case is None:
            raise ToolError(f"archive case {case_id!r} not found; use search_similar_cases")
        return case.model_dump()

    @is_tool(ToolType.READ)
    def lookup_imaging_sign(self, term: str) -> dict:
        """Define an imaging sign or measurement (air bronchogram, meniscus sign, cardiothoracic ratio, ...).

        Args:
            term: The sign's name or a synonym.
        """
        key = " ".join(term.lower().split())
        for name, sign in self.db.signs.items():
            if key == name or key in [x.lower() for x in sign.synonyms]:
                return sign.model_dump()
        near = [n for n in self.db.signs if key.split()[0] in n] if key else []
        raise ToolError(f"sign {term!r} not in the glossary" + (f"; related: {', '.join(near)}" if near else
                                                                   f"; terms: {', '.join(sorted(self.db.signs))}"))

    # -- records (WRITE) ------------------------------------------------------------------------
    @is_tool(ToolType.WRITE)
    def record_finding(self, study_id: str, finding: str, side: str, location: str, size_mm: float | None = None) -> dict:
        """Record a finding in the study's structured read.

        Args:
            study_id: Study identifier.
            finding: nodule, mass, consolidation, pleural effusion, pneumothorax, cardiomegaly or normal.
            side: left, right, bilateral or central (patient's side).
            location: Zone or lobe, e.g. "right upper zone".
            size_mm: Size in mm for a measurable lesion.
        """
        s = self._study(study_id)
        f = finding.strip().lower()
        if f not in FINDINGS:
            raise ToolError(f"finding must be one of {', '.join(FINDINGS)}")
        if side.strip().lower() not in ("left", "right", "bilateral", "central"):
            raise ToolError("side must be left, right, bilateral or central (the patient's side)")
        if size_mm is not None and not 0 < size_mm < 400:
            raise ToolError("size_mm must be between 0 and 400")
        self.db.recorded_findings.append(RecordedFinding(study_id=s.study_id, finding=f, side=side.strip().lower(),
                                                         location=location.strip(), size_mm=size_mm))
        return {"recorded": True, "study_id": s.study_id, "findings_recorded": sum(1 for r in self.db.recorded_findings if r.study_id == s.study_id)}

    @is_tool(ToolType.WRITE)
    def escalate_critical_finding(self, study_id: str, finding: str, recipient: str) -> dict:
        """Escalate a critical imaging finding (e.g. large pneumothorax) directly to the treating team.

        Args:
            study_id: Study identifier.
            finding: The critical finding.
            recipient: Who was contacted.
        """
        s = self._study(study_id)
        if not finding.strip() or not recipient.strip():
            raise ToolError("arguments 'finding' and 'recipient' must not be empty")
        self.db.escalations.append(CriticalEscalation(study_id=s.study_id, finding=finding.strip(), recipient=recipient.strip()))
        return {"escalated": True, "study_id": s.study_id}
