"""Adapters from our calculators' arguments to open-medicine 0.12.0 (MIT).

open-medicine calculators take pydantic ``*Params`` models and return a ``ClinicalResult`` whose
``.value`` is the score. Where it departs from the published definition, ``test_calc_peers_*.py``
restricts the inputs and says why.
"""

from __future__ import annotations

from open_medicine.mcp.calculators import (
    aa_gradient as om_aa,
    abcd2 as om_abcd2,
    anion_gap as om_ag,
    apache2 as om_apache,
    apgar as om_apgar,
    audit_c as om_auditc,
    bishop as om_bishop,
    bmi as om_bmi,
    cage as om_cage,
    centor_mcisaac as om_centor,
    chadsvasc as om_chads,
    child_pugh as om_child,
    ciwa_ar as om_ciwa,
    ckd_epi as om_ckd,
    cockcroft_gault as om_cg,
    corrected_calcium as om_ca,
    corrected_qtc as om_qtc,
    corrected_sodium as om_na,
    crb65 as om_crb,
    curb65 as om_curb,
    epds as om_epds,
    gad7 as om_gad7,
    gcs as om_gcs,
    glasgow_blatchford as om_gbs,
    hasbled as om_hasbled,
    heart_score as om_heart,
    meld_na as om_meld,
    news2 as om_news2,
    nihss as om_nihss,
    ottawa_ankle as om_ottawa,
    parkland as om_parkland,
    perc as om_perc,
    phq9 as om_phq9,
    qsofa as om_qsofa,
    rts as om_rts,
    serum_osmolality as om_osm,
    sofa as om_sofa,
    timi_ua_nstemi as om_timi,
    wells_dvt as om_wdvt,
    wells_pe as om_wpe,
)

from .peers_common import _DVT_KEYS, _NIHSS_OURS, _om, _trop_points


def gcs_open_medicine(eye, verbal, motor):
    return _om(
        om_gcs, "calculate_gcs", "GCSParams", eye_response=eye, verbal_response=verbal, motor_response=motor
    )


def qsofa_open_medicine(respiratory_rate, systolic_bp, altered_mentation):
    return _om(
        om_qsofa,
        "calculate_qsofa",
        "QSOFAParams",
        respiratory_rate=respiratory_rate,
        systolic_blood_pressure=systolic_bp,
        altered_mentation=altered_mentation,
    )


_OM_AVPU = {
    "alert": "alert",
    "new_confusion": "confusion",
    "voice": "voice",
    "pain": "pain",
    "unresponsive": "unresponsive",
}


def news2_open_medicine(
    respiratory_rate,
    spo2,
    on_supplemental_oxygen,
    temperature_c,
    systolic_bp,
    heart_rate,
    consciousness,
    spo2_scale=1,
):
    return _om(
        om_news2,
        "calculate_news2",
        "NEWS2Params",
        respiration_rate=respiratory_rate,
        spo2=spo2,
        spo2_scale=f"scale_{spo2_scale}",
        on_supplemental_o2=on_supplemental_oxygen,
        systolic_bp=systolic_bp,
        pulse=heart_rate,
        consciousness=_OM_AVPU[consciousness],
        temperature=temperature_c,
    )


def sofa_open_medicine(
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
    return _om(
        om_sofa,
        "calculate_sofa",
        "SOFAParams",
        pao2_fio2=pao2_fio2_ratio,
        platelets=platelets_k_per_ul,
        bilirubin=bilirubin_mg_dl,
        map_pressure=map_mmhg,
        dopamine=dopamine_mcg_kg_min,
        epinephrine=epinephrine_mcg_kg_min,
        norepinephrine=norepinephrine_mcg_kg_min,
        gcs=gcs,
        creatinine=creatinine_mg_dl,
        urine_output=urine_output_ml_day,
        **(
            {"mechanical_ventilation": on_mechanical_ventilation}
            if "mechanical_ventilation" in om_sofa.SOFAParams.model_fields
            else {}
        ),
    )


_OM_ADMISSION = {
    "nonoperative": "nonoperative",
    "emergency_postoperative": "emergency_surgery",
    "elective_postoperative": "elective_surgery",
}


def apache2_open_medicine(**kw):
    return _om(
        om_apache,
        "calculate_apache2",
        "APACHE2Params",
        temperature=kw["temperature_c"],
        mean_arterial_pressure=kw["map_mmhg"],
        heart_rate=kw["heart_rate"],
        respiratory_rate=kw["respiratory_rate"],
        fio2=kw["fio2"],
        pao2=kw["pao2_mmhg"],
        paco2=kw.get("paco2_mmhg"),
        arterial_ph=kw["arterial_ph"],
        serum_sodium=kw["sodium_mmol_l"],
        serum_potassium=kw["potassium_mmol_l"],
        serum_creatinine=kw["creatinine_mg_dl"],
        acute_renal_failure=kw.get("acute_renal_failure", False),
        hematocrit=kw["hematocrit_percent"],
        white_blood_cell_count=kw["wbc_k_per_ul"],
        gcs=kw["gcs"],
        age=kw["age"],
        admission_type=_OM_ADMISSION[kw.get("admission_type", "nonoperative")],
        severe_organ_insufficiency_or_immunocompromised=kw.get(
            "severe_organ_insufficiency_or_immunocompromised", False
        ),
    )


def aa_gradient_open_medicine(
    pao2_mmhg, paco2_mmhg, fio2, age=None, atmospheric_pressure_mmhg=760.0, respiratory_quotient=0.8
):
    return _om(
        om_aa,
        "calculate_aa_gradient",
        "AaGradientParams",
        fio2=fio2,
        pao2=pao2_mmhg,
        paco2=paco2_mmhg,
        atmospheric_pressure=atmospheric_pressure_mmhg,
        age=age,
    )


def curb65_open_medicine(confusion, bun_mg_dl, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _om(
        om_curb,
        "calculate_curb65",
        "CURB65Params",
        confusion=confusion,
        bun=bun_mg_dl,
        respiratory_rate=respiratory_rate,
        systolic_bp=systolic_bp,
        diastolic_bp=diastolic_bp,
        age=age,
    )


def crb65_open_medicine(confusion, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _om(
        om_crb,
        "calculate_crb65",
        "CRB65Params",
        confusion=confusion,
        respiratory_rate=respiratory_rate,
        systolic_bp=systolic_bp,
        diastolic_bp=diastolic_bp,
        age=age,
    )


def wells_pe_open_medicine(
    clinical_signs_dvt,
    pe_most_likely,
    heart_rate,
    immobilization_or_recent_surgery,
    previous_dvt_pe,
    hemoptysis,
    malignancy,
    model="two_tier",
):
    return _om(
        om_wpe,
        "calculate_wells_pe",
        "WellsPEParams",
        clinical_signs_dvt=clinical_signs_dvt,
        pe_most_likely_diagnosis=pe_most_likely,
        heart_rate_gt_100=heart_rate > 100,
        immobilization_or_surgery=immobilization_or_recent_surgery,
        previous_dvt_pe=previous_dvt_pe,
        hemoptysis=hemoptysis,
        malignancy=malignancy,
    )


def perc_open_medicine(
    age,
    heart_rate,
    spo2,
    unilateral_leg_swelling,
    hemoptysis,
    recent_surgery_or_trauma,
    prior_pe_or_dvt,
    hormone_use,
):
    return _om(
        om_perc,
        "calculate_perc",
        "PERCParams",
        age_gte_50=age >= 50,
        heart_rate_gte_100=heart_rate >= 100,
        spo2_lt_95=spo2 < 95,
        unilateral_leg_swelling=unilateral_leg_swelling,
        hemoptysis=hemoptysis,
        recent_surgery_or_trauma=recent_surgery_or_trauma,
        prior_dvt_pe=prior_pe_or_dvt,
        estrogen_use=hormone_use,
    )


def heart_open_medicine(history, ecg, age, risk_factor_count, atherosclerotic_disease, troponin_x_uln):
    return _om(
        om_heart,
        "calculate_heart_score",
        "HEARTScoreParams",
        history={"slightly": 0, "moderately": 1, "highly": 2}[history],
        ecg={"normal": 0, "nonspecific": 1, "st_deviation": 2}[ecg],
        age=age,
        risk_factor_count=risk_factor_count,
        history_of_atherosclerosis=atherosclerotic_disease,
        troponin=_trop_points(troponin_x_uln),
    )


def timi_open_medicine(
    age,
    cad_risk_factor_count,
    known_cad_stenosis_50,
    aspirin_past_7_days,
    angina_episodes_24h,
    st_deviation_05mm,
    positive_cardiac_marker,
):
    return _om(
        om_timi,
        "calculate_timi_ua_nstemi",
        "TIMIUANSTEMIParams",
        age_gte_65=age >= 65,
        three_or_more_cad_risk_factors=cad_risk_factor_count >= 3,
        known_cad_gte_50_stenosis=known_cad_stenosis_50,
        aspirin_use_past_7_days=aspirin_past_7_days,
        two_or_more_anginal_events_24h=angina_episodes_24h >= 2,
        st_deviation_gte_0_5mm=st_deviation_05mm,
        elevated_cardiac_markers=positive_cardiac_marker,
    )


def chads_open_medicine(age, sex, chf, hypertension, diabetes, stroke_tia_thromboembolism, vascular_disease):
    return _om(
        om_chads,
        "calculate_chadsvasc",
        "CHADSVAScParams",
        congestive_heart_failure=chf,
        hypertension=hypertension,
        age=age,
        diabetes=diabetes,
        stroke_tia_thromboembolism=stroke_tia_thromboembolism,
        vascular_disease=vascular_disease,
        female_sex=sex == "female",
    )


def hasbled_open_medicine(
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
    return _om(
        om_hasbled,
        "calculate_hasbled",
        "HASBLEDParams",
        hypertension=uncontrolled_hypertension,
        abnormal_renal_function=abnormal_renal_function,
        abnormal_liver_function=abnormal_liver_function,
        stroke=stroke_history,
        bleeding=bleeding_history_or_predisposition,
        labile_inr=labile_inr,
        elderly=age > 65,
        drugs=antiplatelet_or_nsaid_use,
        alcohol=alcohol_use,
    )


def wells_dvt_open_medicine(**kw):
    names = (
        "active_cancer",
        "paralysis_or_casting",
        "bedridden_or_major_surgery",
        "tenderness_along_deep_veins",
        "entire_leg_swollen",
        "calf_swelling_gt_3cm",
        "pitting_edema",
        "collateral_superficial_veins",
        "previously_documented_dvt",
        "alternative_diagnosis_likely",
    )
    return _om(
        om_wdvt, "calculate_wells_dvt", "WellsDVTParams", **{n: kw[k] for n, k in zip(names, _DVT_KEYS)}
    )


def qtc_open_medicine(qt_ms, heart_rate, formula="bazett", sex=None):
    return _om(
        om_qtc,
        "calculate_corrected_qtc",
        "CorrectedQTcParams",
        qt_ms=qt_ms,
        heart_rate=heart_rate,
        method=formula,
    )


def meld_na_open_medicine(bilirubin_mg_dl, inr, creatinine_mg_dl, sodium_mmol_l, on_dialysis):
    return _om(
        om_meld,
        "calculate_meld_na",
        "MELDNaParams",
        creatinine=creatinine_mg_dl,
        bilirubin=bilirubin_mg_dl,
        inr=inr,
        sodium=sodium_mmol_l,
        on_dialysis=on_dialysis,
    )


def child_pugh_open_medicine(bilirubin_mg_dl, albumin_g_dl, inr, ascites, encephalopathy):
    return _om(
        om_child,
        "calculate_child_pugh",
        "ChildPughParams",
        bilirubin=bilirubin_mg_dl,
        albumin=albumin_g_dl,
        inr=inr,
        ascites={"none": "none", "mild": "mild", "moderate_severe": "severe"}[ascites],
        encephalopathy=encephalopathy,
    )


def gbs_open_medicine(
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
    return _om(
        om_gbs,
        "calculate_glasgow_blatchford",
        "GlasgowBlatchfordParams",
        bun=bun_mg_dl,
        hemoglobin=hemoglobin_g_dl,
        systolic_bp=systolic_bp,
        pulse=heart_rate,
        is_male=sex == "male",
        melena=melena,
        syncope=syncope,
        hepatic_disease=hepatic_disease,
        cardiac_failure=cardiac_failure,
    )


def cg_open_medicine(age, weight_kg, creatinine_mg_dl, sex):
    return _om(
        om_cg,
        "calculate_cockcroft_gault",
        "CockcroftGaultParams",
        age=age,
        weight=weight_kg,
        is_female=sex == "female",
        serum_creatinine=creatinine_mg_dl,
    )


def ckd_epi_open_medicine(creatinine_mg_dl, age, sex):
    return _om(
        om_ckd,
        "calculate_ckd_epi",
        "CKDEPIParams",
        age=age,
        is_female=sex == "female",
        serum_creatinine=creatinine_mg_dl,
    )


def bmi_open_medicine(weight_kg, height_cm):
    return _om(om_bmi, "calculate_bmi", "BMIParams", weight_kg=weight_kg, height_cm=height_cm)


def anion_gap_open_medicine(sodium, chloride, bicarbonate, albumin_g_dl=None):
    return _om(
        om_ag,
        "calculate_anion_gap",
        "AnionGapParams",
        sodium=sodium,
        chloride=chloride,
        bicarbonate=bicarbonate,
    )


def calcium_open_medicine(calcium_mg_dl, albumin_g_dl):
    return _om(
        om_ca,
        "calculate_corrected_calcium",
        "CorrectedCalciumParams",
        calcium=calcium_mg_dl,
        albumin=albumin_g_dl,
    )


def sodium_open_medicine(sodium_mmol_l, glucose_mg_dl, formula="katz"):
    return _om(
        om_na,
        "calculate_corrected_sodium",
        "CorrectedSodiumParams",
        sodium=sodium_mmol_l,
        glucose=glucose_mg_dl,
    )


def osm_open_medicine(sodium_mmol_l, glucose_mg_dl, bun_mg_dl):
    return _om(
        om_osm,
        "calculate_serum_osmolality",
        "SerumOsmolalityParams",
        sodium=sodium_mmol_l,
        glucose=glucose_mg_dl,
        bun=bun_mg_dl,
    )


def bishop_open_medicine(dilation_cm, effacement_percent, station, consistency, position):
    return _om(
        om_bishop,
        "calculate_bishop",
        "BishopParams",
        dilation_cm=dilation_cm,
        effacement_pct=effacement_percent,
        station=station,
        consistency={"firm": 0, "medium": 1, "soft": 2}[consistency],
        position={"posterior": 0, "mid": 1, "anterior": 2}[position],
    )


_APGAR = {
    "respiratory_effort": {"absent": 0, "weak": 1, "strong": 2},
    "muscle_tone": {"limp": 0, "some_flexion": 1, "active": 2},
    "reflex_irritability": {"none": 0, "grimace": 1, "cry": 2},
    "color": {"blue_pale": 0, "acrocyanosis": 1, "pink": 2},
}


def apgar_open_medicine(heart_rate, respiratory_effort, muscle_tone, reflex_irritability, color):
    return _om(
        om_apgar,
        "calculate_apgar",
        "ApgarParams",
        appearance=_APGAR["color"][color],
        pulse=0 if heart_rate == 0 else 1 if heart_rate < 100 else 2,
        grimace=_APGAR["reflex_irritability"][reflex_irritability],
        activity=_APGAR["muscle_tone"][muscle_tone],
        respiration=_APGAR["respiratory_effort"][respiratory_effort],
    )


_PHQ9_FIELDS = tuple(om_phq9.PHQ9Params.model_fields)


_GAD7_FIELDS = tuple(om_gad7.GAD7Params.model_fields)


_EPDS_FIELDS = tuple(om_epds.EPDSParams.model_fields)


def phq9_open_medicine(responses):
    return _om(om_phq9, "calculate_phq9", "PHQ9Params", **dict(zip(_PHQ9_FIELDS, responses)))


def gad7_open_medicine(responses):
    return _om(om_gad7, "calculate_gad7", "GAD7Params", **dict(zip(_GAD7_FIELDS, responses)))


def epds_open_medicine(responses):
    return _om(om_epds, "calculate_epds", "EPDSParams", **dict(zip(_EPDS_FIELDS, responses)))


def audit_c_open_medicine(responses, sex):
    return _om(
        om_auditc,
        "calculate_audit_c",
        "AUDITCParams",
        frequency=responses[0],
        typical_quantity=responses[1],
        binge_frequency=responses[2],
        is_male=sex == "male",
    )


def cage_open_medicine(cut_down, annoyed, guilty, eye_opener):
    return _om(
        om_cage,
        "calculate_cage",
        "CAGEParams",
        cut_down=cut_down,
        annoyed=annoyed,
        guilty=guilty,
        eye_opener=eye_opener,
    )


def ciwa_open_medicine(**kw):
    return _om(om_ciwa, "calculate_ciwa_ar", "CIWAArParams", **kw)


def centor_open_medicine(
    age, tonsillar_exudate_or_swelling, tender_anterior_cervical_nodes, temperature_c, cough_absent
):
    return _om(
        om_centor,
        "calculate_centor_mcisaac",
        "CentorMcIsaacParams",
        age=age,
        tonsillar_swelling_or_exudate=tonsillar_exudate_or_swelling,
        tender_anterior_cervical_lymphadenopathy=tender_anterior_cervical_nodes,
        fever=temperature_c > 38,
        absence_of_cough=cough_absent,
    )


def rts_open_medicine(gcs, systolic_bp, respiratory_rate):
    return _om(
        om_rts,
        "calculate_rts",
        "RTSParams",
        gcs=gcs,
        systolic_bp=systolic_bp,
        respiratory_rate=respiratory_rate,
    )


def parkland_open_medicine(weight_kg, tbsa_percent):
    return _om(
        om_parkland, "calculate_parkland", "ParklandParams", weight_kg=weight_kg, tbsa_percent=tbsa_percent
    )


def ottawa_open_medicine(**kw):
    """open-medicine returns a decision, not a count; map it to the number of series indicated."""
    result = om_ottawa.calculate_ottawa_ankle(
        om_ottawa.OttawaAnkleParams(
            malleolar_zone_pain=kw["malleolar_pain"],
            midfoot_zone_pain=kw["midfoot_pain"],
            tenderness_posterior_edge_or_tip_lateral_malleolus=kw["lateral_malleolus_tenderness"],
            tenderness_posterior_edge_or_tip_medial_malleolus=kw["medial_malleolus_tenderness"],
            tenderness_base_fifth_metatarsal=kw["fifth_metatarsal_base_tenderness"],
            tenderness_navicular=kw["navicular_tenderness"],
            inability_to_bear_weight=kw["unable_to_bear_weight"],
        )
    )
    return result.value


_NIHSS_OM = (
    "loc",
    "loc_questions",
    "loc_commands",
    "best_gaze",
    "visual_fields",
    "facial_palsy",
    "left_arm_motor",
    "right_arm_motor",
    "left_leg_motor",
    "right_leg_motor",
    "limb_ataxia",
    "sensory",
    "best_language",
    "dysarthria",
    "extinction_inattention",
)


def nihss_open_medicine(**kw):
    return _om(
        om_nihss, "calculate_nihss", "NIHSSParams", **{o: kw[k] for o, k in zip(_NIHSS_OM, _NIHSS_OURS)}
    )


def abcd2_open_medicine(age, systolic_bp, diastolic_bp, clinical_features, duration_minutes, diabetes):
    return _om(
        om_abcd2,
        "calculate_abcd2",
        "ABCD2Params",
        age_ge_60=age >= 60,
        bp_ge_140_90=systolic_bp >= 140 or diastolic_bp >= 90,
        clinical_features=clinical_features,
        duration="ge_60_min"
        if duration_minutes >= 60
        else "10_to_59_min"
        if duration_minutes >= 10
        else "lt_10_min",
        diabetes=diabetes,
    )
