"""Adapters from our calculators' arguments to medcalc-bench 1.7.0 (module ``medcalc``, Apache-2.0).

medcalc functions take ``{name: (value, unit)}`` dicts and return ``{"Explanation": ..., "Answer": ...}``
(they build the explanation text on every call). Where medcalc departs from the published
definition, ``test_calc_peers_*.py`` restricts the inputs and says why.
"""

from __future__ import annotations

from medcalc import (
    anion_gap as mc_anion_gap,
    calcium_correction as mc_calcium,
    centor_score as mc_centor,
    cha2ds2_vasc_score as mc_chads,
    child_pugh_score as mc_child,
    ckd_epi_2021_creatinine as mc_ckd,
    compute_fena as mc_fena,
    creatinine_clearance as mc_cg,
    curb_65 as mc_curb,
    free_water_deficit as mc_fwd,
    glasgow_bleeding_score as mc_gbs,
    glasgow_coma_score as mc_gcs,
    has_bled_score as mc_hasbled,
    heart_score as mc_heart,
    mean_arterial_pressure as mc_map,
    meldna as mc_meldna,
    perc_rule as mc_perc,
    qt_calculator_bazett as mc_qt_b,
    qt_calculator_framingham as mc_qt_fr,
    qt_calculator_fredericia as mc_qt_f,
    qt_calculator_hodges as mc_qt_h,
    sch as mc_sch,
    sirs_criteria as mc_sirs,
    sOsm as mc_sosm,
    wells_criteria_dvt as mc_wdvt,
    wells_criteria_pe as mc_wpe,
    bmi_calculator as mc_bmi,
)

from .peers_common import _DVT_KEYS, _mc, _trop_points

_MC_EYE = {
    4: "eyes open spontaneously",
    3: "eye opening to verbal command",
    2: "eye opening to pain",
    1: "no eye opening",
}


_MC_VERBAL = {
    5: "oriented",
    4: "confused",
    3: "inappropriate words",
    2: "incomprehensible sounds",
    1: "no verbal response",
}


_MC_MOTOR = {
    6: "obeys commands",
    5: "localizes pain",
    4: "withdrawal from pain",
    3: "flexion to pain",
    2: "extension to pain",
    1: "no motor response",
}


def gcs_medcalc(eye, verbal, motor):
    return _mc(
        mc_gcs.compute_glasgow_coma_score_explanation,
        {
            "best_eye_response": _MC_EYE[eye],
            "best_verbal_response": _MC_VERBAL[verbal],
            "best_motor_response": _MC_MOTOR[motor],
        },
    )


def sirs_medcalc(
    temperature_c, heart_rate, respiratory_rate, wbc_k_per_ul, paco2_mmhg=None, bands_percent=None
):
    inputs = {
        "temperature": (temperature_c, "degrees celsius"),
        "heart_rate": (heart_rate, "beats per minute"),
        "respiratory_rate": (respiratory_rate, "breaths per minute"),
        "wbc": (wbc_k_per_ul * 1000.0, "m^3"),
    }
    if paco2_mmhg is not None:
        inputs["paco2"] = (paco2_mmhg, "mm Hg")
    return _mc(mc_sirs.sirs_criteria_explanation, inputs)


def curb65_medcalc(confusion, bun_mg_dl, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _mc(
        mc_curb.curb_65_explanation,
        {
            "age": (age, "years"),
            "sys_bp": (systolic_bp, "mm hg"),
            "dia_bp": (diastolic_bp, "mm hg"),
            "respiratory_rate": (respiratory_rate, "breaths per minute"),
            "bun": (bun_mg_dl, "mg/dL"),
            "confusion": confusion,
        },
    )


def wells_pe_medcalc(
    clinical_signs_dvt,
    pe_most_likely,
    heart_rate,
    immobilization_or_recent_surgery,
    previous_dvt_pe,
    hemoptysis,
    malignancy,
    model="two_tier",
):
    return _mc(
        mc_wpe.calculate_pe_wells_explanation,
        {
            "clinical_dvt": clinical_signs_dvt,
            "pe_number_one": pe_most_likely,
            "heart_rate": (heart_rate, "beats per minute"),
            "immobilization_for_3days": immobilization_or_recent_surgery,
            "surgery_in_past4weeks": False,
            "previous_pe": previous_dvt_pe,
            "previous_dvt": False,
            "hemoptysis": hemoptysis,
            "malignancy_with_treatment": malignancy,
        },
    )


def perc_medcalc(
    age,
    heart_rate,
    spo2,
    unilateral_leg_swelling,
    hemoptysis,
    recent_surgery_or_trauma,
    prior_pe_or_dvt,
    hormone_use,
):
    return _mc(
        mc_perc.compute_perc_rule_explanation,
        {
            "age": (age, "years"),
            "heart_rate": (heart_rate, "beats per minute"),
            "oxygen_sat": (spo2, "%"),
            "unilateral_leg_swelling": unilateral_leg_swelling,
            "hemoptysis": hemoptysis,
            "recent_surgery_or_trauma": recent_surgery_or_trauma,
            "previous_pe": prior_pe_or_dvt,
            "previous_dvt": False,
            "hormonal_use": hormone_use,
        },
    )


_HEART_RF = (
    "hypertension",
    "hypercholesterolemia",
    "diabetes_mellitus",
    "obesity",
    "smoking",
    "family_with_cvd",
)


_MC_HISTORY = {
    "slightly": "Slightly suspicious",
    "moderately": "Moderately suspicious",
    "highly": "Highly suspicious",
}


_MC_ECG = {
    "normal": "Normal",
    "nonspecific": "Non-specific repolarization disturbance",
    "st_deviation": "Significant ST deviation",
}


def heart_medcalc(history, ecg, age, risk_factor_count, atherosclerotic_disease, troponin_x_uln):
    trop = (
        "less than or equal to normal limit",
        "between the normal limit or up to three times the normal limit",
        "greater than three times normal limit",
    )[_trop_points(troponin_x_uln)]
    inputs = {
        "age": (age, "years"),
        "history": _MC_HISTORY[history],
        "electrocardiogram": _MC_ECG[ecg],
        "atherosclerotic_disease": atherosclerotic_disease,
        "initial_troponin": trop,
    }
    for k, name in enumerate(_HEART_RF):
        inputs[name] = k < risk_factor_count
    return _mc(mc_heart.compute_heart_score_explanation, inputs)


def chads_medcalc(age, sex, chf, hypertension, diabetes, stroke_tia_thromboembolism, vascular_disease):
    return _mc(
        mc_chads.generate_cha2ds2_vasc_explanation,
        {
            "age": (age, "years"),
            "sex": sex.capitalize(),
            "chf": chf,
            "hypertension": hypertension,
            "diabetes": diabetes,
            "stroke": stroke_tia_thromboembolism,
            "tia": False,
            "thromboembolism": False,
            "vascular_disease": vascular_disease,
        },
    )


def hasbled_medcalc(
    age,
    uncontrolled_hypertension,
    abnormal_renal_function,
    abnormal_liver_function,
    stroke_history,
    bleeding_history_or_predisposition,
    labile_inr,
    antiplatelet_or_nsaid_use,
    alcohol_use,
):
    return _mc(
        mc_hasbled.compute_has_bled_score_explanation,
        {
            "age": (age, "years"),
            "hypertension": uncontrolled_hypertension,
            "renal_disease_has_bled": abnormal_renal_function,
            "liver_disease_has_bled": abnormal_liver_function,
            "stroke": stroke_history,
            "prior_bleeding": bleeding_history_or_predisposition,
            "labile_inr": labile_inr,
            "medications_for_bleeding": antiplatelet_or_nsaid_use,
            "alcoholic_drinks": 8 if alcohol_use else 0,
        },
    )


def wells_dvt_medcalc(**kw):
    names = (
        "active_cancer",
        "paralysis_paresis_immobilization_in_lower_extreme",
        "bedridden_for_atleast_3_days",
        "localized_tenderness_on_deep_venuous_system",
        "leg_swollen",
        "calf_swelling_3cm",
        "pitting_edema_on_symptomatic_leg",
        "collateral_superficial_veins",
        "previous_dvt",
        "alternative_to_dvt_diagnosis",
    )
    inputs = {n: kw[k] for n, k in zip(names, _DVT_KEYS)}
    inputs["major_surgery_in_last_12_weeks"] = False
    return _mc(mc_wdvt.compute_wells_criteria_dvt_explanation, inputs)


_MC_QT = {
    "bazett": (mc_qt_b, "bazett_calculator_explanation"),
    "fridericia": (mc_qt_f, "fredericia_calculator_explanation"),
    "framingham": (mc_qt_fr, "framingham_calculator_explanation"),
    "hodges": (mc_qt_h, "hodges_calculator_explanation"),
}


def qtc_medcalc(qt_ms, heart_rate, formula="bazett", sex=None):
    module, name = _MC_QT[formula]
    return _mc(
        getattr(module, name),
        {"heart_rate": (heart_rate, "beats per minute"), "qt_interval": (qt_ms, "msec")},
    )


def map_medcalc(systolic_bp, diastolic_bp):
    return _mc(
        mc_map.mean_arterial_pressure_explanation,
        {"sys_bp": (systolic_bp, "mm hg"), "dia_bp": (diastolic_bp, "mm hg")},
    )


def meld_na_medcalc(bilirubin_mg_dl, inr, creatinine_mg_dl, sodium_mmol_l, on_dialysis):
    return _mc(
        mc_meldna.compute_meldna_explanation,
        {
            "creatinine": (creatinine_mg_dl, "mg/dL"),
            "dialysis_twice": on_dialysis,
            "bilirubin": (bilirubin_mg_dl, "mg/dL"),
            "inr": inr,
            "sodium": (sodium_mmol_l, "mEq/L"),
        },
    )


_MC_ASCITES = {"none": "Absent", "mild": "Slight", "moderate_severe": "Moderate"}


_MC_ENCEPH = {"none": "No Encephalopathy", "grade_1_2": "Grade 1-2", "grade_3_4": "Grade 3-4"}


def child_pugh_medcalc(bilirubin_mg_dl, albumin_g_dl, inr, ascites, encephalopathy):
    return _mc(
        mc_child.compute_child_pugh_score_explanation,
        {
            "bilirubin": (bilirubin_mg_dl, "mg/dL"),
            "albumin": (albumin_g_dl, "g/dL"),
            "inr": inr,
            "ascites": _MC_ASCITES[ascites],
            "encephalopathy": _MC_ENCEPH[encephalopathy],
        },
    )


def gbs_medcalc(
    bun_mg_dl,
    hemoglobin_g_dl,
    sex,
    systolic_bp,
    heart_rate,
    melena,
    syncope,
    hepatic_disease,
    cardiac_failure,
):
    return _mc(
        mc_gbs.glasgow_bleeding_score_explanation,
        {
            "hemoglobin": (hemoglobin_g_dl, "g/dL"),
            "bun": (bun_mg_dl, "mg/dL"),
            "sys_bp": (systolic_bp, "mm hg"),
            "sex": sex.capitalize(),
            "heart_rate": (heart_rate, "beats per minute"),
            "melena_present": melena,
            "syncope": syncope,
            "hepatic_disease_history": hepatic_disease,
            "cardiac_failure": cardiac_failure,
        },
    )


def cg_medcalc(age, weight_kg, creatinine_mg_dl, sex, height_cm):
    return _mc(
        mc_cg.generate_cockcroft_gault_explanation,
        {
            "sex": sex.capitalize(),
            "weight": (weight_kg, "kg"),
            "height": (height_cm, "cm"),
            "creatinine": (creatinine_mg_dl, "mg/dL"),
            "age": (age, "years"),
        },
    )


def ckd_epi_medcalc(creatinine_mg_dl, age, sex):
    return _mc(
        mc_ckd.ckd_epi_2021_explanation,
        {"sex": sex.capitalize(), "age": (age, "years"), "creatinine": (creatinine_mg_dl, "mg/dL")},
    )


def fena_medcalc(urine_sodium_mmol_l, serum_sodium_mmol_l, urine_creatinine_mg_dl, serum_creatinine_mg_dl):
    return _mc(
        mc_fena.compute_fena_explanation,
        {
            "sodium": (serum_sodium_mmol_l, "mmol/L"),
            "creatinine": (serum_creatinine_mg_dl, "mg/dL"),
            "urine_sodium": (urine_sodium_mmol_l, "mmol/L"),
            "urine_creatinine": (urine_creatinine_mg_dl, "mg/dL"),
        },
    )


def fwd_medcalc(sodium_mmol_l, weight_kg, age, sex, target_sodium_mmol_l=140.0):
    return _mc(
        mc_fwd.free_water_deficit_explanation,
        {
            "sex": sex.capitalize(),
            "age": (age, "years"),
            "weight": (weight_kg, "kg"),
            "sodium": (sodium_mmol_l, "mmol/L"),
        },
    )


def bmi_medcalc(weight_kg, height_cm):
    return _mc(mc_bmi.bmi_calculator_explanation, {"weight": (weight_kg, "kg"), "height": (height_cm, "cm")})


def anion_gap_medcalc(sodium, chloride, bicarbonate, albumin_g_dl=None):
    return _mc(
        mc_anion_gap.compute_anion_gap_explanation,
        {
            "sodium": (sodium, "mmol/L"),
            "chloride": (chloride, "mmol/L"),
            "bicarbonate": (bicarbonate, "mmol/L"),
        },
    )


def calcium_medcalc(calcium_mg_dl, albumin_g_dl):
    return _mc(
        mc_calcium.calculate_corrected_calcium_explanation,
        {"calcium": (calcium_mg_dl, "mg/dL"), "albumin": (albumin_g_dl, "g/dL")},
    )


def sodium_medcalc(sodium_mmol_l, glucose_mg_dl, formula="hillier"):
    return _mc(
        mc_sch.compute_sodium_correction_hyperglycemia_explanation,
        {"glucose": (glucose_mg_dl, "mg/dL"), "sodium": (sodium_mmol_l, "mEq/L")},
    )


def osm_medcalc(sodium_mmol_l, glucose_mg_dl, bun_mg_dl):
    return _mc(
        mc_sosm.compute_serum_osmolality_explanation,
        {
            "bun": (bun_mg_dl, "mg/dL"),
            "glucose": (glucose_mg_dl, "mg/dL"),
            "sodium": (sodium_mmol_l, "mEq/L"),
        },
    )


def centor_medcalc(
    age, tonsillar_exudate_or_swelling, tender_anterior_cervical_nodes, temperature_c, cough_absent
):
    return _mc(
        mc_centor.compute_centor_score_explanation,
        {
            "age": (age, "years"),
            "temperature": (temperature_c, "degrees celsius"),
            "exudate_swelling_tonsils": tonsillar_exudate_or_swelling,
            "tender_lymph_nodes": tender_anterior_cervical_nodes,
            "cough_absent": cough_absent,
        },
    )
