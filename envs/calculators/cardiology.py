"""Cardiology and vascular instruments: HEART, TIMI UA/NSTEMI, CHA2DS2-VASc, HAS-BLED,
Wells DVT, QTc and mean arterial pressure.

Sex is always "male" or "female" (the sex the published equations and points were derived for).
"""

from __future__ import annotations

import math
from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_int,
    check_number,
    fmt,
    make_result,
)

_SEX = ("male", "female")


def calculate_heart_score(
    history: Literal["slightly", "moderately", "highly"],
    ecg: Literal["normal", "nonspecific", "st_deviation"],
    age: int,
    risk_factor_count: int,
    atherosclerotic_disease: bool,
    troponin_x_uln: float,
) -> ScoreResult:
    """HEART score (0-10) for major adverse cardiac events in emergency chest pain.

    Args:
        history: How suspicious the history is for ACS: "slightly" (0), "moderately" (1) or "highly" (2).
        ecg: "normal" (0), "nonspecific" repolarisation disturbance/LBBB/LVH/paced (1) or
            "st_deviation" (significant ST depression, 2).
        age: Age in years, integer 18-120 (< 45: 0, 45-64: 1, >= 65: 2).
        risk_factor_count: Number of risk factors (hypertension, hypercholesterolaemia, diabetes,
            obesity BMI > 30, smoking, family history), integer 0-10.
        atherosclerotic_disease: True for known atherosclerotic disease (prior MI, PCI/CABG,
            stroke/TIA, peripheral arterial disease): risk factors score 2.
        troponin_x_uln: Initial troponin as a multiple of the normal limit, 0-10000
            (<= 1: 0, > 1 to 3: 1, > 3: 2).
    """
    fn = "calculate_heart_score"
    h = check_choice(fn, "history", history, ("slightly", "moderately", "highly"))
    e = check_choice(fn, "ecg", ecg, ("normal", "nonspecific", "st_deviation"))
    a = check_int(fn, "age", age, 18, 120, "years")
    rf = check_int(fn, "risk_factor_count", risk_factor_count, 0, 10)
    ath = check_bool(fn, "atherosclerotic_disease", atherosclerotic_disease)
    trop = check_number(fn, "troponin_x_uln", troponin_x_uln, 0, 10000, "x ULN")
    comps = {
        "history": {"slightly": 0, "moderately": 1, "highly": 2}[h],
        "ecg": {"normal": 0, "nonspecific": 1, "st_deviation": 2}[e],
        "age": 0 if a < 45 else 1 if a < 65 else 2,
        "risk_factors": 2 if (rf >= 3 or ath) else 1 if rf >= 1 else 0,
        "troponin": 0 if trop <= 1 else 1 if trop <= 3 else 2,
    }
    total = sum(comps.values())
    if total <= 3:
        cat, text = "low risk", "6-week MACE about 1.7%: candidate for early discharge"
    elif total <= 6:
        cat, text = "moderate risk", "6-week MACE about 16.6%: admit for observation and non-invasive testing"
    else:
        cat, text = "high risk", "6-week MACE about 50%: early invasive strategy"
    return make_result(
        "HEART score",
        total,
        "points",
        cat,
        f"HEART {total}/10 ({cat}): {text}.",
        comps,
        "Six AJ, Backus BE, Kelder JC. Chest pain in the emergency room: value of the HEART score. "
        "Neth Heart J 2008;16:191-196; Backus BE et al. Int J Cardiol 2013;168:2153-2158.",
    )


# Antman 2000, Table 3: 14-day all-cause death, MI or urgent revascularisation.
_TIMI_RISK = {0: "4.7%", 1: "4.7%", 2: "8.3%", 3: "13.2%", 4: "19.9%", 5: "26.2%", 6: "40.9%", 7: "40.9%"}


def calculate_timi_ua(
    age: int,
    cad_risk_factor_count: int,
    known_cad_stenosis_50: bool,
    aspirin_past_7_days: bool,
    angina_episodes_24h: int,
    st_deviation_05mm: bool,
    positive_cardiac_marker: bool,
) -> ScoreResult:
    """TIMI risk score for unstable angina / non-ST-elevation MI (0-7).

    Args:
        age: Age in years, integer 18-120 (>= 65 scores 1).
        cad_risk_factor_count: Number of CAD risk factors (family history, hypertension,
            hypercholesterolaemia, diabetes, current smoking), integer 0-5 (>= 3 scores 1).
        known_cad_stenosis_50: True for known coronary stenosis >= 50 %.
        aspirin_past_7_days: True if aspirin was taken in the past 7 days.
        angina_episodes_24h: Number of anginal episodes in the past 24 h, integer 0-50 (>= 2 scores 1).
        st_deviation_05mm: True for ST deviation >= 0.5 mm on the admission ECG.
        positive_cardiac_marker: True for elevated troponin or CK-MB.
    """
    fn = "calculate_timi_ua"
    a = check_int(fn, "age", age, 18, 120, "years")
    rf = check_int(fn, "cad_risk_factor_count", cad_risk_factor_count, 0, 5)
    comps = {
        "age_ge_65": int(a >= 65),
        "three_or_more_risk_factors": int(rf >= 3),
        "known_cad_stenosis_50": int(check_bool(fn, "known_cad_stenosis_50", known_cad_stenosis_50)),
        "aspirin_past_7_days": int(check_bool(fn, "aspirin_past_7_days", aspirin_past_7_days)),
        "severe_angina": int(check_int(fn, "angina_episodes_24h", angina_episodes_24h, 0, 50) >= 2),
        "st_deviation_05mm": int(check_bool(fn, "st_deviation_05mm", st_deviation_05mm)),
        "positive_cardiac_marker": int(check_bool(fn, "positive_cardiac_marker", positive_cardiac_marker)),
    }
    total = sum(comps.values())
    cat = "low risk" if total <= 2 else "intermediate risk" if total <= 4 else "high risk"
    return make_result(
        "TIMI UA/NSTEMI",
        total,
        "points",
        cat,
        f"TIMI {total}/7 ({cat}): 14-day risk of death, MI or urgent revascularisation {_TIMI_RISK[total]}.",
        comps,
        "Antman EM et al. The TIMI risk score for unstable angina/non-ST elevation MI. JAMA "
        "2000;284:835-842.",
    )


# Lip 2010 / ESC 2010 AF guideline: adjusted stroke rate (%/year) by CHA2DS2-VASc score.
_CHADS_RATE = ("0%", "1.3%", "2.2%", "3.2%", "4.0%", "6.7%", "9.8%", "9.6%", "6.7%", "15.2%")


def calculate_cha2ds2_vasc(
    age: int,
    sex: Literal["male", "female"],
    chf: bool,
    hypertension: bool,
    diabetes: bool,
    stroke_tia_thromboembolism: bool,
    vascular_disease: bool,
) -> ScoreResult:
    """CHA2DS2-VASc stroke-risk score (0-9) in atrial fibrillation.

    Args:
        age: Age in years, integer 18-120 (65-74: 1, >= 75: 2).
        sex: "male" or "female" (female scores 1).
        chf: True for congestive heart failure or LV dysfunction.
        hypertension: True for hypertension.
        diabetes: True for diabetes mellitus.
        stroke_tia_thromboembolism: True for prior stroke, TIA or thromboembolism (scores 2).
        vascular_disease: True for prior MI, peripheral artery disease or aortic plaque.
    """
    fn = "calculate_cha2ds2_vasc"
    a = check_int(fn, "age", age, 18, 120, "years")
    s = check_choice(fn, "sex", sex, _SEX)
    comps = {
        "chf": int(check_bool(fn, "chf", chf)),
        "hypertension": int(check_bool(fn, "hypertension", hypertension)),
        "age": 2 if a >= 75 else 1 if a >= 65 else 0,
        "diabetes": int(check_bool(fn, "diabetes", diabetes)),
        "stroke_tia_thromboembolism": 2
        * check_bool(fn, "stroke_tia_thromboembolism", stroke_tia_thromboembolism),
        "vascular_disease": int(check_bool(fn, "vascular_disease", vascular_disease)),
        "sex_female": int(s == "female"),
    }
    total = sum(comps.values())
    non_sex = total - comps["sex_female"]  # ESC 2020: thresholds are sex-specific
    if non_sex == 0:
        cat, text = "low risk", "no oral anticoagulation indicated"
    elif non_sex == 1:
        cat, text = "intermediate risk", "oral anticoagulation should be considered"
    else:
        cat, text = "high risk", "oral anticoagulation recommended"
    return make_result(
        "CHA2DS2-VASc",
        total,
        "points",
        cat,
        f"CHA2DS2-VASc {total} ({cat}; adjusted stroke rate about {_CHADS_RATE[total]}/year): {text}.",
        comps,
        "Lip GYH et al. Refining clinical risk stratification for predicting stroke and thromboembolism "
        "in atrial fibrillation. Chest 2010;137:263-272; thresholds: Hindricks G et al. 2020 ESC AF "
        "guideline.",
    )


# Pisters 2010: bleeds per 100 patient-years by HAS-BLED score.
_HASBLED_RATE = {0: "1.13", 1: "1.02", 2: "1.88", 3: "3.74", 4: "8.70", 5: "12.50"}


def calculate_has_bled(
    age: int,
    uncontrolled_hypertension: bool,
    abnormal_renal_function: bool,
    abnormal_liver_function: bool,
    stroke_history: bool,
    bleeding_history_or_predisposition: bool,
    labile_inr: bool,
    antiplatelet_or_nsaid_use: bool,
    alcohol_use: bool,
) -> ScoreResult:
    """HAS-BLED major-bleeding risk score (0-9) for anticoagulated atrial fibrillation.

    Args:
        age: Age in years, integer 18-120 ("elderly": > 65 scores 1).
        uncontrolled_hypertension: True for systolic blood pressure > 160 mmHg.
        abnormal_renal_function: True for dialysis, transplant or creatinine >= 2.26 mg/dL (200 umol/L).
        abnormal_liver_function: True for cirrhosis or bilirubin > 2x ULN with AST/ALT/ALP > 3x ULN.
        stroke_history: True for prior stroke.
        bleeding_history_or_predisposition: True for prior major bleeding or predisposition (anaemia).
        labile_inr: True for unstable/high INRs or time in therapeutic range < 60 %.
        antiplatelet_or_nsaid_use: True for concomitant antiplatelet or NSAID drugs.
        alcohol_use: True for >= 8 alcoholic drinks per week.
    """
    fn = "calculate_has_bled"
    a = check_int(fn, "age", age, 18, 120, "years")
    comps = {
        "hypertension": int(check_bool(fn, "uncontrolled_hypertension", uncontrolled_hypertension)),
        "abnormal_renal_function": int(check_bool(fn, "abnormal_renal_function", abnormal_renal_function)),
        "abnormal_liver_function": int(check_bool(fn, "abnormal_liver_function", abnormal_liver_function)),
        "stroke": int(check_bool(fn, "stroke_history", stroke_history)),
        "bleeding": int(
            check_bool(fn, "bleeding_history_or_predisposition", bleeding_history_or_predisposition)
        ),
        "labile_inr": int(check_bool(fn, "labile_inr", labile_inr)),
        "elderly_gt_65": int(a > 65),
        "drugs": int(check_bool(fn, "antiplatelet_or_nsaid_use", antiplatelet_or_nsaid_use)),
        "alcohol": int(check_bool(fn, "alcohol_use", alcohol_use)),
    }
    total = sum(comps.values())
    rate = _HASBLED_RATE.get(total)
    if total >= 3:
        cat, text = "high risk", "caution and regular review; correct modifiable bleeding risk factors"
    elif total == 2:
        cat, text = "moderate risk", "address modifiable bleeding risk factors"
    else:
        cat, text = "low risk", "low bleeding risk"
    return make_result(
        "HAS-BLED",
        total,
        "points",
        cat,
        f"HAS-BLED {total} ({cat}; "
        + (f"about {rate} bleeds per 100 patient-years" if rate else "too few patients above 5 for a rate")
        + f"): {text}.",
        comps,
        "Pisters R et al. A novel user-friendly score (HAS-BLED) to assess 1-year risk of major bleeding "
        "in patients with atrial fibrillation. Chest 2010;138:1093-1100.",
    )


def calculate_wells_dvt(
    active_cancer: bool,
    paralysis_paresis_or_cast: bool,
    bedridden_or_major_surgery: bool,
    localized_tenderness: bool,
    entire_leg_swollen: bool,
    calf_swelling_3cm: bool,
    pitting_edema: bool,
    collateral_superficial_veins: bool,
    previous_dvt: bool,
    alternative_diagnosis_as_likely: bool,
) -> ScoreResult:
    """Wells score for deep-vein thrombosis (modified 2003 version, -2 to 9).

    Args:
        active_cancer: True for active cancer (treatment within 6 months or palliative).
        paralysis_paresis_or_cast: True for paralysis, paresis or recent plaster immobilisation of the leg.
        bedridden_or_major_surgery: True if bedridden >= 3 days or major surgery within 12 weeks.
        localized_tenderness: True for tenderness along the deep venous system.
        entire_leg_swollen: True if the entire leg is swollen.
        calf_swelling_3cm: True for calf swelling > 3 cm versus the other leg (10 cm below tibial tuberosity).
        pitting_edema: True for pitting oedema confined to the symptomatic leg.
        collateral_superficial_veins: True for collateral (non-varicose) superficial veins.
        previous_dvt: True for previously documented DVT.
        alternative_diagnosis_as_likely: True if an alternative diagnosis is at least as likely (-2).
    """
    fn = "calculate_wells_dvt"
    names = (
        "active_cancer",
        "paralysis_paresis_or_cast",
        "bedridden_or_major_surgery",
        "localized_tenderness",
        "entire_leg_swollen",
        "calf_swelling_3cm",
        "pitting_edema",
        "collateral_superficial_veins",
        "previous_dvt",
    )
    values = (
        active_cancer,
        paralysis_paresis_or_cast,
        bedridden_or_major_surgery,
        localized_tenderness,
        entire_leg_swollen,
        calf_swelling_3cm,
        pitting_edema,
        collateral_superficial_veins,
        previous_dvt,
    )
    comps = {n: int(check_bool(fn, n, v)) for n, v in zip(names, values)}
    comps["alternative_diagnosis_as_likely"] = -2 * check_bool(
        fn, "alternative_diagnosis_as_likely", alternative_diagnosis_as_likely
    )
    total = sum(comps.values())
    if total >= 2:
        cat, text = "DVT likely", "proceed to proximal-leg ultrasound"
    else:
        cat, text = "DVT unlikely", "a negative D-dimer excludes DVT"
    return make_result(
        "Wells DVT",
        total,
        "points",
        cat,
        f"Wells DVT {total} ({cat}): {text}.",
        comps,
        "Wells PS et al. Evaluation of D-dimer in the diagnosis of suspected deep-vein thrombosis. "
        "N Engl J Med 2003;349:1227-1235 (two-level score: >= 2 likely).",
    )


def calculate_qtc(
    qt_ms: float,
    heart_rate: float,
    formula: Literal["bazett", "fridericia", "framingham", "hodges"] = "bazett",
    sex: Literal["male", "female"] | None = None,
) -> ScoreResult:
    """Heart-rate-corrected QT interval (QTc) in ms by Bazett, Fridericia, Framingham or Hodges.

    Args:
        qt_ms: Measured QT interval in ms, 150-800.
        heart_rate: Heart rate in beats/min, 20-300 (RR interval = 60 / heart rate seconds).
        formula: "bazett" (QT/RR^0.5), "fridericia" (QT/RR^(1/3)), "framingham"
            (QT + 154 x (1 - RR)) or "hodges" (QT + 1.75 x (HR - 60)).
        sex: Optional "male" or "female" for the prolongation threshold (450 ms men, 460 ms women);
            without it the lower (male) threshold is used so no prolonged interval is missed.
    """
    fn = "calculate_qtc"
    qt = check_number(fn, "qt_ms", qt_ms, 150, 800, "ms")
    hr = check_number(fn, "heart_rate", heart_rate, 20, 300, "beats/min")
    f = check_choice(fn, "formula", formula, ("bazett", "fridericia", "framingham", "hodges"))
    if sex is not None:
        check_choice(fn, "sex", sex, _SEX)
    rr = 60.0 / hr
    if f == "bazett":
        qtc = qt / math.sqrt(rr)
    elif f == "fridericia":
        qtc = qt / rr ** (1.0 / 3.0)
    elif f == "framingham":
        qtc = qt + 154.0 * (1.0 - rr)
    else:
        qtc = qt + 1.75 * (hr - 60.0)
    limit = 460.0 if sex == "female" else 450.0
    if qtc > 500:
        cat, text = "markedly prolonged", "QTc > 500 ms: high risk of torsades de pointes"
    elif qtc >= limit:
        cat, text = "prolonged", f"QTc >= {limit:.0f} ms is prolonged"
    elif qtc <= 390:
        cat, text = "short", "QTc <= 390 ms is short"
    else:
        cat, text = "normal", "QTc within normal limits"
    return make_result(
        "QTc",
        qtc,
        "ms",
        cat,
        f"QTc ({f}) {qtc:.0f} ms: {text}.",
        {"rr_interval_s": rr, "formula": f},
        "Bazett HC. Heart 1920;7:353-370; Fridericia LS. Acta Med Scand 1920;53:469-486; Sagie A et al. "
        "(Framingham) Am J Cardiol 1992;70:797-801; Hodges M. J Am Coll Cardiol 1983;1:694. Thresholds: "
        "Rautaharju PM et al. AHA/ACCF/HRS recommendations, Circulation 2009;119:e241-e250.",
    )


def calculate_map(systolic_bp: float, diastolic_bp: float) -> ScoreResult:
    """Mean arterial pressure estimated as DBP + (SBP - DBP) / 3.

    Args:
        systolic_bp: Systolic blood pressure in mmHg, 20-350.
        diastolic_bp: Diastolic blood pressure in mmHg, 5-250; must not exceed systolic_bp.
    """
    fn = "calculate_map"
    sbp = check_number(fn, "systolic_bp", systolic_bp, 20, 350, "mmHg")
    dbp = check_number(fn, "diastolic_bp", diastolic_bp, 5, 250, "mmHg")
    if dbp > sbp:
        raise CalculatorInputError(fn, "diastolic_bp", f"at most systolic_bp ({fmt(sbp)} mmHg)", diastolic_bp)
    value = dbp + (sbp - dbp) / 3.0
    if value < 65:
        cat, text = "below target", "below the 65 mmHg target used for septic shock: organ hypoperfusion risk"
    else:
        cat, text = "at or above target", "at or above the 65 mmHg perfusion target"
    return make_result(
        "Mean arterial pressure",
        value,
        "mmHg",
        cat,
        f"MAP {value:.0f} mmHg: {text}.",
        {"pulse_pressure_mmhg": sbp - dbp},
        "MAP = DBP + (SBP - DBP)/3 (standard estimate); target: Evans L et al. Surviving Sepsis Campaign "
        "2021 guidelines, Crit Care Med 2021;49:e1063-e1143.",
    )
