"""Hepatology and GI-bleeding instruments: MELD-Na (OPTN/UNOS 2016), Child-Pugh, Glasgow-Blatchford.

MELD-Na follows the OPTN/UNOS policy calculation (in force from January 2016), not the Kim 2008
paper's algebraically different sodium term:

1. bilirubin, INR and creatinine below 1.0 are set to 1.0; creatinine above 4.0 is set to 4.0;
   dialysis at least twice (or 24 h of CVVHD) in the past week sets creatinine to 4.0;
2. MELD(i) = 0.957 ln(Cr) + 0.378 ln(bili) + 1.120 ln(INR) + 0.643, rounded to the tenth and
   multiplied by 10;
3. only if MELD(i) > 11: MELD = MELD(i) + 1.32 (137 - Na) - 0.033 MELD(i) (137 - Na), with
   sodium bounded to 125-137 mmol/L;
4. the result is rounded to a whole number and capped at 40.
"""

from __future__ import annotations

import math
from typing import Literal

from ._core import ScoreResult, check_bool, check_choice, check_number, make_result

# Wiesner R et al. Gastroenterology 2003;124:91-96: 90-day mortality by MELD band.
_MELD_BANDS = (
    (9, "MELD < 10", "1.9%"),
    (19, "MELD 10-19", "6.0%"),
    (29, "MELD 20-29", "19.6%"),
    (39, "MELD 30-39", "52.6%"),
    (40, "MELD >= 40", "71.3%"),
)


def _round_half_up(x: float) -> int:
    return math.floor(x + 0.5)


def calculate_meld_na(
    bilirubin_mg_dl: float, inr: float, creatinine_mg_dl: float, sodium_mmol_l: float, on_dialysis: bool
) -> ScoreResult:
    """MELD-Na score (6-40) by the OPTN/UNOS 2016 calculation for liver-transplant allocation.

    Args:
        bilirubin_mg_dl: Total bilirubin in mg/dL, 0.1-100 (values < 1 are set to 1).
        inr: International normalised ratio, 0.5-20 (values < 1 are set to 1).
        creatinine_mg_dl: Serum creatinine in mg/dL, 0.1-30 (bounded to 1-4).
        sodium_mmol_l: Serum sodium in mmol/L, 80-220 (bounded to 125-137).
        on_dialysis: True for dialysis at least twice, or 24 h of CVVHD, in the past week
            (creatinine is then set to 4.0).
    """
    fn = "calculate_meld_na"
    bili = check_number(fn, "bilirubin_mg_dl", bilirubin_mg_dl, 0.1, 100, "mg/dL")
    i = check_number(fn, "inr", inr, 0.5, 20)
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0.1, 30, "mg/dL")
    na = check_number(fn, "sodium_mmol_l", sodium_mmol_l, 80, 220, "mmol/L")
    dialysis = check_bool(fn, "on_dialysis", on_dialysis)
    cr_used = 4.0 if dialysis else min(max(cr, 1.0), 4.0)
    bili_used = max(bili, 1.0)
    inr_used = max(i, 1.0)
    na_used = min(max(na, 125.0), 137.0)
    raw = 0.957 * math.log(cr_used) + 0.378 * math.log(bili_used) + 1.120 * math.log(inr_used) + 0.643
    # Rounding to the tenth then x10 is an integer; round(raw*10) avoids binary artefacts of x.x5.
    meld_i = _round_half_up(round(raw * 10.0, 9))
    if meld_i > 11:
        meld = meld_i + 1.32 * (137.0 - na_used) - 0.033 * meld_i * (137.0 - na_used)
    else:
        meld = float(meld_i)
    score = min(_round_half_up(round(meld, 9)), 40)
    for upper, band, mortality in _MELD_BANDS:
        if score <= upper:
            break
    return make_result(
        "MELD-Na",
        score,
        "points",
        band,
        f"MELD-Na {score}: 90-day mortality about {mortality} ({band}, Wiesner 2003 bands).",
        {
            "meld_i": meld_i,
            "creatinine_used": cr_used,
            "bilirubin_used": bili_used,
            "inr_used": inr_used,
            "sodium_used": na_used,
            "sodium_term_applied": meld_i > 11,
        },
        "OPTN/UNOS Policy 9.1.D (MELD-Na calculation, effective January 2016); Kim WR et al. Hyponatremia "
        "and mortality among patients on the liver-transplant waiting list. N Engl J Med 2008;359:1018-1026.",
    )


def calculate_child_pugh(
    bilirubin_mg_dl: float,
    albumin_g_dl: float,
    inr: float,
    ascites: Literal["none", "mild", "moderate_severe"],
    encephalopathy: Literal["none", "grade_1_2", "grade_3_4"],
) -> ScoreResult:
    """Child-Pugh score (5-15) and class A/B/C for cirrhosis severity.

    Args:
        bilirubin_mg_dl: Total bilirubin in mg/dL, 0.1-100 (< 2: 1, 2-3: 2, > 3: 3).
        albumin_g_dl: Serum albumin in g/dL, 0.5-7 (> 3.5: 1, 2.8-3.5: 2, < 2.8: 3).
        inr: International normalised ratio, 0.5-20 (< 1.7: 1, 1.7-2.3: 2, > 2.3: 3).
        ascites: "none" (1), "mild" (2) or "moderate_severe" (3).
        encephalopathy: "none" (1), "grade_1_2" (2) or "grade_3_4" (3).
    """
    fn = "calculate_child_pugh"
    bili = check_number(fn, "bilirubin_mg_dl", bilirubin_mg_dl, 0.1, 100, "mg/dL")
    alb = check_number(fn, "albumin_g_dl", albumin_g_dl, 0.5, 7, "g/dL")
    i = check_number(fn, "inr", inr, 0.5, 20)
    asc = check_choice(fn, "ascites", ascites, ("none", "mild", "moderate_severe"))
    enc = check_choice(fn, "encephalopathy", encephalopathy, ("none", "grade_1_2", "grade_3_4"))
    comps = {
        "bilirubin": 1 if bili < 2 else 2 if bili <= 3 else 3,
        "albumin": 1 if alb > 3.5 else 2 if alb >= 2.8 else 3,
        "inr": 1 if i < 1.7 else 2 if i <= 2.3 else 3,
        "ascites": {"none": 1, "mild": 2, "moderate_severe": 3}[asc],
        "encephalopathy": {"none": 1, "grade_1_2": 2, "grade_3_4": 3}[enc],
    }
    total = sum(comps.values())
    if total <= 6:
        cat, text = "Class A", "well-compensated disease (1-year survival about 100%, 2-year 85%)"
    elif total <= 9:
        cat, text = "Class B", "significant functional compromise (1-year survival about 80%, 2-year 60%)"
    else:
        cat, text = "Class C", "decompensated disease (1-year survival about 45%, 2-year 35%)"
    return make_result(
        "Child-Pugh",
        total,
        "points",
        cat,
        f"Child-Pugh {total} ({cat}): {text}.",
        comps,
        "Pugh RNH et al. Transection of the oesophagus for bleeding oesophageal varices. Br J Surg "
        "1973;60:646-649 (INR substituted for prothrombin time as in current practice).",
    )


def calculate_glasgow_blatchford(
    bun_mg_dl: float,
    hemoglobin_g_dl: float,
    sex: Literal["male", "female"],
    systolic_bp: float,
    heart_rate: float,
    melena: bool,
    syncope: bool,
    hepatic_disease: bool,
    cardiac_failure: bool,
) -> ScoreResult:
    """Glasgow-Blatchford bleeding score (0-23) for upper gastrointestinal haemorrhage.

    Args:
        bun_mg_dl: Blood urea nitrogen in mg/dL, 0-300 (converted to urea mmol/L by / 2.8;
            6.5-7.9: 2, 8-9.9: 3, 10-24.9: 4, >= 25: 6).
        hemoglobin_g_dl: Haemoglobin in g/dL, 1-25 (men 12-12.9: 1, 10-11.9: 3, < 10: 6;
            women 10-11.9: 1, < 10: 6).
        sex: "male" or "female".
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (100-109: 1, 90-99: 2, < 90: 3).
        heart_rate: Pulse in beats/min, 0-350 (>= 100 scores 1).
        melena: True for melaena (1).
        syncope: True for presentation with syncope (2).
        hepatic_disease: True for known hepatic disease (2).
        cardiac_failure: True for cardiac failure (2).
    """
    fn = "calculate_glasgow_blatchford"
    bun = check_number(fn, "bun_mg_dl", bun_mg_dl, 0, 300, "mg/dL")
    hb = check_number(fn, "hemoglobin_g_dl", hemoglobin_g_dl, 1, 25, "g/dL")
    s = check_choice(fn, "sex", sex, ("male", "female"))
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    urea = bun / 2.8  # mmol/L of urea: the score was published in mmol/L
    if s == "male":
        hb_points = 0 if hb >= 13 else 1 if hb >= 12 else 3 if hb >= 10 else 6
    else:
        hb_points = 0 if hb >= 12 else 1 if hb >= 10 else 6
    comps = {
        "urea": 6 if urea >= 25 else 4 if urea >= 10 else 3 if urea >= 8 else 2 if urea >= 6.5 else 0,
        "hemoglobin": hb_points,
        "systolic_bp": 3 if sbp < 90 else 2 if sbp < 100 else 1 if sbp < 110 else 0,
        "heart_rate_ge_100": int(hr >= 100),
        "melena": int(check_bool(fn, "melena", melena)),
        "syncope": 2 * check_bool(fn, "syncope", syncope),
        "hepatic_disease": 2 * check_bool(fn, "hepatic_disease", hepatic_disease),
        "cardiac_failure": 2 * check_bool(fn, "cardiac_failure", cardiac_failure),
    }
    total = sum(comps.values())
    if total <= 1:
        cat, text = "very low risk", "candidate for outpatient management without endoscopy in hospital"
    else:
        cat, text = (
            "not low risk",
            "admit; risk of needing transfusion, endoscopic therapy or surgery rises with the score",
        )
    return make_result(
        "Glasgow-Blatchford score",
        total,
        "points",
        cat,
        f"Glasgow-Blatchford {total} ({cat}): {text}.",
        comps,
        "Blatchford O, Murray WR, Blatchford M. A risk score to predict need for treatment for upper-"
        "gastrointestinal haemorrhage. Lancet 2000;356:1318-1321; threshold <= 1: Laine L et al. ACG "
        "guideline, Am J Gastroenterol 2021;116:899-917.",
    )
