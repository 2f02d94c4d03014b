"""Adapters from our calculators' arguments to independent open-source implementations.

Each adapter takes *our* keyword arguments and returns the peer's numeric score, so a property
test can compare ``ours(**kw).score`` with ``peer(**kw)``. Peers used (test-only dependencies):

* ``medcalc`` (medcalc-bench 1.7.0, Apache-2.0): functions take ``{name: (value, unit)}`` dicts
  and return ``{"Explanation": ..., "Answer": ...}``;
* ``open_medicine`` (0.12.0, MIT): pydantic ``*Params`` models, results in ``.value``;
* ``clincalc`` (0.4.0, AGPL-3.0): adapters in ``peers_clincalc.py``, kept apart so that this
  module (used by ``bench/calculators.py`` too) never imports AGPL code; clincalc is imported
  by tests only, never from ``envs/`` or ``bench/``.

Where a peer's definition differs from the published one, the adapter does not paper over it:
the property test restricts or special-cases the inputs and says why.
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

# ----------------------------------------------------------------------------- helpers


def _mc(fn, inputs: dict) -> float:
    return fn(inputs)["Answer"]


def _om(module, func: str, params_cls: str, **kwargs) -> float:
    params = getattr(module, params_cls)(**kwargs)
    return getattr(module, func)(params).value


# ----------------------------------------------------------------------------- critical care

_MC_EYE = {4: "eyes open spontaneously", 3: "eye opening to verbal command", 2: "eye opening to pain", 1: "no eye opening"}
_MC_VERBAL = {5: "oriented", 4: "confused", 3: "inappropriate words", 2: "incomprehensible sounds",
              1: "no verbal response"}
_MC_MOTOR = {6: "obeys commands", 5: "localizes pain", 4: "withdrawal from pain", 3: "flexion to pain",
             2: "extension to pain", 1: "no motor response"}
def gcs_medcalc(eye, verbal, motor):
    return _mc(mc_gcs.compute_glasgow_coma_score_explanation, {
        "best_eye_response": _MC_EYE[eye], "best_verbal_response": _MC_VERBAL[verbal],
        "best_motor_response": _MC_MOTOR[motor]})


def gcs_open_medicine(eye, verbal, motor):
    return _om(om_gcs, "calculate_gcs", "GCSParams", eye_response=eye, verbal_response=verbal, motor_response=motor)


def qsofa_open_medicine(respiratory_rate, systolic_bp, altered_mentation):
    return _om(om_qsofa, "calculate_qsofa", "QSOFAParams", respiratory_rate=respiratory_rate,
               systolic_blood_pressure=systolic_bp, altered_mentation=altered_mentation)


def sirs_medcalc(temperature_c, heart_rate, respiratory_rate, wbc_k_per_ul, paco2_mmhg=None, bands_percent=None):
    inputs = {"temperature": (temperature_c, "degrees celsius"), "heart_rate": (heart_rate, "beats per minute"),
              "respiratory_rate": (respiratory_rate, "breaths per minute"), "wbc": (wbc_k_per_ul * 1000.0, "m^3")}
    if paco2_mmhg is not None:
        inputs["paco2"] = (paco2_mmhg, "mm Hg")
    return _mc(mc_sirs.sirs_criteria_explanation, inputs)


_OM_AVPU = {"alert": "alert", "new_confusion": "confusion", "voice": "voice", "pain": "pain",
            "unresponsive": "unresponsive"}


def news2_open_medicine(respiratory_rate, spo2, on_supplemental_oxygen, temperature_c, systolic_bp, heart_rate,
                        consciousness, spo2_scale=1):
    return _om(om_news2, "calculate_news2", "NEWS2Params", respiration_rate=respiratory_rate, spo2=spo2,
               spo2_scale=f"scale_{spo2_scale}", on_supplemental_o2=on_supplemental_oxygen, systolic_bp=systolic_bp,
               pulse=heart_rate, consciousness=_OM_AVPU[consciousness], temperature=temperature_c)


def sofa_open_medicine(pao2_fio2_ratio, on_mechanical_ventilation, platelets_k_per_ul, bilirubin_mg_dl, map_mmhg, gcs,
                       creatinine_mg_dl, dopamine_mcg_kg_min=0.0, dobutamine_mcg_kg_min=0.0,
                       epinephrine_mcg_kg_min=0.0, norepinephrine_mcg_kg_min=0.0, urine_output_ml_day=None):
    return _om(om_sofa, "calculate_sofa", "SOFAParams", pao2_fio2=pao2_fio2_ratio, platelets=platelets_k_per_ul,
               bilirubin=bilirubin_mg_dl, map_pressure=map_mmhg, dopamine=dopamine_mcg_kg_min,
               epinephrine=epinephrine_mcg_kg_min, norepinephrine=norepinephrine_mcg_kg_min, gcs=gcs,
               creatinine=creatinine_mg_dl, urine_output=urine_output_ml_day,
               **({"mechanical_ventilation": on_mechanical_ventilation}
                  if "mechanical_ventilation" in om_sofa.SOFAParams.model_fields else {}))


_OM_ADMISSION = {"nonoperative": "nonoperative", "emergency_postoperative": "emergency_surgery",
                 "elective_postoperative": "elective_surgery"}


def apache2_open_medicine(**kw):
    return _om(om_apache, "calculate_apache2", "APACHE2Params", temperature=kw["temperature_c"],
               mean_arterial_pressure=kw["map_mmhg"], heart_rate=kw["heart_rate"],
               respiratory_rate=kw["respiratory_rate"], fio2=kw["fio2"], pao2=kw["pao2_mmhg"],
               paco2=kw.get("paco2_mmhg"), arterial_ph=kw["arterial_ph"], serum_sodium=kw["sodium_mmol_l"],
               serum_potassium=kw["potassium_mmol_l"], serum_creatinine=kw["creatinine_mg_dl"],
               acute_renal_failure=kw.get("acute_renal_failure", False), hematocrit=kw["hematocrit_percent"],
               white_blood_cell_count=kw["wbc_k_per_ul"], gcs=kw["gcs"], age=kw["age"],
               admission_type=_OM_ADMISSION[kw.get("admission_type", "nonoperative")],
               severe_organ_insufficiency_or_immunocompromised=kw.get(
                   "severe_organ_insufficiency_or_immunocompromised", False))


def aa_gradient_open_medicine(pao2_mmhg, paco2_mmhg, fio2, age=None, atmospheric_pressure_mmhg=760.0,
                              respiratory_quotient=0.8):
    return _om(om_aa, "calculate_aa_gradient", "AaGradientParams", fio2=fio2, pao2=pao2_mmhg, paco2=paco2_mmhg,
               atmospheric_pressure=atmospheric_pressure_mmhg, age=age)


# ----------------------------------------------------------------------------- pulmonary


def curb65_medcalc(confusion, bun_mg_dl, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _mc(mc_curb.curb_65_explanation, {
        "age": (age, "years"), "sys_bp": (systolic_bp, "mm hg"), "dia_bp": (diastolic_bp, "mm hg"),
        "respiratory_rate": (respiratory_rate, "breaths per minute"), "bun": (bun_mg_dl, "mg/dL"),
        "confusion": confusion})


def curb65_open_medicine(confusion, bun_mg_dl, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _om(om_curb, "calculate_curb65", "CURB65Params", confusion=confusion, bun=bun_mg_dl,
               respiratory_rate=respiratory_rate, systolic_bp=systolic_bp, diastolic_bp=diastolic_bp, age=age)


def crb65_open_medicine(confusion, respiratory_rate, systolic_bp, diastolic_bp, age):
    return _om(om_crb, "calculate_crb65", "CRB65Params", confusion=confusion, respiratory_rate=respiratory_rate,
               systolic_bp=systolic_bp, diastolic_bp=diastolic_bp, age=age)


def wells_pe_medcalc(clinical_signs_dvt, pe_most_likely, heart_rate, immobilization_or_recent_surgery,
                     previous_dvt_pe, hemoptysis, malignancy, model="two_tier"):
    return _mc(mc_wpe.calculate_pe_wells_explanation, {
        "clinical_dvt": clinical_signs_dvt, "pe_number_one": pe_most_likely,
        "heart_rate": (heart_rate, "beats per minute"), "immobilization_for_3days": immobilization_or_recent_surgery,
        "surgery_in_past4weeks": False, "previous_pe": previous_dvt_pe, "previous_dvt": False,
        "hemoptysis": hemoptysis, "malignancy_with_treatment": malignancy})


def wells_pe_open_medicine(clinical_signs_dvt, pe_most_likely, heart_rate, immobilization_or_recent_surgery,
                           previous_dvt_pe, hemoptysis, malignancy, model="two_tier"):
    return _om(om_wpe, "calculate_wells_pe", "WellsPEParams", clinical_signs_dvt=clinical_signs_dvt,
               pe_most_likely_diagnosis=pe_most_likely, heart_rate_gt_100=heart_rate > 100,
               immobilization_or_surgery=immobilization_or_recent_surgery, previous_dvt_pe=previous_dvt_pe,
               hemoptysis=hemoptysis, malignancy=malignancy)


def perc_medcalc(age, heart_rate, spo2, unilateral_leg_swelling, hemoptysis, recent_surgery_or_trauma,
                 prior_pe_or_dvt, hormone_use):
    return _mc(mc_perc.compute_perc_rule_explanation, {
        "age": (age, "years"), "heart_rate": (heart_rate, "beats per minute"), "oxygen_sat": (spo2, "%"),
        "unilateral_leg_swelling": unilateral_leg_swelling, "hemoptysis": hemoptysis,
        "recent_surgery_or_trauma": recent_surgery_or_trauma, "previous_pe": prior_pe_or_dvt, "previous_dvt": False,
        "hormonal_use": hormone_use})


def perc_open_medicine(age, heart_rate, spo2, unilateral_leg_swelling, hemoptysis, recent_surgery_or_trauma,
                       prior_pe_or_dvt, hormone_use):
    return _om(om_perc, "calculate_perc", "PERCParams", age_gte_50=age >= 50, heart_rate_gte_100=heart_rate >= 100,
               spo2_lt_95=spo2 < 95, unilateral_leg_swelling=unilateral_leg_swelling, hemoptysis=hemoptysis,
               recent_surgery_or_trauma=recent_surgery_or_trauma, prior_dvt_pe=prior_pe_or_dvt,
               estrogen_use=hormone_use)


# ----------------------------------------------------------------------------- cardiology

_HEART_RF = ("hypertension", "hypercholesterolemia", "diabetes_mellitus", "obesity", "smoking", "family_with_cvd")
_MC_HISTORY = {"slightly": "Slightly suspicious", "moderately": "Moderately suspicious", "highly": "Highly suspicious"}
_MC_ECG = {"normal": "Normal", "nonspecific": "Non-specific repolarization disturbance",
           "st_deviation": "Significant ST deviation"}


def _trop_points(x):
    return 0 if x <= 1 else 1 if x <= 3 else 2


def heart_medcalc(history, ecg, age, risk_factor_count, atherosclerotic_disease, troponin_x_uln):
    trop = ("less than or equal to normal limit", "between the normal limit or up to three times the normal limit",
            "greater than three times normal limit")[_trop_points(troponin_x_uln)]
    inputs = {"age": (age, "years"), "history": _MC_HISTORY[history], "electrocardiogram": _MC_ECG[ecg],
              "atherosclerotic_disease": atherosclerotic_disease, "initial_troponin": trop}
    for k, name in enumerate(_HEART_RF):
        inputs[name] = k < risk_factor_count
    return _mc(mc_heart.compute_heart_score_explanation, inputs)


def heart_open_medicine(history, ecg, age, risk_factor_count, atherosclerotic_disease, troponin_x_uln):
    return _om(om_heart, "calculate_heart_score", "HEARTScoreParams",
               history={"slightly": 0, "moderately": 1, "highly": 2}[history],
               ecg={"normal": 0, "nonspecific": 1, "st_deviation": 2}[ecg], age=age,
               risk_factor_count=risk_factor_count, history_of_atherosclerosis=atherosclerotic_disease,
               troponin=_trop_points(troponin_x_uln))


def timi_open_medicine(age, cad_risk_factor_count, known_cad_stenosis_50, aspirin_past_7_days, angina_episodes_24h,
                       st_deviation_05mm, positive_cardiac_marker):
    return _om(om_timi, "calculate_timi_ua_nstemi", "TIMIUANSTEMIParams", age_gte_65=age >= 65,
               three_or_more_cad_risk_factors=cad_risk_factor_count >= 3, known_cad_gte_50_stenosis=known_cad_stenosis_50,
               aspirin_use_past_7_days=aspirin_past_7_days, two_or_more_anginal_events_24h=angina_episodes_24h >= 2,
               st_deviation_gte_0_5mm=st_deviation_05mm, elevated_cardiac_markers=positive_cardiac_marker)


def chads_medcalc(age, sex, chf, hypertension, diabetes, stroke_tia_thromboembolism, vascular_disease):
    return _mc(mc_chads.generate_cha2ds2_vasc_explanation, {
        "age": (age, "years"), "sex": sex.capitalize(), "chf": chf, "hypertension": hypertension,
        "diabetes": diabetes, "stroke": stroke_tia_thromboembolism, "tia": False, "thromboembolism": False,
        "vascular_disease": vascular_disease})


def chads_open_medicine(age, sex, chf, hypertension, diabetes, stroke_tia_thromboembolism, vascular_disease):
    return _om(om_chads, "calculate_chadsvasc", "CHADSVAScParams", congestive_heart_failure=chf,
               hypertension=hypertension, age=age, diabetes=diabetes,
               stroke_tia_thromboembolism=stroke_tia_thromboembolism, vascular_disease=vascular_disease,
               female_sex=sex == "female")


def hasbled_medcalc(age, uncontrolled_hypertension, abnormal_renal_function, abnormal_liver_function, stroke_history,
                    bleeding_history_or_predisposition, labile_inr, antiplatelet_or_nsaid_use, alcohol_use):
    return _mc(mc_hasbled.compute_has_bled_score_explanation, {
        "age": (age, "years"), "hypertension": uncontrolled_hypertension,
        "renal_disease_has_bled": abnormal_renal_function, "liver_disease_has_bled": abnormal_liver_function,
        "stroke": stroke_history, "prior_bleeding": bleeding_history_or_predisposition, "labile_inr": labile_inr,
        "medications_for_bleeding": antiplatelet_or_nsaid_use, "alcoholic_drinks": 8 if alcohol_use else 0})


def hasbled_open_medicine(age, uncontrolled_hypertension, abnormal_renal_function, abnormal_liver_function,
                          stroke_history, bleeding_history_or_predisposition, labile_inr, antiplatelet_or_nsaid_use,
                          alcohol_use):
    return _om(om_hasbled, "calculate_hasbled", "HASBLEDParams", hypertension=uncontrolled_hypertension,
               abnormal_renal_function=abnormal_renal_function, abnormal_liver_function=abnormal_liver_function,
               stroke=stroke_history, bleeding=bleeding_history_or_predisposition, labile_inr=labile_inr,
               elderly=age > 65, drugs=antiplatelet_or_nsaid_use, alcohol=alcohol_use)


_DVT_KEYS = ("active_cancer", "paralysis_paresis_or_cast", "bedridden_or_major_surgery", "localized_tenderness",
             "entire_leg_swollen", "calf_swelling_3cm", "pitting_edema", "collateral_superficial_veins",
             "previous_dvt", "alternative_diagnosis_as_likely")


def wells_dvt_medcalc(**kw):
    names = ("active_cancer", "paralysis_paresis_immobilization_in_lower_extreme", "bedridden_for_atleast_3_days",
             "localized_tenderness_on_deep_venuous_system", "leg_swollen", "calf_swelling_3cm",
             "pitting_edema_on_symptomatic_leg", "collateral_superficial_veins", "previous_dvt",
             "alternative_to_dvt_diagnosis")
    inputs = {n: kw[k] for n, k in zip(names, _DVT_KEYS)}
    inputs["major_surgery_in_last_12_weeks"] = False
    return _mc(mc_wdvt.compute_wells_criteria_dvt_explanation, inputs)


def wells_dvt_open_medicine(**kw):
    names = ("active_cancer", "paralysis_or_casting", "bedridden_or_major_surgery", "tenderness_along_deep_veins",
             "entire_leg_swollen", "calf_swelling_gt_3cm", "pitting_edema", "collateral_superficial_veins",
             "previously_documented_dvt", "alternative_diagnosis_likely")
    return _om(om_wdvt, "calculate_wells_dvt", "WellsDVTParams", **{n: kw[k] for n, k in zip(names, _DVT_KEYS)})


_MC_QT = {"bazett": (mc_qt_b, "bazett_calculator_explanation"),
          "fridericia": (mc_qt_f, "fredericia_calculator_explanation"),
          "framingham": (mc_qt_fr, "framingham_calculator_explanation"),
          "hodges": (mc_qt_h, "hodges_calculator_explanation")}


def qtc_medcalc(qt_ms, heart_rate, formula="bazett", sex=None):
    module, name = _MC_QT[formula]
    return _mc(getattr(module, name), {"heart_rate": (heart_rate, "beats per minute"), "qt_interval": (qt_ms, "msec")})


def qtc_open_medicine(qt_ms, heart_rate, formula="bazett", sex=None):
    return _om(om_qtc, "calculate_corrected_qtc", "CorrectedQTcParams", qt_ms=qt_ms, heart_rate=heart_rate,
               method=formula)


def map_medcalc(systolic_bp, diastolic_bp):
    return _mc(mc_map.mean_arterial_pressure_explanation,
               {"sys_bp": (systolic_bp, "mm hg"), "dia_bp": (diastolic_bp, "mm hg")})


# ----------------------------------------------------------------------------- hepatology / GI


def meld_na_medcalc(bilirubin_mg_dl, inr, creatinine_mg_dl, sodium_mmol_l, on_dialysis):
    return _mc(mc_meldna.compute_meldna_explanation, {
        "creatinine": (creatinine_mg_dl, "mg/dL"), "dialysis_twice": on_dialysis,
        "bilirubin": (bilirubin_mg_dl, "mg/dL"), "inr": inr, "sodium": (sodium_mmol_l, "mEq/L")})


def meld_na_open_medicine(bilirubin_mg_dl, inr, creatinine_mg_dl, sodium_mmol_l, on_dialysis):
    return _om(om_meld, "calculate_meld_na", "MELDNaParams", creatinine=creatinine_mg_dl, bilirubin=bilirubin_mg_dl,
               inr=inr, sodium=sodium_mmol_l, on_dialysis=on_dialysis)


_MC_ASCITES = {"none": "Absent", "mild": "Slight", "moderate_severe": "Moderate"}
_MC_ENCEPH = {"none": "No Encephalopathy", "grade_1_2": "Grade 1-2", "grade_3_4": "Grade 3-4"}


def child_pugh_medcalc(bilirubin_mg_dl, albumin_g_dl, inr, ascites, encephalopathy):
    return _mc(mc_child.compute_child_pugh_score_explanation, {
        "bilirubin": (bilirubin_mg_dl, "mg/dL"), "albumin": (albumin_g_dl, "g/dL"), "inr": inr,
        "ascites": _MC_ASCITES[ascites], "encephalopathy": _MC_ENCEPH[encephalopathy]})


def child_pugh_open_medicine(bilirubin_mg_dl, albumin_g_dl, inr, ascites, encephalopathy):
    return _om(om_child, "calculate_child_pugh", "ChildPughParams", bilirubin=bilirubin_mg_dl, albumin=albumin_g_dl,
               inr=inr, ascites={"none": "none", "mild": "mild", "moderate_severe": "severe"}[ascites],
               encephalopathy=encephalopathy)


def gbs_medcalc(bun_mg_dl, hemoglobin_g_dl, sex, systolic_bp, heart_rate, melena, syncope, hepatic_disease,
                cardiac_failure):
    return _mc(mc_gbs.glasgow_bleeding_score_explanation, {
        "hemoglobin": (hemoglobin_g_dl, "g/dL"), "bun": (bun_mg_dl, "mg/dL"), "sys_bp": (systolic_bp, "mm hg"),
        "sex": sex.capitalize(), "heart_rate": (heart_rate, "beats per minute"), "melena_present": melena,
        "syncope": syncope, "hepatic_disease_history": hepatic_disease, "cardiac_failure": cardiac_failure})


def gbs_open_medicine(bun_mg_dl, hemoglobin_g_dl, sex, systolic_bp, heart_rate, melena, syncope, hepatic_disease,
                      cardiac_failure):
    return _om(om_gbs, "calculate_glasgow_blatchford", "GlasgowBlatchfordParams", bun=bun_mg_dl,
               hemoglobin=hemoglobin_g_dl, systolic_bp=systolic_bp, pulse=heart_rate, is_male=sex == "male",
               melena=melena, syncope=syncope, hepatic_disease=hepatic_disease, cardiac_failure=cardiac_failure)


# ----------------------------------------------------------------------------- renal


def cg_medcalc(age, weight_kg, creatinine_mg_dl, sex, height_cm):
    return _mc(mc_cg.generate_cockcroft_gault_explanation, {
        "sex": sex.capitalize(), "weight": (weight_kg, "kg"), "height": (height_cm, "cm"),
        "creatinine": (creatinine_mg_dl, "mg/dL"), "age": (age, "years")})


def cg_open_medicine(age, weight_kg, creatinine_mg_dl, sex):
    return _om(om_cg, "calculate_cockcroft_gault", "CockcroftGaultParams", age=age, weight=weight_kg,
               is_female=sex == "female", serum_creatinine=creatinine_mg_dl)


def ckd_epi_medcalc(creatinine_mg_dl, age, sex):
    return _mc(mc_ckd.ckd_epi_2021_explanation, {"sex": sex.capitalize(), "age": (age, "years"),
                                                 "creatinine": (creatinine_mg_dl, "mg/dL")})


def ckd_epi_open_medicine(creatinine_mg_dl, age, sex):
    return _om(om_ckd, "calculate_ckd_epi", "CKDEPIParams", age=age, is_female=sex == "female",
               serum_creatinine=creatinine_mg_dl)


def fena_medcalc(urine_sodium_mmol_l, serum_sodium_mmol_l, urine_creatinine_mg_dl, serum_creatinine_mg_dl):
    return _mc(mc_fena.compute_fena_explanation, {
        "sodium": (serum_sodium_mmol_l, "mmol/L"), "creatinine": (serum_creatinine_mg_dl, "mg/dL"),
        "urine_sodium": (urine_sodium_mmol_l, "mmol/L"), "urine_creatinine": (urine_creatinine_mg_dl, "mg/dL")})


def fwd_medcalc(sodium_mmol_l, weight_kg, age, sex, target_sodium_mmol_l=140.0):
    return _mc(mc_fwd.free_water_deficit_explanation, {
        "sex": sex.capitalize(), "age": (age, "years"), "weight": (weight_kg, "kg"), "sodium": (sodium_mmol_l, "mmol/L")})


# ----------------------------------------------------------------------------- general


def bmi_medcalc(weight_kg, height_cm):
    return _mc(mc_bmi.bmi_calculator_explanation, {"weight": (weight_kg, "kg"), "height": (height_cm, "cm")})


def bmi_open_medicine(weight_kg, height_cm):
    return _om(om_bmi, "calculate_bmi", "BMIParams", weight_kg=weight_kg, height_cm=height_cm)


def anion_gap_medcalc(sodium, chloride, bicarbonate, albumin_g_dl=None):
    return _mc(mc_anion_gap.compute_anion_gap_explanation, {
        "sodium": (sodium, "mmol/L"), "chloride": (chloride, "mmol/L"), "bicarbonate": (bicarbonate, "mmol/L")})


def anion_gap_open_medicine(sodium, chloride, bicarbonate, albumin_g_dl=None):
    return _om(om_ag, "calculate_anion_gap", "AnionGapParams", sodium=sodium, chloride=chloride,
               bicarbonate=bicarbonate)


def calcium_medcalc(calcium_mg_dl, albumin_g_dl):
    return _mc(mc_calcium.calculate_corrected_calcium_explanation,
               {"calcium": (calcium_mg_dl, "mg/dL"), "albumin": (albumin_g_dl, "g/dL")})


def calcium_open_medicine(calcium_mg_dl, albumin_g_dl):
    return _om(om_ca, "calculate_corrected_calcium", "CorrectedCalciumParams", calcium=calcium_mg_dl,
               albumin=albumin_g_dl)


def sodium_medcalc(sodium_mmol_l, glucose_mg_dl, formula="hillier"):
    return _mc(mc_sch.compute_sodium_correction_hyperglycemia_explanation,
               {"glucose": (glucose_mg_dl, "mg/dL"), "sodium": (sodium_mmol_l, "mEq/L")})


def sodium_open_medicine(sodium_mmol_l, glucose_mg_dl, formula="katz"):
    return _om(om_na, "calculate_corrected_sodium", "CorrectedSodiumParams", sodium=sodium_mmol_l,
               glucose=glucose_mg_dl)


def osm_medcalc(sodium_mmol_l, glucose_mg_dl, bun_mg_dl):
    return _mc(mc_sosm.compute_serum_osmolality_explanation, {
        "bun": (bun_mg_dl, "mg/dL"), "glucose": (glucose_mg_dl, "mg/dL"), "sodium": (sodium_mmol_l, "mEq/L")})


def osm_open_medicine(sodium_mmol_l, glucose_mg_dl, bun_mg_dl):
    return _om(om_osm, "calculate_serum_osmolality", "SerumOsmolalityParams", sodium=sodium_mmol_l,
               glucose=glucose_mg_dl, bun=bun_mg_dl)


# ----------------------------------------------------------------------------- obstetrics


def bishop_open_medicine(dilation_cm, effacement_percent, station, consistency, position):
    return _om(om_bishop, "calculate_bishop", "BishopParams", dilation_cm=dilation_cm,
               effacement_pct=effacement_percent, station=station,
               consistency={"firm": 0, "medium": 1, "soft": 2}[consistency],
               position={"posterior": 0, "mid": 1, "anterior": 2}[position])


_APGAR = {"respiratory_effort": {"absent": 0, "weak": 1, "strong": 2},
          "muscle_tone": {"limp": 0, "some_flexion": 1, "active": 2},
          "reflex_irritability": {"none": 0, "grimace": 1, "cry": 2},
          "color": {"blue_pale": 0, "acrocyanosis": 1, "pink": 2}}


def apgar_open_medicine(heart_rate, respiratory_effort, muscle_tone, reflex_irritability, color):
    return _om(om_apgar, "calculate_apgar", "ApgarParams", appearance=_APGAR["color"][color],
               pulse=0 if heart_rate == 0 else 1 if heart_rate < 100 else 2,
               grimace=_APGAR["reflex_irritability"][reflex_irritability], activity=_APGAR["muscle_tone"][muscle_tone],
               respiration=_APGAR["respiratory_effort"][respiratory_effort])


# ----------------------------------------------------------------------------- psychiatry

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
    return _om(om_auditc, "calculate_audit_c", "AUDITCParams", frequency=responses[0], typical_quantity=responses[1],
               binge_frequency=responses[2], is_male=sex == "male")


def cage_open_medicine(cut_down, annoyed, guilty, eye_opener):
    return _om(om_cage, "calculate_cage", "CAGEParams", cut_down=cut_down, annoyed=annoyed, guilty=guilty,
               eye_opener=eye_opener)


def ciwa_open_medicine(**kw):
    return _om(om_ciwa, "calculate_ciwa_ar", "CIWAArParams", **kw)


# ----------------------------------------------------------------------------- emergency / neurology


def centor_medcalc(age, tonsillar_exudate_or_swelling, tender_anterior_cervical_nodes, temperature_c, cough_absent):
    return _mc(mc_centor.compute_centor_score_explanation, {
        "age": (age, "years"), "temperature": (temperature_c, "degrees celsius"),
        "exudate_swelling_tonsils": tonsillar_exudate_or_swelling, "tender_lymph_nodes": tender_anterior_cervical_nodes,
        "cough_absent": cough_absent})


def centor_open_medicine(age, tonsillar_exudate_or_swelling, tender_anterior_cervical_nodes, temperature_c,
                         cough_absent):
    return _om(om_centor, "calculate_centor_mcisaac", "CentorMcIsaacParams", age=age,
               tonsillar_swelling_or_exudate=tonsillar_exudate_or_swelling,
               tender_anterior_cervical_lymphadenopathy=tender_anterior_cervical_nodes, fever=temperature_c > 38,
               absence_of_cough=cough_absent)


def rts_open_medicine(gcs, systolic_bp, respiratory_rate):
    return _om(om_rts, "calculate_rts", "RTSParams", gcs=gcs, systolic_bp=systolic_bp,
               respiratory_rate=respiratory_rate)


def parkland_open_medicine(weight_kg, tbsa_percent):
    return _om(om_parkland, "calculate_parkland", "ParklandParams", weight_kg=weight_kg, tbsa_percent=tbsa_percent)


def ottawa_open_medicine(**kw):
    """open-medicine returns a decision, not a count; map it to the number of series indicated."""
    result = om_ottawa.calculate_ottawa_ankle(om_ottawa.OttawaAnkleParams(
        malleolar_zone_pain=kw["malleolar_pain"], midfoot_zone_pain=kw["midfoot_pain"],
        tenderness_posterior_edge_or_tip_lateral_malleolus=kw["lateral_malleolus_tenderness"],
        tenderness_posterior_edge_or_tip_medial_malleolus=kw["medial_malleolus_tenderness"],
        tenderness_base_fifth_metatarsal=kw["fifth_metatarsal_base_tenderness"],
        tenderness_navicular=kw["navicular_tenderness"], inability_to_bear_weight=kw["unable_to_bear_weight"]))
    return result.value


_NIHSS_OM = ("loc", "loc_questions", "loc_commands", "best_gaze", "visual_fields", "facial_palsy", "left_arm_motor",
             "right_arm_motor", "left_leg_motor", "right_leg_motor", "limb_ataxia", "sensory", "best_language",
             "dysarthria", "extinction_inattention")
_NIHSS_OURS = ("loc", "loc_questions", "loc_commands", "best_gaze", "visual_fields", "facial_palsy", "motor_arm_left",
               "motor_arm_right", "motor_leg_left", "motor_leg_right", "limb_ataxia", "sensory", "best_language",
               "dysarthria", "extinction_inattention")
def nihss_open_medicine(**kw):
    return _om(om_nihss, "calculate_nihss", "NIHSSParams", **{o: kw[k] for o, k in zip(_NIHSS_OM, _NIHSS_OURS)})


def abcd2_open_medicine(age, systolic_bp, diastolic_bp, clinical_features, duration_minutes, diabetes):
    return _om(om_abcd2, "calculate_abcd2", "ABCD2Params", age_ge_60=age >= 60,
               bp_ge_140_90=systolic_bp >= 140 or diastolic_bp >= 90, clinical_features=clinical_features,
               duration="ge_60_min" if duration_minutes >= 60 else "10_to_59_min" if duration_minutes >= 10
               else "lt_10_min", diabetes=diabetes)

