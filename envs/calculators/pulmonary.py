"""Pulmonary instruments: CURB-65, CRB-65, Wells PE, PERC, PESI and sPESI.

CURB-65 urea: Lim 2003 uses serum urea > 7 mmol/L. US laboratories report blood urea nitrogen
(BUN) in mg/dL; 7 mmol/L urea carries 7 x 2.8 = 19.6 mg/dL of nitrogen, and the usual US
statement of the criterion is "BUN > 19 mg/dL", which we follow.
"""

from __future__ import annotations

from typing import Literal

from ._core import (
    ScoreResult,
    check_bool,
    check_choice,
    check_int,
    check_number,
    make_result,
)

# Lim 2003 (abstract): 30-day mortality 1.5% for scores 0-1, 9.2% for 2, 22% for 3-5.
_CURB_MORTALITY = ("1.5%", "1.5%", "9.2%", "22%", "22%", "22%")


def calculate_curb65(
    confusion: bool,
    bun_mg_dl: float,
    respiratory_rate: float,
    systolic_bp: float,
    diastolic_bp: float,
    age: int,
) -> ScoreResult:
    """CURB-65 severity score (0-5) for community-acquired pneumonia.

    Args:
        confusion: True for new mental confusion (abbreviated mental test <= 8 or disorientation).
        bun_mg_dl: Blood urea nitrogen in mg/dL, 0-300 (> 19 mg/dL, i.e. urea > 7 mmol/L, scores 1).
        respiratory_rate: Respiratory rate in breaths/min, 0-100 (>= 30 scores 1).
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (< 90 scores 1).
        diastolic_bp: Diastolic blood pressure in mmHg, 0-250 (<= 60 scores 1).
        age: Age in years, integer 18-120 (>= 65 scores 1).
    """
    fn = "calculate_curb65"
    c = check_bool(fn, "confusion", confusion)
    bun = check_number(fn, "bun_mg_dl", bun_mg_dl, 0, 300, "mg/dL")
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    dbp = check_number(fn, "diastolic_bp", diastolic_bp, 0, 250, "mmHg")
    a = check_int(fn, "age", age, 18, 120, "years")
    comps = {
        "confusion": int(c),
        "urea": int(bun > 19),
        "respiratory_rate": int(rr >= 30),
        "blood_pressure": int(sbp < 90 or dbp <= 60),
        "age_65": int(a >= 65),
    }
    total = sum(comps.values())
    if total <= 1:
        cat, text = "low risk", "consider home treatment"
    elif total == 2:
        cat, text = "moderate risk", "consider short inpatient stay or supervised outpatient treatment"
    else:
        cat, text = "high risk", "manage in hospital as severe pneumonia; assess for ICU if 4-5"
    return make_result(
        "CURB-65",
        total,
        "points",
        cat,
        f"CURB-65 {total}/5 ({cat}; 30-day mortality about {_CURB_MORTALITY[total]}): {text}.",
        comps,
        "Lim WS et al. Defining community acquired pneumonia severity on presentation to hospital: an "
        "international derivation and validation study. Thorax 2003;58:377-382.",
    )


def calculate_crb65(
    confusion: bool,
    respiratory_rate: float,
    systolic_bp: float,
    diastolic_bp: float,
    age: int,
) -> ScoreResult:
    """CRB-65 (CURB-65 without urea, 0-4) for pneumonia severity in the community.

    Args:
        confusion: True for new mental confusion.
        respiratory_rate: Respiratory rate in breaths/min, 0-100 (>= 30 scores 1).
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (< 90 scores 1).
        diastolic_bp: Diastolic blood pressure in mmHg, 0-250 (<= 60 scores 1).
        age: Age in years, integer 18-120 (>= 65 scores 1).
    """
    fn = "calculate_crb65"
    c = check_bool(fn, "confusion", confusion)
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    dbp = check_number(fn, "diastolic_bp", diastolic_bp, 0, 250, "mmHg")
    a = check_int(fn, "age", age, 18, 120, "years")
    comps = {
        "confusion": int(c),
        "respiratory_rate": int(rr >= 30),
        "blood_pressure": int(sbp < 90 or dbp <= 60),
        "age_65": int(a >= 65),
    }
    total = sum(comps.values())
    if total == 0:
        cat, text = "low risk", "likely suitable for home treatment"
    elif total <= 2:
        cat, text = "increased risk", "consider hospital referral"
    else:
        cat, text = "high risk", "urgent hospital admission"
    return make_result(
        "CRB-65",
        total,
        "points",
        cat,
        f"CRB-65 {total}/4 ({cat}): {text}.",
        comps,
        "Lim WS et al. Thorax 2003;58:377-382; Lim WS et al. BTS guidelines for the management of community "
        "acquired pneumonia in adults: update 2009. Thorax 2009;64(Suppl 3):iii1-iii55.",
    )


def calculate_wells_pe(
    clinical_signs_dvt: bool,
    pe_most_likely: bool,
    heart_rate: float,
    immobilization_or_recent_surgery: bool,
    previous_dvt_pe: bool,
    hemoptysis: bool,
    malignancy: bool,
    model: Literal["two_tier", "three_tier"] = "two_tier",
) -> ScoreResult:
    """Wells score for pulmonary embolism (0-12.5) with the two- or three-tier interpretation.

    Args:
        clinical_signs_dvt: True for clinical signs and symptoms of DVT (scores 3).
        pe_most_likely: True if PE is the most likely diagnosis (scores 3).
        heart_rate: Heart rate in beats/min, 0-350 (> 100 scores 1.5).
        immobilization_or_recent_surgery: True for immobilisation >= 3 days or surgery within 4 weeks (1.5).
        previous_dvt_pe: True for previous DVT or PE (1.5).
        hemoptysis: True for haemoptysis (1).
        malignancy: True for malignancy treated within 6 months or palliative (1).
        model: "two_tier" (default; > 4 PE likely) or "three_tier" (< 2 low, 2-6 moderate, > 6 high).
    """
    fn = "calculate_wells_pe"
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    m = check_choice(fn, "model", model, ("two_tier", "three_tier"))
    comps = {
        "clinical_signs_dvt": 3.0 * check_bool(fn, "clinical_signs_dvt", clinical_signs_dvt),
        "pe_most_likely": 3.0 * check_bool(fn, "pe_most_likely", pe_most_likely),
        "heart_rate_gt_100": 1.5 * (hr > 100),
        "immobilization_or_recent_surgery": 1.5
        * check_bool(fn, "immobilization_or_recent_surgery", immobilization_or_recent_surgery),
        "previous_dvt_pe": 1.5 * check_bool(fn, "previous_dvt_pe", previous_dvt_pe),
        "hemoptysis": 1.0 * check_bool(fn, "hemoptysis", hemoptysis),
        "malignancy": 1.0 * check_bool(fn, "malignancy", malignancy),
    }
    total = sum(comps.values())
    if m == "two_tier":
        if total > 4:
            cat, text = "PE likely", "proceed to CT pulmonary angiography"
        else:
            cat, text = "PE unlikely", "a negative D-dimer excludes PE"
    elif total > 6:
        cat, text = "high probability", "high pretest probability of PE: imaging (CTPA) without D-dimer"
    elif total >= 2:
        cat, text = (
            "moderate probability",
            "moderate pretest probability: high-sensitivity D-dimer, imaging if positive",
        )
    else:
        cat, text = "low probability", "low pretest probability: apply PERC or D-dimer"
    return make_result(
        "Wells PE",
        total,
        "points",
        cat,
        f"Wells PE {total:g} ({cat}): {text}.",
        comps,
        "Wells PS et al. Derivation of a simple clinical model to categorize patients probability of "
        "pulmonary embolism. Thromb Haemost 2000;83:416-420.",
    )


def calculate_perc(
    age: int,
    heart_rate: float,
    spo2: float,
    unilateral_leg_swelling: bool,
    hemoptysis: bool,
    recent_surgery_or_trauma: bool,
    prior_pe_or_dvt: bool,
    hormone_use: bool,
) -> ScoreResult:
    """Pulmonary Embolism Rule-out Criteria (PERC): number of criteria present (0-8).

    Args:
        age: Age in years, integer 18-120 (>= 50 is a criterion).
        heart_rate: Heart rate in beats/min, 0-350 (>= 100 is a criterion).
        spo2: Oxygen saturation on room air in percent, 0-100 (< 95 is a criterion).
        unilateral_leg_swelling: True for unilateral leg swelling.
        hemoptysis: True for haemoptysis.
        recent_surgery_or_trauma: True for surgery or trauma requiring hospitalisation within 4 weeks.
        prior_pe_or_dvt: True for prior PE or DVT.
        hormone_use: True for oral contraceptives, hormone replacement or oestrogen use.
    """
    fn = "calculate_perc"
    a = check_int(fn, "age", age, 18, 120, "years")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    s = check_number(fn, "spo2", spo2, 0, 100, "%")
    comps = {
        "age_ge_50": int(a >= 50),
        "heart_rate_ge_100": int(hr >= 100),
        "spo2_lt_95": int(s < 95),
        "unilateral_leg_swelling": int(check_bool(fn, "unilateral_leg_swelling", unilateral_leg_swelling)),
        "hemoptysis": int(check_bool(fn, "hemoptysis", hemoptysis)),
        "recent_surgery_or_trauma": int(check_bool(fn, "recent_surgery_or_trauma", recent_surgery_or_trauma)),
        "prior_pe_or_dvt": int(check_bool(fn, "prior_pe_or_dvt", prior_pe_or_dvt)),
        "hormone_use": int(check_bool(fn, "hormone_use", hormone_use)),
    }
    total = sum(comps.values())
    if total == 0:
        cat, text = (
            "PERC negative",
            "PE can be ruled out without testing if the gestalt pretest probability is low (< 15%)",
        )
    else:
        cat, text = (
            "PERC positive",
            "PE cannot be ruled out by PERC; use D-dimer or imaging per pretest probability",
        )
    return make_result(
        "PERC rule",
        total,
        "criteria",
        cat,
        f"PERC {total}/8 ({cat}): {text}.",
        comps,
        "Kline JA et al. Clinical criteria to prevent unnecessary diagnostic testing in emergency department "
        "patients with suspected pulmonary embolism. J Thromb Haemost 2004;2:1247-1255.",
    )


_PESI_CLASSES = (
    (65, "Class I", "very low", "0-1.6%"),
    (85, "Class II", "low", "1.7-3.5%"),
    (105, "Class III", "intermediate", "3.2-7.1%"),
    (125, "Class IV", "high", "4.0-11.4%"),
    (10_000, "Class V", "very high", "10.0-24.5%"),
)


def calculate_pesi(
    age: int,
    sex: Literal["male", "female"],
    cancer: bool,
    heart_failure: bool,
    chronic_lung_disease: bool,
    heart_rate: float,
    systolic_bp: float,
    respiratory_rate: float,
    temperature_c: float,
    altered_mental_status: bool,
    spo2: float,
) -> ScoreResult:
    """Pulmonary Embolism Severity Index (PESI) points and risk class I-V.

    Args:
        age: Age in years, integer 18-120 (scores 1 point per year).
        sex: "male" (10 points) or "female".
        cancer: True for cancer (30).
        heart_failure: True for chronic heart failure (10).
        chronic_lung_disease: True for chronic lung disease (10).
        heart_rate: Pulse in beats/min, 0-350 (>= 110 scores 20).
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (< 100 scores 30).
        respiratory_rate: Respiratory rate in breaths/min, 0-100 (>= 30 scores 20).
        temperature_c: Temperature in degrees C, 25-45 (< 36 scores 20).
        altered_mental_status: True for disorientation, lethargy, stupor or coma (60).
        spo2: Arterial oxygen saturation in percent, 0-100 (< 90 scores 20).
    """
    fn = "calculate_pesi"
    a = check_int(fn, "age", age, 18, 120, "years")
    s = check_choice(fn, "sex", sex, ("male", "female"))
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    t = check_number(fn, "temperature_c", temperature_c, 25, 45, "degrees C")
    sat = check_number(fn, "spo2", spo2, 0, 100, "%")
    comps = {
        "age": a,
        "male_sex": 10 * (s == "male"),
        "cancer": 30 * check_bool(fn, "cancer", cancer),
        "heart_failure": 10 * check_bool(fn, "heart_failure", heart_failure),
        "chronic_lung_disease": 10 * check_bool(fn, "chronic_lung_disease", chronic_lung_disease),
        "heart_rate_ge_110": 20 * (hr >= 110),
        "systolic_bp_lt_100": 30 * (sbp < 100),
        "respiratory_rate_ge_30": 20 * (rr >= 30),
        "temperature_lt_36": 20 * (t < 36),
        "altered_mental_status": 60 * check_bool(fn, "altered_mental_status", altered_mental_status),
        "spo2_lt_90": 20 * (sat < 90),
    }
    total = sum(comps.values())
    for upper, cls, risk, mortality in _PESI_CLASSES:
        if total <= upper:
            break
    return make_result(
        "PESI",
        total,
        "points",
        cls,
        f"PESI {total} ({cls}, {risk} risk): 30-day mortality {mortality}"
        + ("; candidate for outpatient treatment." if total <= 85 else "; inpatient management."),
        comps,
        "Aujesky D et al. Derivation and validation of a prognostic model for pulmonary embolism. "
        "Am J Respir Crit Care Med 2005;172:1041-1046.",
    )


def calculate_spesi(
    age: int,
    cancer: bool,
    chronic_cardiopulmonary_disease: bool,
    heart_rate: float,
    systolic_bp: float,
    spo2: float,
) -> ScoreResult:
    """Simplified PESI (sPESI, 0-6): 0 points is low 30-day mortality risk.

    Args:
        age: Age in years, integer 18-120 (> 80 scores 1).
        cancer: True for cancer.
        chronic_cardiopulmonary_disease: True for chronic heart failure or chronic lung disease.
        heart_rate: Pulse in beats/min, 0-350 (>= 110 scores 1).
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (< 100 scores 1).
        spo2: Arterial oxygen saturation in percent, 0-100 (< 90 scores 1).
    """
    fn = "calculate_spesi"
    a = check_int(fn, "age", age, 18, 120, "years")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    sat = check_number(fn, "spo2", spo2, 0, 100, "%")
    comps = {
        "age_gt_80": int(a > 80),
        "cancer": int(check_bool(fn, "cancer", cancer)),
        "chronic_cardiopulmonary_disease": int(
            check_bool(fn, "chronic_cardiopulmonary_disease", chronic_cardiopulmonary_disease)
        ),
        "heart_rate_ge_110": int(hr >= 110),
        "systolic_bp_lt_100": int(sbp < 100),
        "spo2_lt_90": int(sat < 90),
    }
    total = sum(comps.values())
    if total == 0:
        cat, text = "low risk", "30-day mortality about 1.0%"
    else:
        cat, text = "high risk", "30-day mortality about 10.9%"
    return make_result(
        "sPESI",
        total,
        "points",
        cat,
        f"sPESI {total} ({cat}): {text}.",
        comps,
        "Jimenez D et al. Simplification of the Pulmonary Embolism Severity Index for prognostication in "
        "patients with acute symptomatic pulmonary embolism. Arch Intern Med 2010;170:1383-1389.",
    )
