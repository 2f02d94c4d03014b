"""Adapters from our calculators' arguments to ``clincalc`` 0.4.0 (AGPL-3.0, test-only).

clincalc is a Rust engine behind ``clincalc.calculate(name, inputs)`` that validates its inputs
against JSON schemas (``clincalc.get_schema(name)``). AGPL: this module is imported by the test
suite only, never by ``envs/`` or ``bench/``.
"""

from __future__ import annotations

import clincalc

from .peers_common import _DVT_KEYS, _NIHSS_OURS, _trop_points


def _cc(name: str, inputs: dict) -> float:
    return clincalc.calculate(name, inputs)["result"]


_CC_EYE = {4: "spontaneous", 3: "to_sound", 2: "to_pressure", 1: "no_response"}
_CC_VERBAL = {5: "orientated", 4: "confused", 3: "words", 2: "sounds", 1: "no_response"}
_CC_MOTOR = {
    6: "obey_commands",
    5: "localising",
    4: "normal_flexion",
    3: "abnormal_flexion",
    2: "extension",
    1: "no_response",
}


def gcs_clincalc(eye, verbal, motor):
    return _cc(
        "gcs",
        {
            "eye_opening": _CC_EYE[eye],
            "verbal_response": _CC_VERBAL[verbal],
            "motor_response": _CC_MOTOR[motor],
        },
    )


def qsofa_clincalc(respiratory_rate, systolic_bp, altered_mentation):
    return _cc(
        "qsofa",
        {
            "respiratory_rate": respiratory_rate,
            "systolic_bp": systolic_bp,
            "altered_mentation": altered_mentation,
        },
    )


def news2_clincalc(
    respiratory_rate,
    spo2,
    on_supplemental_oxygen,
    temperature_c,
    systolic_bp,
    heart_rate,
    consciousness,
    spo2_scale=1,
):
    return _cc(
        "news2",
        {
            "respiratory_rate": respiratory_rate,
            "spo2": spo2,
            "spo2_scale": str(spo2_scale),
            "on_oxygen": on_supplemental_oxygen,
            "systolic_bp": systolic_bp,
            "pulse": heart_rate,
            "consciousness": "alert" if consciousness == "alert" else "confusion-or-vpu",
            "temperature": temperature_c,
        },
    )


def _cc_cardio(map_mmhg, dopa, dobu, epi, norepi):
    if dopa > 15 or epi > 0.1 or norepi > 0.1:
        return "high-vasopressors"
    if dopa > 5 or epi > 0 or norepi > 0:
        return "moderate-vasopressors"
    if dopa > 0 or dobu > 0:
        return "dopamine-low"
    return "map-below70" if map_mmhg < 70 else "map-at-least70"


def sofa_clincalc(
    pao2_fio2_ratio,
    on_mechanical_ventilation,
    platelets_k_per_ul,
    bilirubin_mg_dl,
    map_mmhg,
    gcs,
    creatinine_mg_dl,
    dopamine_mcg_kg_min=0.0,
    dobutamine_mcg_kg_min=0.0,
    epinephrine_mcg_kg_min=0.0,
    norepinephrine_mcg_kg_min=0.0,
    urine_output_ml_day=None,
):
    # clincalc takes the cardiovascular level as a category: the mapping from doses is Vincent 1996's.
    return _cc(
        "sofa",
        {
            "pao2_fio2": pao2_fio2_ratio,
            "respiratory_support": on_mechanical_ventilation,
            "platelets": platelets_k_per_ul,
            "bilirubin": bilirubin_mg_dl,
            "bilirubin_unit": "mg/dL",
            "cardiovascular": _cc_cardio(
                map_mmhg,
                dopamine_mcg_kg_min,
                dobutamine_mcg_kg_min,
                epinephrine_mcg_kg_min,
                norepinephrine_mcg_kg_min,
            ),
            "gcs": gcs,
            "creatinine": creatinine_mg_dl,
            "creatinine_unit": "mg/dL",
        },
    )


def apache2_clincalc(**kw):
    chronic = "none"
    if kw.get("severe_organ_insufficiency_or_immunocompromised"):
        chronic = (
            "elective_postoperative"
            if kw.get("admission_type") == "elective_postoperative"
            else "nonoperative_or_emergency_postoperative"
        )
    inputs = {
        "temperature_c": kw["temperature_c"],
        "mean_arterial_pressure_mm_hg": kw["map_mmhg"],
        "heart_rate": kw["heart_rate"],
        "respiratory_rate": kw["respiratory_rate"],
        "fio2": kw["fio2"],
        "arterial_ph": kw["arterial_ph"],
        "sodium_mmol_l": kw["sodium_mmol_l"],
        "potassium_mmol_l": kw["potassium_mmol_l"],
        "creatinine_mg_dl": kw["creatinine_mg_dl"],
        "acute_renal_failure": kw.get("acute_renal_failure", False),
        "hematocrit_percent": kw["hematocrit_percent"],
        "wbc_10_9_l": kw["wbc_k_per_ul"],
        "glasgow_coma_scale": kw["gcs"],
        "age": kw["age"],
        "chronic_health_status": chronic,
    }
    if kw["fio2"] >= 0.5:
        inputs["aa_gradient_mm_hg"] = kw["aa_gradient_mmhg"]
    else:
        inputs["pao2_mm_hg"] = kw["pao2_mmhg"]
    return _cc("apache2", inputs)


def curb65_clincalc(confusion, bun_mg_dl, respiratory_rate, systolic_bp, diastolic_bp, age):
    # clincalc takes urea in mmol/L (the paper's unit): BUN mg/dL / 2.8.
    return _cc(
        "curb65",
        {
            "confusion": confusion,
            "urea_mmol_l": bun_mg_dl / 2.8,
            "respiratory_rate": respiratory_rate,
            "systolic_bp": systolic_bp,
            "diastolic_bp": diastolic_bp,
            "age": age,
        },
    )


def wells_pe_clincalc(
    clinical_signs_dvt,
    pe_most_likely,
    heart_rate,
    immobilization_or_recent_surgery,
    previous_dvt_pe,
    hemoptysis,
    malignancy,
    model="two_tier",
):
    return _cc(
        "wells_pe",
        {
            "clinical_signs_of_dvt": clinical_signs_dvt,
            "pe_most_likely_diagnosis": pe_most_likely,
            "heart_rate_over_100": heart_rate > 100,
            "immobilisation_or_surgery": immobilization_or_recent_surgery,
            "previous_dvt_or_pe": previous_dvt_pe,
            "haemoptysis": hemoptysis,
            "malignancy": malignancy,
        },
    )


def perc_clincalc(
    age,
    heart_rate,
    spo2,
    unilateral_leg_swelling,
    hemoptysis,
    recent_surgery_or_trauma,
    prior_pe_or_dvt,
    hormone_use,
):
    r = clincalc.calculate(
        "perc",
        {
            "age_years": age,
            "heart_rate_bpm": heart_rate,
            "room_air_oxygen_saturation_percent": spo2,
            "unilateral_leg_swelling": unilateral_leg_swelling,
            "haemoptysis": hemoptysis,
            "recent_surgery_or_trauma_requiring_hospitalisation": recent_surgery_or_trauma,
            "prior_vte": prior_pe_or_dvt,
            "exogenous_oestrogen_use": hormone_use,
            "low_pretest_probability_confirmed": True,
        },
    )
    return r["working"]["positive_count"]  # "result" is the rule's verdict; the count is in the working


def heart_clincalc(history, ecg, age, risk_factor_count, atherosclerotic_disease, troponin_x_uln):
    rf = (
        "three_or_more_or_atherosclerosis"
        if risk_factor_count >= 3 or atherosclerotic_disease
        else "one_or_two"
        if risk_factor_count
        else "none"
    )
    return _cc(
        "heart",
        {
            "history": f"{history}_suspicious",
            "ecg": {
                "normal": "normal",
                "nonspecific": "non_specific_repolarisation",
                "st_deviation": "significant_st_deviation",
            }[ecg],
            "age": age,
            "risk_factors": rf,
            "troponin": ("normal", "one_to_three_times", "over_three_times")[_trop_points(troponin_x_uln)],
        },
    )


def timi_clincalc(
    age,
    cad_risk_factor_count,
    known_cad_stenosis_50,
    aspirin_past_7_days,
    angina_episodes_24h,
    st_deviation_05mm,
    positive_cardiac_marker,
):
    return _cc(
        "timi",
        {
            "age": age,
            "three_or_more_cad_risk_factors": cad_risk_factor_count >= 3,
            "known_cad": known_cad_stenosis_50,
            "aspirin_use_past_7_days": aspirin_past_7_days,
            "severe_angina": angina_episodes_24h >= 2,
            "st_deviation": st_deviation_05mm,
            "positive_biomarker": positive_cardiac_marker,
        },
    )


def chads_clincalc(age, sex, chf, hypertension, diabetes, stroke_tia_thromboembolism, vascular_disease):
    return _cc(
        "cha2ds2vasc",
        {
            "age": age,
            "sex": sex,
            "congestive_heart_failure": chf,
            "hypertension": hypertension,
            "diabetes": diabetes,
            "stroke_tia_thromboembolism": stroke_tia_thromboembolism,
            "vascular_disease": vascular_disease,
        },
    )


def hasbled_clincalc(
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
    return _cc(
        "hasbled",
        {
            "hypertension_uncontrolled": uncontrolled_hypertension,
            "abnormal_renal_function": abnormal_renal_function,
            "abnormal_liver_function": abnormal_liver_function,
            "stroke": stroke_history,
            "bleeding_history": bleeding_history_or_predisposition,
            "labile_inr": labile_inr,
            "elderly_over_65": age > 65,
            "drugs_antiplatelet_nsaid": antiplatelet_or_nsaid_use,
            "alcohol_excess": alcohol_use,
        },
    )


def wells_dvt_clincalc(**kw):
    names = (
        "active_cancer",
        "paralysis_paresis_immobilisation",
        "bedridden_or_major_surgery",
        "localised_tenderness",
        "entire_leg_swollen",
        "calf_swelling_over_3cm",
        "pitting_oedema",
        "collateral_superficial_veins",
        "previously_documented_dvt",
        "alternative_diagnosis_as_likely",
    )
    return _cc("wells_dvt", {n: kw[k] for n, k in zip(names, _DVT_KEYS)})


def meld_clincalc(bilirubin_mg_dl, inr, creatinine_mg_dl, sodium_mmol_l, on_dialysis):
    """clincalc's ``meld`` is MELD without sodium: compare with our MELD(i) component."""
    return _cc(
        "meld",
        {
            "bilirubin": bilirubin_mg_dl,
            "bilirubin_unit": "mg/dL",
            "creatinine": creatinine_mg_dl,
            "creatinine_unit": "mg/dL",
            "inr": inr,
            "dialysis_twice_past_week": on_dialysis,
        },
    )


def child_pugh_clincalc(bilirubin_mg_dl, albumin_g_dl, inr, ascites, encephalopathy):
    return _cc(
        "child_pugh",
        {
            "bilirubin": bilirubin_mg_dl,
            "bilirubin_unit": "mg/dL",
            "albumin": albumin_g_dl,
            "albumin_unit": "g/dL",
            "inr": inr,
            "ascites": ascites.replace("_", "-"),
            "encephalopathy": {"none": "none", "grade_1_2": "grade1-to2", "grade_3_4": "grade3-to4"}[
                encephalopathy
            ],
        },
    )


def gbs_clincalc(
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
    return _cc(
        "glasgow_blatchford",
        {
            "age_16_or_over": True,
            "acute_upper_gi_bleeding_at_first_assessment": True,
            "emergency_department_overt_ugib": True,
            "sex": sex,
            "urea_mmol_l": bun_mg_dl / 2.8,
            "haemoglobin_g_l": hemoglobin_g_dl * 10.0,
            "systolic_bp_mm_hg": systolic_bp,
            "heart_rate_bpm": heart_rate,
            "melaena": melena,
            "syncope": syncope,
            "hepatic_disease": hepatic_disease,
            "cardiac_failure": cardiac_failure,
        },
    )


def cg_clincalc(age, weight_kg, creatinine_mg_dl, sex):
    return _cc(
        "cockcroft_gault",
        {
            "age": age,
            "weight_kg": weight_kg,
            "creatinine": creatinine_mg_dl,
            "creatinine_unit": "mg/dL",
            "sex": sex,
        },
    )


def ckd_epi_clincalc(creatinine_mg_dl, age, sex):
    return _cc("egfr", {"age": age, "creatinine": creatinine_mg_dl, "creatinine_unit": "mg/dL", "sex": sex})


def fena_clincalc(urine_sodium_mmol_l, serum_sodium_mmol_l, urine_creatinine_mg_dl, serum_creatinine_mg_dl):
    return float(
        _cc(
            "fena",
            {
                "urine_sodium": urine_sodium_mmol_l,
                "plasma_sodium": serum_sodium_mmol_l,
                "urine_creatinine": urine_creatinine_mg_dl,
                "plasma_creatinine": serum_creatinine_mg_dl,
            },
        )
    )  # a string, 2 decimals


def fwd_clincalc(sodium_mmol_l, weight_kg, age, sex, target_sodium_mmol_l=140.0, tbw_fraction=0.6):
    return _cc(
        "free_water_deficit",
        {
            "assessment_context": "adult_with_hypernatraemia",
            "weight_kg": weight_kg,
            "current_sodium_mmol_l": sodium_mmol_l,
            "target_sodium_mmol_l": target_sodium_mmol_l,
            "total_body_water_fraction": tbw_fraction,
        },
    )


def bmi_clincalc(weight_kg, height_cm):
    return _cc("bmi", {"weight_kg": weight_kg, "height_cm": height_cm})


def anion_gap_clincalc(sodium, chloride, bicarbonate, albumin_g_dl=None):
    return _cc(
        "anion_gap", {"sodium_mmol_l": sodium, "chloride_mmol_l": chloride, "bicarbonate_mmol_l": bicarbonate}
    )


def calcium_clincalc(calcium_mg_dl, albumin_g_dl):
    return _cc(
        "corrected_calcium",
        {"calcium": calcium_mg_dl, "calcium_unit": "mg/dL", "albumin": albumin_g_dl, "albumin_unit": "g/dL"},
    )


def sodium_clincalc(sodium_mmol_l, glucose_mg_dl, formula="katz"):
    return _cc(
        "corrected_sodium",
        {"sodium": sodium_mmol_l, "glucose": glucose_mg_dl, "glucose_unit": "mg/dL", "method": formula},
    )


def apgar_clincalc(heart_rate, respiratory_effort, muscle_tone, reflex_irritability, color):
    return _cc(
        "apgar",
        {
            "minute_after_birth": 5,
            "assessment_during_resuscitation": False,
            "gestational_context": "term_or_late_preterm",
            "heart_rate": "absent"
            if heart_rate == 0
            else "below_100"
            if heart_rate < 100
            else "at_least_100",
            "respiratory_effort": {
                "absent": "absent",
                "weak": "slow_or_irregular",
                "strong": "good_with_vigorous_cry",
            }[respiratory_effort],
            "muscle_tone": {"limp": "flaccid", "some_flexion": "some_flexion", "active": "active_motion"}[
                muscle_tone
            ],
            "reflex_irritability": {
                "none": "no_response",
                "grimace": "grimace",
                "cry": "cough_sneeze_or_active_withdrawal",
            }[reflex_irritability],
            "appearance": {
                "blue_pale": "blue_or_pale",
                "acrocyanosis": "pink_body_blue_extremities",
                "pink": "completely_pink",
            }[color],
        },
    )


def phq9_clincalc(responses):
    return _cc("phq9", {"responses": list(responses)})


def gad7_clincalc(responses):
    return _cc("gad7", {"responses": list(responses)})


def epds_clincalc(responses):
    return _cc("epds", {"responses": list(responses)})


def audit_c_clincalc(responses, sex):
    return _cc("auditc", {"responses": list(responses), "sex": sex})


def ciwa_clincalc(**kw):
    return _cc(
        "ciwa_ar",
        {
            "assessment_context": (
                "clinically_identified_alcohol_withdrawal_with_reliable_patient_participation"
            ),
            "nausea_and_vomiting": kw["nausea_vomiting"],
            "tremor": kw["tremor"],
            "paroxysmal_sweats": kw["paroxysmal_sweats"],
            "anxiety": kw["anxiety"],
            "agitation": kw["agitation"],
            "tactile_disturbances": kw["tactile_disturbances"],
            "auditory_disturbances": kw["auditory_disturbances"],
            "visual_disturbances": kw["visual_disturbances"],
            "headache_or_fullness": kw["headache"],
            "orientation_and_clouding": kw["orientation"],
        },
    )


def centor_clincalc(
    age, tonsillar_exudate_or_swelling, tender_anterior_cervical_nodes, temperature_c, cough_absent
):
    return _cc(
        "centor",
        {
            "age": age,
            "tonsillar_exudate": tonsillar_exudate_or_swelling,
            "tender_anterior_cervical_nodes": tender_anterior_cervical_nodes,
            "fever": temperature_c > 38,
            "absence_of_cough": cough_absent,
        },
    )


def alvarado_clincalc(
    migration_to_rlq,
    anorexia,
    nausea_vomiting,
    rlq_tenderness,
    rebound_tenderness,
    temperature_c,
    wbc_k_per_ul,
    neutrophil_percent,
):
    return _cc(
        "alvarado",
        {
            "migration_to_rlq": migration_to_rlq,
            "anorexia": anorexia,
            "nausea_or_vomiting": nausea_vomiting,
            "rlq_tenderness": rlq_tenderness,
            "rebound_tenderness": rebound_tenderness,
            "fever": temperature_c >= 37.3,
            "leukocytosis": wbc_k_per_ul > 10,
            "left_shift": neutrophil_percent > 75,
        },
    )


_NIHSS_CC = (
    "level_of_consciousness",
    "loc_questions",
    "loc_commands",
    "best_gaze",
    "visual_fields",
    "facial_palsy",
    "motor_arm_left",
    "motor_arm_right",
    "motor_leg_left",
    "motor_leg_right",
    "limb_ataxia",
    "sensory",
    "best_language",
    "dysarthria",
    "extinction_inattention",
)
_NIHSS_CC_SCHEMA = clincalc.get_schema("nihss")["properties"]


def nihss_clincalc(**kw):
    inputs = {
        "assessment_context": "clinician_administered_standard_adult_nihss_using_authorized_scale_materials"
    }
    for cc_name, ours in zip(_NIHSS_CC, _NIHSS_OURS):
        enum = _NIHSS_CC_SCHEMA[cc_name]["enum"]
        if cc_name == "loc_questions":  # its enum lists two options worth 1 point
            enum = ["both_correct", "one_correct", "neither_correct_or_aphasic_or_stuporous"]
        inputs[cc_name] = enum[kw[ours]]  # enums are listed in point order (0, 1, 2, ...)
    return _cc("nihss", inputs)


def abcd2_clincalc(age, systolic_bp, diastolic_bp, clinical_features, duration_minutes, diabetes):
    return _cc(
        "abcd2",
        {
            "age": age,
            "systolic_bp": systolic_bp,
            "diastolic_bp": diastolic_bp,
            "clinical_features": clinical_features.replace("_", "-"),
            "duration": "60min-or-more"
            if duration_minutes >= 60
            else "10-59min"
            if duration_minutes >= 10
            else "under-10min",
            "diabetes": diabetes,
        },
    )
