"""Renal instruments: Cockcroft-Gault creatinine clearance, CKD-EPI 2021 eGFR, bedside
Schwartz (paediatric) eGFR, fractional excretion of sodium and free-water deficit.

Creatinine is in mg/dL throughout (to convert from umol/L divide by 88.4). Equations return the
unrounded value; categories are assigned from that value.
"""

from __future__ import annotations

from typing import Literal

from ._core import ScoreResult, check_choice, check_number, make_result

_SEX = ("male", "female")


def _kdigo_g(gfr: float) -> tuple[str, str]:
    # KDIGO 2012 GFR categories (mL/min/1.73 m2).
    if gfr >= 90:
        return "G1", "normal or high"
    if gfr >= 60:
        return "G2", "mildly decreased"
    if gfr >= 45:
        return "G3a", "mildly to moderately decreased"
    if gfr >= 30:
        return "G3b", "moderately to severely decreased"
    if gfr >= 15:
        return "G4", "severely decreased"
    return "G5", "kidney failure range"


_KDIGO = (
    "KDIGO 2012 Clinical Practice Guideline for the Evaluation and Management of CKD. Kidney Int "
    "Suppl 2013;3:1-150."
)


def calculate_creatinine_clearance(
    age: float, weight_kg: float, creatinine_mg_dl: float, sex: Literal["male", "female"]
) -> ScoreResult:
    """Cockcroft-Gault creatinine clearance in mL/min (for drug dosing).

    Args:
        age: Age in years, 18-120.
        weight_kg: Body weight in kg, 20-350 (the equation was derived with actual body weight).
        creatinine_mg_dl: Stable serum creatinine in mg/dL, 0.1-30.
        sex: "male" or "female" (female x 0.85).
    """
    fn = "calculate_creatinine_clearance"
    a = check_number(fn, "age", age, 18, 120, "years")
    w = check_number(fn, "weight_kg", weight_kg, 20, 350, "kg")
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0.1, 30, "mg/dL")
    s = check_choice(fn, "sex", sex, _SEX)
    factor = 0.85 if s == "female" else 1.0
    crcl = (140.0 - a) * w / (72.0 * cr) * factor
    # FDA renal-impairment categories for creatinine clearance (drug labelling).
    if crcl >= 90:
        cat = "normal"
    elif crcl >= 60:
        cat = "mild impairment"
    elif crcl >= 30:
        cat = "moderate impairment"
    elif crcl >= 15:
        cat = "severe impairment"
    else:
        cat = "kidney failure"
    return make_result(
        "Cockcroft-Gault creatinine clearance",
        crcl,
        "mL/min",
        cat,
        f"Creatinine clearance {crcl:.0f} mL/min ({cat}); use for drug-dose adjustment.",
        {"sex_factor": factor},
        "Cockcroft DW, Gault MH. Prediction of creatinine clearance from serum creatinine. Nephron "
        "1976;16:31-41; categories: FDA guidance, Pharmacokinetics in patients with impaired renal "
        "function (2010 draft).",
    )


def calculate_ckd_epi_2021(
    creatinine_mg_dl: float, age: float, sex: Literal["male", "female"]
) -> ScoreResult:
    """Race-free CKD-EPI 2021 creatinine eGFR in mL/min/1.73 m2 with its KDIGO G category.

    Args:
        creatinine_mg_dl: Serum creatinine (IDMS-traceable) in mg/dL, 0.1-30.
        age: Age in years, 18-120.
        sex: "male" or "female".
    """
    fn = "calculate_ckd_epi_2021"
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0.1, 30, "mg/dL")
    a = check_number(fn, "age", age, 18, 120, "years")
    s = check_choice(fn, "sex", sex, _SEX)
    if s == "female":
        kappa, alpha, factor = 0.7, -0.241, 1.012
    else:
        kappa, alpha, factor = 0.9, -0.302, 1.0
    ratio = cr / kappa
    gfr = 142.0 * min(ratio, 1.0) ** alpha * max(ratio, 1.0) ** -1.200 * 0.9938**a * factor
    g, text = _kdigo_g(gfr)
    return make_result(
        "CKD-EPI 2021 eGFR",
        gfr,
        "mL/min/1.73 m2",
        g,
        f"eGFR {gfr:.0f} mL/min/1.73 m2: KDIGO {g} ({text}).",
        {"kappa": kappa, "alpha": alpha, "sex_factor": factor},
        "Inker LA et al. New creatinine- and cystatin C-based equations to estimate GFR without race. "
        "N Engl J Med 2021;385:1737-1749; " + _KDIGO,
    )


def calculate_bedside_schwartz(height_cm: float, creatinine_mg_dl: float, age: float) -> ScoreResult:
    """Bedside Schwartz eGFR for children (0.413 x height / creatinine) in mL/min/1.73 m2.

    Args:
        height_cm: Height in cm, 40-220.
        creatinine_mg_dl: Serum creatinine (enzymatic, IDMS-traceable) in mg/dL, 0.05-30.
        age: Age in years, 1-18 (the range the equation was derived in).
    """
    fn = "calculate_bedside_schwartz"
    h = check_number(fn, "height_cm", height_cm, 40, 220, "cm")
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0.05, 30, "mg/dL")
    check_number(fn, "age", age, 1, 18, "years")
    gfr = 0.413 * h / cr
    g, text = _kdigo_g(gfr)
    return make_result(
        "Bedside Schwartz eGFR",
        gfr,
        "mL/min/1.73 m2",
        g,
        f"eGFR {gfr:.0f} mL/min/1.73 m2: KDIGO {g} ({text}).",
        {"k": 0.413},
        "Schwartz GJ et al. New equations to estimate GFR in children with CKD. J Am Soc Nephrol "
        "2009;20:629-637; " + _KDIGO,
    )


def calculate_fena(
    urine_sodium_mmol_l: float,
    serum_sodium_mmol_l: float,
    urine_creatinine_mg_dl: float,
    serum_creatinine_mg_dl: float,
) -> ScoreResult:
    """Fractional excretion of sodium (FENa, %) to separate prerenal from intrinsic acute kidney injury.

    Args:
        urine_sodium_mmol_l: Urine sodium in mmol/L, 0-400.
        serum_sodium_mmol_l: Serum sodium in mmol/L, 80-220.
        urine_creatinine_mg_dl: Urine creatinine in mg/dL, 1-1000.
        serum_creatinine_mg_dl: Serum creatinine in mg/dL, 0.1-30.
    """
    fn = "calculate_fena"
    una = check_number(fn, "urine_sodium_mmol_l", urine_sodium_mmol_l, 0, 400, "mmol/L")
    pna = check_number(fn, "serum_sodium_mmol_l", serum_sodium_mmol_l, 80, 220, "mmol/L")
    ucr = check_number(fn, "urine_creatinine_mg_dl", urine_creatinine_mg_dl, 1, 1000, "mg/dL")
    pcr = check_number(fn, "serum_creatinine_mg_dl", serum_creatinine_mg_dl, 0.1, 30, "mg/dL")
    fena = una * pcr / (pna * ucr) * 100.0
    if fena < 1:
        cat, text = "prerenal", "FENa < 1% suggests a prerenal cause (unreliable on diuretics)"
    elif fena <= 2:
        cat, text = "indeterminate", "FENa 1-2% is indeterminate"
    else:
        cat, text = (
            "intrinsic renal",
            "FENa > 2% suggests intrinsic renal injury such as acute tubular necrosis",
        )
    return make_result(
        "FENa",
        fena,
        "%",
        cat,
        f"FENa {fena:.2f}%: {text}.",
        {"urine_to_plasma_sodium": una / pna, "urine_to_plasma_creatinine": ucr / pcr},
        "Espinel CH. The FENa test: use in the differential diagnosis of acute renal failure. JAMA "
        "1976;236:579-581; Miller TR et al. Ann Intern Med 1978;89:47-50.",
    )


def calculate_free_water_deficit(
    sodium_mmol_l: float,
    weight_kg: float,
    age: float,
    sex: Literal["male", "female"],
    target_sodium_mmol_l: float = 140.0,
) -> ScoreResult:
    """Free-water deficit in litres for hypernatraemia: TBW x (Na / target - 1).

    Args:
        sodium_mmol_l: Serum sodium in mmol/L, 100-220.
        weight_kg: Body weight in kg, 1-350.
        age: Age in years, 0-120 (children < 18: TBW 0.6; adults 0.6 men / 0.5 women; >= 65:
            0.5 men / 0.45 women).
        sex: "male" or "female".
        target_sodium_mmol_l: Target sodium in mmol/L, 130-150 (default 140).
    """
    fn = "calculate_free_water_deficit"
    na = check_number(fn, "sodium_mmol_l", sodium_mmol_l, 100, 220, "mmol/L")
    w = check_number(fn, "weight_kg", weight_kg, 1, 350, "kg")
    a = check_number(fn, "age", age, 0, 120, "years")
    s = check_choice(fn, "sex", sex, _SEX)
    target = check_number(fn, "target_sodium_mmol_l", target_sodium_mmol_l, 130, 150, "mmol/L")
    if a < 18:
        fraction = 0.6
    elif a < 65:
        fraction = 0.6 if s == "male" else 0.5
    else:
        fraction = 0.5 if s == "male" else 0.45
    tbw = fraction * w
    deficit = tbw * (na / target - 1.0)
    if deficit > 0:
        cat = "free-water deficit"
        text = (
            f"free-water deficit {deficit:.1f} L; replace over >= 48 h, lowering sodium by no more than "
            "10-12 mmol/L per 24 h in chronic hypernatraemia"
        )
    else:
        cat = "no deficit"
        text = f"sodium at or below target {target:g} mmol/L: no free-water deficit"
    return make_result(
        "Free-water deficit",
        deficit,
        "L",
        cat,
        f"{text[0].upper()}{text[1:]}.",
        {"total_body_water_fraction": fraction, "total_body_water_l": tbw},
        "Adrogue HJ, Madias NE. Hypernatremia. N Engl J Med 2000;342:1493-1499.",
    )
