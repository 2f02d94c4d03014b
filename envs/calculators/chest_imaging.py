"""Pulmonary-nodule guidelines: Fleischner Society 2017 and ACR Lung-RADS v2022.

Fleischner 2017 (incidental nodules, adults >= 35 years, not in screening, not
immunocompromised, no known cancer): the size is the average of the long and short axes,
rounded to the nearest millimetre, and the size bands are < 6, 6-8 and > 8 mm. Lesions > 30 mm
are masses and outside the guideline.

Lung-RADS v2022 (lung-cancer screening CT): sizes are mean diameters to one decimal place.
"new" means not seen on the prior screen, "growing" an increase of > 1.5 mm in mean diameter
within 12 months. Stepped management: a category 3 nodule stable at its 6-month CT becomes
category 2, a category 4A stable at its 3-month CT becomes category 3; for a "stable" nodule the
prior category must be given. Atypical pulmonary cysts are not modelled.
"""

from __future__ import annotations

import math
from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_number,
    make_result,
)

_FLEISCHNER_REF = (
    "MacMahon H et al. Guidelines for management of incidental pulmonary nodules detected on CT "
    "images: from the Fleischner Society 2017. Radiology 2017;284:228-243."
)


def fleischner_recommendation(
    nodule_type: Literal["solid", "ground_glass", "part_solid"],
    size_mm: float,
    multiple: bool,
    risk: Literal["low", "high"],
) -> ScoreResult:
    """Fleischner Society 2017 follow-up recommendation for an incidental pulmonary nodule on CT.

    Args:
        nodule_type: "solid", "ground_glass" (pure ground-glass) or "part_solid".
        size_mm: Average of long- and short-axis diameters in mm, 1-30 (rounded to the nearest mm;
            for multiple nodules, the largest/most suspicious one).
        multiple: True if there are multiple nodules.
        risk: Patient risk of lung cancer, "low" or "high" (smoking, exposure, family history, older
            age, upper-lobe location, emphysema/fibrosis); used for solid nodules only.
    """
    fn = "fleischner_recommendation"
    kind = check_choice(fn, "nodule_type", nodule_type, ("solid", "ground_glass", "part_solid"))
    raw = check_number(fn, "size_mm", size_mm, 1, 30, "mm (larger lesions are masses, outside the guideline)")
    multi = check_bool(fn, "multiple", multiple)
    r = check_choice(fn, "risk", risk, ("low", "high"))
    size = math.floor(raw + 0.5)  # nearest whole millimetre, as the guideline measures
    band = "< 6 mm" if size < 6 else "6-8 mm" if size <= 8 else "> 8 mm"
    if kind == "solid":
        if size < 6:
            cat = "no routine follow-up" if r == "low" else "optional CT at 12 months"
            text = cat
        elif size <= 8:
            if multi:
                cat = "CT at 3-6 months"
                text = (
                    "CT at 3-6 months, then consider CT at 18-24 months"
                    if r == "low"
                    else "CT at 3-6 months, then CT at 18-24 months"
                )
            else:
                cat = "CT at 6-12 months"
                text = (
                    "CT at 6-12 months, then consider CT at 18-24 months"
                    if r == "low"
                    else "CT at 6-12 months, then CT at 18-24 months"
                )
        elif multi:
            cat, text = "CT at 3-6 months", "CT at 3-6 months, then consider CT at 18-24 months"
        else:
            cat = "CT at 3 months, PET/CT or tissue sampling"
            text = "consider CT at 3 months, PET/CT, or tissue sampling"
    elif multi:  # multiple subsolid nodules
        if size < 6:
            cat, text = "CT at 3-6 months", "CT at 3-6 months; if stable, consider CT at 2 and 4 years"
        else:
            cat = "CT at 3-6 months"
            text = "CT at 3-6 months; subsequent management based on the most suspicious nodule(s)"
    elif size < 6:
        cat, text = "no routine follow-up", "no routine follow-up"
    elif kind == "ground_glass":
        cat = "CT at 6-12 months"
        text = "CT at 6-12 months to confirm persistence, then CT every 2 years until 5 years"
    else:
        cat = "CT at 3-6 months"
        text = (
            "CT at 3-6 months to confirm persistence; if unchanged and the solid component remains < 6 mm, "
            "annual CT for 5 years (a solid component >= 6 mm is highly suspicious)"
        )
    return make_result(
        "Fleischner 2017",
        size,
        "mm",
        cat,
        f"Fleischner 2017, {'multiple' if multi else 'single'} {kind.replace('_', '-')} nodule {band}"
        + (f" ({r} risk)" if kind == "solid" else "")
        + f": {text}.",
        {
            "size_mm_rounded": size,
            "size_band": band,
            "nodule_type": kind,
            "multiple": multi,
            "risk_applied": r if kind == "solid" else None,
        },
        _FLEISCHNER_REF,
    )


_LR_MANAGEMENT = {
    "0": "additional screening CT images and/or comparison with prior CT needed",
    "1": "continue annual screening with LDCT in 12 months",
    "2": "continue annual screening with LDCT in 12 months",
    "3": "LDCT in 6 months (malignancy 1-2%)",
    "4A": "LDCT in 3 months; PET/CT may be considered if there is a solid component >= 8 mm (malignancy "
    "5-15%)",
    "4B": "diagnostic chest CT, PET/CT if solid component >= 8 mm, and/or tissue sampling (malignancy > 15%)",
    "4X": "diagnostic chest CT, PET/CT if solid component >= 8 mm, and/or tissue sampling (malignancy > 15%)",
}


def _solid(size: float, context: str) -> str:
    if context == "baseline":
        return "2" if size < 6 else "3" if size < 8 else "4A" if size < 15 else "4B"
    if context == "new":
        return "2" if size < 4 else "3" if size < 6 else "4A" if size < 8 else "4B"
    return "4A" if size < 8 else "4B"  # growing


def _part_solid(size: float, solid: float, context: str) -> str:
    if context == "baseline":
        if size < 6:
            return "2"
        return "3" if solid < 6 else "4A" if solid < 8 else "4B"
    if context == "new" and size < 6:
        return "3"
    return "4A" if solid < 4 else "4B"  # new >= 6 mm, or growing


def calculate_lung_rads(
    nodule_type: Literal[
        "none",
        "benign_calcified_or_fat",
        "solid",
        "part_solid",
        "ground_glass",
        "perifissural",
        "airway_subsegmental",
        "airway_segmental_or_proximal",
    ],
    size_mm: float = 0.0,
    solid_component_mm: float = 0.0,
    context: Literal["baseline", "new", "growing", "stable"] = "baseline",
    prior_category: Literal["2", "3", "4A", "4B"] | None = None,
    suspicious_features: bool = False,
    incomplete: bool = False,
    significant_other_finding: bool = False,
) -> ScoreResult:
    """ACR Lung-RADS v2022 category for the most suspicious finding on a lung-cancer screening CT.

    Args:
        nodule_type: "none", "benign_calcified_or_fat" (benign calcification or fat), "solid",
            "part_solid", "ground_glass" (non-solid), "perifissural" (juxtapleural/perifissural solid
            nodule with smooth margins and oval, lentiform or triangular shape), "airway_subsegmental"
            or "airway_segmental_or_proximal" (endobronchial nodule).
        size_mm: Mean diameter in mm to one decimal place, 0-100 (total diameter for part-solid).
        solid_component_mm: Mean diameter of the solid component of a part-solid nodule in mm, 0-100.
        context: "baseline" (first screen), "new", "growing" (> 1.5 mm in 12 months) or "stable".
        prior_category: Category assigned at the previous CT ("2", "3", "4A" or "4B"); required
            when context is "stable".
        suspicious_features: True for category 3 or 4 findings with additional features that raise
            suspicion (spiculation, lymphadenopathy, GGN doubling in a year...): category 4X.
        incomplete: True if the lungs cannot be fully evaluated or a prior CT is being obtained (category 0).
        significant_other_finding: True for a clinically significant non-lung-cancer finding (S modifier).
    """
    fn = "calculate_lung_rads"
    kind = check_choice(
        fn,
        "nodule_type",
        nodule_type,
        (
            "none",
            "benign_calcified_or_fat",
            "solid",
            "part_solid",
            "ground_glass",
            "perifissural",
            "airway_subsegmental",
            "airway_segmental_or_proximal",
        ),
    )
    size = round(check_number(fn, "size_mm", size_mm, 0, 100, "mm"), 1)
    solid = round(check_number(fn, "solid_component_mm", solid_component_mm, 0, 100, "mm"), 1)
    ctx = check_choice(fn, "context", context, ("baseline", "new", "growing", "stable"))
    if prior_category is not None:
        check_choice(fn, "prior_category", prior_category, ("2", "3", "4A", "4B"))
    susp = check_bool(fn, "suspicious_features", suspicious_features)
    inc = check_bool(fn, "incomplete", incomplete)
    s_mod = check_bool(fn, "significant_other_finding", significant_other_finding)
    sized = kind in ("solid", "part_solid", "ground_glass", "perifissural")
    if sized and size <= 0:
        raise CalculatorInputError(fn, "size_mm", f"> 0 mm for a {kind} nodule", size_mm)
    if kind == "part_solid" and not 0 < solid <= size:
        raise CalculatorInputError(
            fn,
            "solid_component_mm",
            f"> 0 and <= size_mm ({size:g} mm) for a part-solid nodule",
            solid_component_mm,
        )
    if (
        ctx == "stable"
        and prior_category is None
        and kind
        not in ("none", "benign_calcified_or_fat", "airway_subsegmental", "airway_segmental_or_proximal")
    ):
        raise CalculatorInputError(
            fn, "prior_category", "given ('2', '3', '4A' or '4B') when context is 'stable'", None
        )
    if inc:
        cat = "0"
    elif kind in ("none", "benign_calcified_or_fat"):
        cat = "1"
    elif kind == "airway_subsegmental":
        cat = "2"
    elif kind == "airway_segmental_or_proximal":
        cat = "4A" if ctx in ("baseline", "new") else "4B"
    elif ctx == "stable":
        cat = {"2": "2", "3": "2", "4A": "3", "4B": "4B"}[prior_category]  # type: ignore[index]
    elif kind == "perifissural" and ctx in ("baseline", "new") and size < 10:
        cat = "2"
    elif kind in ("solid", "perifissural"):
        cat = _solid(size, ctx)
    elif kind == "part_solid":
        cat = _part_solid(size, solid, ctx)
    else:  # ground glass: < 30 mm benign at any time point; >= 30 mm at baseline or new is 3
        cat = "3" if size >= 30 and ctx in ("baseline", "new") else "2"
    if susp and cat in ("3", "4A", "4B"):
        cat = "4X"
    label = cat + ("S" if s_mod else "")
    return make_result(
        "Lung-RADS v2022",
        int(cat[0]),
        "category",
        label,
        f"Lung-RADS {label}: {_LR_MANAGEMENT[cat]}"
        + ("; S: manage the significant other finding." if s_mod else "."),
        {
            "nodule_type": kind,
            "size_mm": size,
            "solid_component_mm": solid if kind == "part_solid" else None,
            "context": ctx,
            "prior_category": prior_category,
            "s_modifier": s_mod,
        },
        "American College of Radiology. Lung CT Screening Reporting & Data System (Lung-RADS) v2022: "
        "assessment categories and management (released November 2022).",
    )
