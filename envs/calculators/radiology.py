"""Imaging classification systems: ACR TI-RADS (thyroid) and BI-RADS (breast).

TI-RADS (Tessler 2017): points from five feature categories; echogenic foci are additive
("choose all that apply"). Spongiform nodules score 0 overall ("do not add further points").
The chart lists TR1 for 0 points and TR2 for 2 points; a total of 1 (reachable only through
combinations the lexicon treats as unusual, e.g. a cystic nodule with macrocalcification) is
not listed: we assign TR2 because a point-scoring feature is present (no FNA or follow-up
either way, so management does not change).

BI-RADS: the ACR Atlas (5th ed., 2013) defines the assessment categories by likelihood of
malignancy, not by an algorithm. ``calculate_birads`` turns structured lexicon findings into
the category the Atlas associates with each finding and reports the most suspicious one:
typically benign findings 2; a circumscribed oval/round solid mass without prior films 3
(probably benign, Sickles 1991) or 2 once stable for 2 years; calcification morphology by its
Atlas PPV (coarse heterogeneous 13 %, amorphous 21 %, fine pleomorphic 29 %: 4B; fine linear
or fine-linear branching 70 %: 4C); an irregular spiculated mass 5 (>= 95 %); other suspicious
mass features or architectural distortion 4 (the Atlas gives no subcategory PPV for them). The
interpreting radiologist's final assessment always takes precedence.
"""

from __future__ import annotations

from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_optional_number,
    make_result,
)

_COMPOSITION = {"cystic": 0, "spongiform": 0, "mixed": 1, "solid": 2, "cannot_determine": 2}
_ECHO = {
    "anechoic": 0,
    "hyperechoic": 1,
    "isoechoic": 1,
    "hypoechoic": 2,
    "very_hypoechoic": 3,
    "cannot_determine": 1,
}
_SHAPE = {"wider_than_tall": 0, "taller_than_wide": 3}
_MARGIN = {
    "smooth": 0,
    "ill_defined": 0,
    "lobulated_irregular": 2,
    "extrathyroidal_extension": 3,
    "cannot_determine": 0,
}
_FOCI = {"none": 0, "large_comet_tail": 0, "macrocalcifications": 1, "peripheral_rim": 2, "punctate": 3}
# TR level -> (label, FNA threshold cm, follow-up threshold cm, follow-up schedule)
_TR = {
    1: ("benign", None, None, ""),
    2: ("not suspicious", None, None, ""),
    3: ("mildly suspicious", 2.5, 1.5, "ultrasound at 1, 3 and 5 years"),
    4: ("moderately suspicious", 1.5, 1.0, "ultrasound at 1, 2, 3 and 5 years"),
    5: ("highly suspicious", 1.0, 0.5, "ultrasound every year for 5 years"),
}
_TIRADS_REF = (
    "Tessler FN et al. ACR Thyroid Imaging, Reporting and Data System (TI-RADS): white paper of "
    "the ACR TI-RADS Committee. J Am Coll Radiol 2017;14:587-595."
)


def calculate_tirads(
    composition: Literal["cystic", "spongiform", "mixed", "solid", "cannot_determine"],
    echogenicity: Literal[
        "anechoic", "hyperechoic", "isoechoic", "hypoechoic", "very_hypoechoic", "cannot_determine"
    ],
    shape: Literal["wider_than_tall", "taller_than_wide"],
    margin: Literal[
        "smooth", "ill_defined", "lobulated_irregular", "extrathyroidal_extension", "cannot_determine"
    ],
    echogenic_foci: list[
        Literal["none", "large_comet_tail", "macrocalcifications", "peripheral_rim", "punctate"]
    ],
    max_diameter_cm: float | None = None,
) -> ScoreResult:
    """ACR TI-RADS points and TR level for a thyroid nodule, with FNA/follow-up advice by size.

    Args:
        composition: "cystic" (or almost completely cystic, 0), "spongiform" (0, no further points),
            "mixed" cystic and solid (1), "solid" (or almost completely solid, 2) or "cannot_determine"
            (obscured by calcification, 2).
        echogenicity: "anechoic" (0), "hyperechoic" or "isoechoic" (1), "hypoechoic" (2),
            "very_hypoechoic" (3) or "cannot_determine" (1).
        shape: "wider_than_tall" (0) or "taller_than_wide" (3), on the transverse image.
        margin: "smooth" or "ill_defined" (0), "lobulated_irregular" (2), "extrathyroidal_extension" (3)
            or "cannot_determine" (0).
        echogenic_foci: All types present (points add up): "none" or "large_comet_tail" (0),
            "macrocalcifications" (1), "peripheral_rim" (2), "punctate" (3). Use ["none"] if none.
        max_diameter_cm: Optional maximum nodule diameter in cm, 0.1-15; gives the FNA or
            follow-up recommendation.
    """
    fn = "calculate_tirads"
    comp = check_choice(fn, "composition", composition, tuple(_COMPOSITION))
    echo = check_choice(fn, "echogenicity", echogenicity, tuple(_ECHO))
    sh = check_choice(fn, "shape", shape, tuple(_SHAPE))
    mar = check_choice(fn, "margin", margin, tuple(_MARGIN))
    expected = "a non-empty list of distinct values from " + ", ".join(repr(f) for f in _FOCI)
    if not isinstance(echogenic_foci, (list, tuple)) or not echogenic_foci:
        raise CalculatorInputError(fn, "echogenic_foci", expected, echogenic_foci)
    for item in echogenic_foci:
        if type(item) is not str or item not in _FOCI:
            raise CalculatorInputError(fn, "echogenic_foci", expected, echogenic_foci)
    foci = set(echogenic_foci)
    if len(foci) != len(echogenic_foci) or ("none" in foci and len(foci) > 1):
        raise CalculatorInputError(fn, "echogenic_foci", expected + " ('none' alone)", echogenic_foci)
    size = check_optional_number(fn, "max_diameter_cm", max_diameter_cm, 0.1, 15, "cm")
    comps = {
        "composition": _COMPOSITION[comp],
        "echogenicity": _ECHO[echo],
        "shape": _SHAPE[sh],
        "margin": _MARGIN[mar],
        "echogenic_foci": sum(_FOCI[f] for f in foci),
    }
    if comp == "spongiform":  # ACR: spongiform nodules are benign; do not add further points
        comps = {k: 0 for k in comps}
    total = sum(comps.values())
    level = 1 if total == 0 else 2 if total <= 2 else 3 if total == 3 else 4 if total <= 6 else 5
    label, fna_cm, follow_cm, schedule = _TR[level]
    if fna_cm is None:
        advice = "no FNA"
    elif size is None:
        advice = (
            f"FNA if >= {fna_cm:g} cm; follow-up if >= {follow_cm:g} cm (give the size for a recommendation)"
        )
    elif size >= fna_cm:
        advice = f"FNA recommended (>= {fna_cm:g} cm)"
    elif size >= follow_cm:
        advice = f"follow-up {schedule} (>= {follow_cm:g} cm, < {fna_cm:g} cm)"
    else:
        advice = f"no FNA or follow-up (< {follow_cm:g} cm)"
    comps["recommendation"] = advice
    return make_result(
        "ACR TI-RADS",
        total,
        "points",
        f"TR{level}",
        f"ACR TI-RADS TR{level} ({label}, {total} points): {advice}.",
        comps,
        _TIRADS_REF,
    )


_BIRADS_RANK = {"1": 0, "2": 1, "3": 2, "0": 3, "4": 4, "4A": 5, "4B": 6, "4C": 7, "5": 8, "6": 9}
_BIRADS_TEXT = {
    "0": "incomplete: additional imaging evaluation and/or prior mammograms needed",
    "1": "negative: routine screening",
    "2": "benign: routine screening",
    "3": "probably benign (<= 2% malignancy): short-interval (6-month) follow-up",
    "4": "suspicious (> 2% to < 95%): tissue diagnosis",
    "4A": "low suspicion (> 2% to <= 10%): tissue diagnosis",
    "4B": "moderate suspicion (> 10% to <= 50%): tissue diagnosis",
    "4C": "high suspicion (> 50% to < 95%): tissue diagnosis",
    "5": "highly suggestive of malignancy (>= 95%): tissue diagnosis",
    "6": "known biopsy-proven malignancy: surgical excision when clinically appropriate",
}
_CALC = {
    "none": None,
    "typically_benign": "2",
    "coarse_heterogeneous": "4B",
    "amorphous": "4B",
    "fine_pleomorphic": "4B",
    "fine_linear_branching": "4C",
}


def calculate_birads(
    mass_shape: Literal["none", "oval", "round", "irregular"] = "none",
    mass_margin: Literal[
        "none", "circumscribed", "obscured", "microlobulated", "indistinct", "spiculated"
    ] = "none",
    mass_typically_benign: bool = False,
    mass_stable_2_years: bool = False,
    calcification_morphology: Literal[
        "none",
        "typically_benign",
        "coarse_heterogeneous",
        "amorphous",
        "fine_pleomorphic",
        "fine_linear_branching",
    ] = "none",
    architectural_distortion: bool = False,
    exam_complete: bool = True,
    known_biopsy_proven_malignancy: bool = False,
) -> ScoreResult:
    """BI-RADS assessment category (0-6, with 4A/4B/4C) from structured breast-imaging lexicon findings.

    Args:
        mass_shape: Mass shape: "none" (no mass), "oval", "round" or "irregular".
        mass_margin: Mass margin: "none" (no mass), "circumscribed", "obscured", "microlobulated",
            "indistinct" or "spiculated".
        mass_typically_benign: True if the mass is characteristically benign (simple cyst,
            fat-containing lesion such as lipoma, hamartoma or oil cyst, intramammary lymph node).
        mass_stable_2_years: True if a circumscribed mass is unchanged for >= 2 years.
        calcification_morphology: Most suspicious calcification morphology: "none", "typically_benign",
            "coarse_heterogeneous", "amorphous", "fine_pleomorphic" or "fine_linear_branching".
        architectural_distortion: True for architectural distortion without a surgical explanation.
        exam_complete: False if the work-up is incomplete (category 0).
        known_biopsy_proven_malignancy: True for a finding already proven malignant by biopsy (category 6).
    """
    fn = "calculate_birads"
    shape = check_choice(fn, "mass_shape", mass_shape, ("none", "oval", "round", "irregular"))
    margin = check_choice(
        fn,
        "mass_margin",
        mass_margin,
        ("none", "circumscribed", "obscured", "microlobulated", "indistinct", "spiculated"),
    )
    benign_mass = check_bool(fn, "mass_typically_benign", mass_typically_benign)
    stable = check_bool(fn, "mass_stable_2_years", mass_stable_2_years)
    calc = check_choice(fn, "calcification_morphology", calcification_morphology, tuple(_CALC))
    distortion = check_bool(fn, "architectural_distortion", architectural_distortion)
    complete = check_bool(fn, "exam_complete", exam_complete)
    malignant = check_bool(fn, "known_biopsy_proven_malignancy", known_biopsy_proven_malignancy)
    if (shape == "none") != (margin == "none"):
        raise CalculatorInputError(
            fn, "mass_margin", "'none' exactly when mass_shape is 'none' (and vice versa)", margin
        )
    findings: dict[str, str] = {}
    if shape != "none":
        if benign_mass:
            findings["mass"] = "2"
        elif shape == "irregular" and margin == "spiculated":
            findings["mass"] = "5"
        elif shape == "irregular" or margin in ("spiculated", "indistinct", "microlobulated"):
            findings["mass"] = "4"
        elif margin == "obscured":
            findings["mass"] = "0"
        else:  # circumscribed oval or round solid mass
            findings["mass"] = "2" if stable else "3"
    if _CALC[calc] is not None:
        findings["calcifications"] = _CALC[calc]
    if distortion:
        findings["architectural_distortion"] = "4"
    if malignant:
        category = "6"
    elif not complete:
        category = "0"
    elif not findings:
        category = "1"
    else:
        category = max(findings.values(), key=_BIRADS_RANK.__getitem__)
    score = int(category[0])
    comps: dict[str, str | None] = {
        "mass": findings.get("mass"),
        "calcifications": findings.get("calcifications"),
        "architectural_distortion": findings.get("architectural_distortion"),
    }
    return make_result(
        "BI-RADS assessment",
        score,
        "category",
        f"BI-RADS {category}",
        f"BI-RADS {category}: {_BIRADS_TEXT[category]}.",
        comps,
        "D'Orsi CJ, Sickles EA, Mendelson EB, Morris EA et al. ACR BI-RADS Atlas, Breast Imaging "
        "Reporting and "
        "Data System, 5th ed. Reston, VA: American College of Radiology, 2013; Sickles EA. Radiology "
        "1991;179:463-468.",
    )
