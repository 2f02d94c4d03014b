"""General-medicine formulas: BMI, anion gap, corrected calcium, corrected sodium, serum osmolality.

Chemistry units follow US reporting (glucose and BUN in mg/dL, calcium in mg/dL, albumin in
g/dL); electrolytes are in mmol/L (= mEq/L for monovalent ions). The molar conversions are
glucose 18 mg/dL per mmol/L and urea nitrogen 2.8 mg/dL per mmol/L.
"""

from __future__ import annotations

from typing import Literal

from ._core import ScoreResult, check_choice, check_number, check_optional_number, make_result


def calculate_bmi(weight_kg: float, height_cm: float) -> ScoreResult:
    """Body-mass index (kg/m2) with the WHO adult category.

    Args:
        weight_kg: Body weight in kg, 1-700.
        height_cm: Height in cm, 30-280.
    """
    fn = "calculate_bmi"
    w = check_number(fn, "weight_kg", weight_kg, 1, 700, "kg")
    h = check_number(fn, "height_cm", height_cm, 30, 280, "cm")
    bmi = w / (h / 100.0) ** 2
    if bmi < 18.5:
        cat = "underweight"
    elif bmi < 25:
        cat = "normal weight"
    elif bmi < 30:
        cat = "overweight"
    elif bmi < 35:
        cat = "obesity class I"
    elif bmi < 40:
        cat = "obesity class II"
    else:
        cat = "obesity class III"
    return make_result(
        "Body-mass index",
        bmi,
        "kg/m2",
        cat,
        f"BMI {bmi:.1f} kg/m2: {cat} (WHO adult classification).",
        {"height_m": h / 100.0},
        "World Health Organization. Obesity: preventing and managing the global epidemic. WHO Technical "
        "Report Series 894, 2000.",
    )


def calculate_anion_gap(
    sodium: float, chloride: float, bicarbonate: float, albumin_g_dl: float | None = None
) -> ScoreResult:
    """Serum anion gap Na - (Cl + HCO3) in mmol/L, optionally corrected for albumin.

    Args:
        sodium: Serum sodium in mmol/L, 80-220.
        chloride: Serum chloride in mmol/L, 50-170.
        bicarbonate: Serum bicarbonate (total CO2) in mmol/L, 1-80.
        albumin_g_dl: Optional serum albumin in g/dL, 0.5-7; the gap is then corrected by
            +2.5 mmol/L per 1 g/dL below 4.0 (Figge) and classified on the corrected value.
    """
    fn = "calculate_anion_gap"
    na = check_number(fn, "sodium", sodium, 80, 220, "mmol/L")
    cl = check_number(fn, "chloride", chloride, 50, 170, "mmol/L")
    hco3 = check_number(fn, "bicarbonate", bicarbonate, 1, 80, "mmol/L")
    alb = check_optional_number(fn, "albumin_g_dl", albumin_g_dl, 0.5, 7, "g/dL")
    gap = na - (cl + hco3)
    corrected = gap + 2.5 * (4.0 - alb) if alb is not None else None
    judged = corrected if corrected is not None else gap
    # Reference interval 3-11 mmol/L with ion-selective electrodes (Winter 1990); labs vary.
    if judged > 11:
        cat, text = (
            "elevated",
            "elevated anion gap: look for unmeasured anions (lactate, ketones, toxins, uraemia)",
        )
    elif judged < 3:
        cat, text = (
            "low",
            "low anion gap: consider hypoalbuminaemia, paraproteins, lithium or laboratory error",
        )
    else:
        cat, text = "normal", "anion gap within the 3-11 mmol/L reference interval"
    label = f"anion gap {gap:.1f} mmol/L" + (
        f" (albumin-corrected {corrected:.1f})" if corrected is not None else ""
    )
    return make_result(
        "Anion gap",
        gap,
        "mmol/L",
        cat,
        f"{label[0].upper()}{label[1:]}: {text}.",
        {"albumin_corrected_gap": corrected},
        "Winter SD et al. The fall of the serum anion gap. Arch Intern Med 1990;150:311-313; albumin "
        "correction: Figge J et al. Crit Care Med 1998;26:1807-1810.",
    )


def calculate_corrected_calcium(calcium_mg_dl: float, albumin_g_dl: float) -> ScoreResult:
    """Albumin-corrected total calcium (mg/dL): Ca + 0.8 x (4.0 - albumin).

    Args:
        calcium_mg_dl: Total serum calcium in mg/dL, 2-20.
        albumin_g_dl: Serum albumin in g/dL, 0.5-7.
    """
    fn = "calculate_corrected_calcium"
    ca = check_number(fn, "calcium_mg_dl", calcium_mg_dl, 2, 20, "mg/dL")
    alb = check_number(fn, "albumin_g_dl", albumin_g_dl, 0.5, 7, "g/dL")
    corrected = ca + 0.8 * (4.0 - alb)
    if corrected < 8.5:
        cat = "hypocalcaemia"
    elif corrected > 10.5:
        cat = "hypercalcaemia"
    else:
        cat = "normal"
    return make_result(
        "Corrected calcium",
        corrected,
        "mg/dL",
        cat,
        f"Albumin-corrected calcium {corrected:.2f} mg/dL: {cat} (reference 8.5-10.5 mg/dL); "
        "measure ionised calcium when it matters.",
        {"correction_mg_dl": corrected - ca},
        "Payne RB et al. Interpretation of serum calcium in patients with abnormal serum proteins. "
        "BMJ 1973;4:643-646.",
    )


def calculate_corrected_sodium(
    sodium_mmol_l: float, glucose_mg_dl: float, formula: Literal["katz", "hillier"] = "katz"
) -> ScoreResult:
    """Sodium corrected for hyperglycaemia: Na + k x (glucose - 100) / 100 mmol/L.

    Args:
        sodium_mmol_l: Measured serum sodium in mmol/L, 80-220.
        glucose_mg_dl: Serum glucose in mg/dL, 10-3000.
        formula: "katz" (k = 1.6, default) or "hillier" (k = 2.4).
    """
    fn = "calculate_corrected_sodium"
    na = check_number(fn, "sodium_mmol_l", sodium_mmol_l, 80, 220, "mmol/L")
    glu = check_number(fn, "glucose_mg_dl", glucose_mg_dl, 10, 3000, "mg/dL")
    f = check_choice(fn, "formula", formula, ("katz", "hillier"))
    k = 1.6 if f == "katz" else 2.4
    corrected = na + k * (glu - 100.0) / 100.0
    cat = "hyponatraemia" if corrected < 135 else "hypernatraemia" if corrected > 145 else "normal"
    return make_result(
        "Corrected sodium",
        corrected,
        "mmol/L",
        cat,
        f"Glucose-corrected sodium ({f}) {corrected:.1f} mmol/L: {cat} (reference 135-145).",
        {"factor_per_100_mg_dl": k},
        "Katz MA. Hyperglycemia-induced hyponatremia: calculation of expected serum sodium depression. "
        "N Engl J Med 1973;289:843-844; Hillier TA et al. Am J Med 1999;106:399-403.",
    )


def calculate_serum_osmolality(
    sodium_mmol_l: float,
    glucose_mg_dl: float,
    bun_mg_dl: float,
    ethanol_mg_dl: float | None = None,
    measured_osmolality_mosm_kg: float | None = None,
) -> ScoreResult:
    """Calculated serum osmolality 2 Na + glucose/18 + BUN/2.8 (mOsm/kg), with the osmolal gap.

    Args:
        sodium_mmol_l: Serum sodium in mmol/L, 80-220.
        glucose_mg_dl: Serum glucose in mg/dL, 10-3000.
        bun_mg_dl: Blood urea nitrogen in mg/dL, 1-300.
        ethanol_mg_dl: Optional serum ethanol in mg/dL, 0-1000 (adds ethanol/3.7).
        measured_osmolality_mosm_kg: Optional measured osmolality in mOsm/kg, 150-500; gives the
            osmolal gap (> 10 is elevated).
    """
    fn = "calculate_serum_osmolality"
    na = check_number(fn, "sodium_mmol_l", sodium_mmol_l, 80, 220, "mmol/L")
    glu = check_number(fn, "glucose_mg_dl", glucose_mg_dl, 10, 3000, "mg/dL")
    bun = check_number(fn, "bun_mg_dl", bun_mg_dl, 1, 300, "mg/dL")
    eth = check_optional_number(fn, "ethanol_mg_dl", ethanol_mg_dl, 0, 1000, "mg/dL")
    measured = check_optional_number(
        fn, "measured_osmolality_mosm_kg", measured_osmolality_mosm_kg, 150, 500, "mOsm/kg"
    )
    osm = 2.0 * na + glu / 18.0 + bun / 2.8 + (eth / 3.7 if eth is not None else 0.0)
    gap = measured - osm if measured is not None else None
    if gap is not None and gap > 10:
        cat, text = "elevated osmolal gap", f"osmolal gap {gap:.0f} > 10: consider toxic alcohols"
    elif osm < 275:
        cat, text = "low", "below the 275-295 mOsm/kg reference interval"
    elif osm > 295:
        cat, text = "high", "above the 275-295 mOsm/kg reference interval"
    else:
        cat, text = "normal", "within the 275-295 mOsm/kg reference interval"
    return make_result(
        "Calculated serum osmolality",
        osm,
        "mOsm/kg",
        cat,
        f"Calculated osmolality {osm:.0f} mOsm/kg: {text}.",
        {"osmolal_gap": gap},
        "Dorwart WV, Chalmers L. Comparison of methods for calculating serum osmolality from chemical "
        "concentrations. Clin Chem 1975;21:190-194; ethanol term: Purssell RA et al. Ann Emerg Med "
        "2001;38:653-659.",
    )
