"""Published worked examples, band boundaries and invalid inputs: cardiology, hepatology/GI,
renal and general formulas. Hand-worked examples are computed from the cited equation or table.
"""

from __future__ import annotations

import pytest

from envs import calculators as C
from envs.calculators import CalculatorInputError
from envs.calculators.renal import _kdigo_g


# ----------------------------------------------------------------------------- HEART (Six 2008, Backus 2013)

HEART0 = dict(
    history="slightly",
    ecg="normal",
    age=40,
    risk_factor_count=0,
    atherosclerotic_disease=False,
    troponin_x_uln=0.5,
)


def test_heart_worked_examples_and_bands():
    top = C.calculate_heart_score("highly", "st_deviation", 70, 3, False, 4.0)
    assert (top.score, top.category) == (10, "high risk")
    assert C.calculate_heart_score(**HEART0).score == 0
    three = C.calculate_heart_score(**dict(HEART0, history="moderately", ecg="nonspecific", age=45))
    assert (three.score, three.category) == (3, "low risk")
    four = C.calculate_heart_score(**dict(HEART0, history="highly", ecg="nonspecific", age=45))
    assert (four.score, four.category) == (4, "moderate risk")
    six = C.calculate_heart_score(**dict(HEART0, history="highly", ecg="st_deviation", age=65))
    assert (six.score, six.category) == (6, "moderate risk")
    seven = C.calculate_heart_score(
        **dict(HEART0, history="highly", ecg="st_deviation", age=65, risk_factor_count=1)
    )
    assert (seven.score, seven.category) == (7, "high risk")


@pytest.mark.parametrize(
    "arg,value,key,points",
    [
        ("age", 44, "age", 0),
        ("age", 45, "age", 1),
        ("age", 64, "age", 1),
        ("age", 65, "age", 2),
        ("troponin_x_uln", 1.0, "troponin", 0),
        ("troponin_x_uln", 1.01, "troponin", 1),
        ("troponin_x_uln", 3.0, "troponin", 1),
        ("troponin_x_uln", 3.01, "troponin", 2),
        ("risk_factor_count", 1, "risk_factors", 1),
        ("risk_factor_count", 2, "risk_factors", 1),
        ("risk_factor_count", 3, "risk_factors", 2),
        ("atherosclerotic_disease", True, "risk_factors", 2),
    ],
)
def test_heart_component_edges(arg, value, key, points):
    assert C.calculate_heart_score(**dict(HEART0, **{arg: value})).components[key] == points


# ----------------------------------------------------------------------------- TIMI UA/NSTEMI (Antman 2000)

TIMI0 = dict(
    age=64,
    cad_risk_factor_count=2,
    known_cad_stenosis_50=False,
    aspirin_past_7_days=False,
    angina_episodes_24h=1,
    st_deviation_05mm=False,
    positive_cardiac_marker=False,
)


def test_timi_criteria_and_bands():
    assert C.calculate_timi_ua(**TIMI0).score == 0
    for arg, value in [
        ("age", 65),
        ("cad_risk_factor_count", 3),
        ("angina_episodes_24h", 2),
        ("known_cad_stenosis_50", True),
        ("aspirin_past_7_days", True),
        ("st_deviation_05mm", True),
        ("positive_cardiac_marker", True),
    ]:
        assert C.calculate_timi_ua(**dict(TIMI0, **{arg: value})).score == 1, arg
    two = C.calculate_timi_ua(**dict(TIMI0, age=65, aspirin_past_7_days=True))
    assert (two.score, two.category) == (2, "low risk")
    three = C.calculate_timi_ua(**dict(TIMI0, age=65, aspirin_past_7_days=True, st_deviation_05mm=True))
    assert (three.score, three.category) == (3, "intermediate risk")
    assert "13.2%" in three.interpretation  # Antman 2000, Table 3
    five = C.calculate_timi_ua(
        **dict(
            TIMI0,
            age=65,
            aspirin_past_7_days=True,
            st_deviation_05mm=True,
            positive_cardiac_marker=True,
            angina_episodes_24h=3,
        )
    )
    assert (five.score, five.category) == (5, "high risk")


# --------------------------------------------------------------------- CHA2DS2-VASc (Lip 2010, ESC 2020)

CHADS0 = dict(
    age=60,
    sex="male",
    chf=False,
    hypertension=False,
    diabetes=False,
    stroke_tia_thromboembolism=False,
    vascular_disease=False,
)


def test_cha2ds2_vasc():
    assert (C.calculate_cha2ds2_vasc(**CHADS0).score, C.calculate_cha2ds2_vasc(**CHADS0).category) == (
        0,
        "low risk",
    )
    female = C.calculate_cha2ds2_vasc(**dict(CHADS0, sex="female"))
    assert (female.score, female.category) == (1, "low risk")  # female sex alone does not raise risk
    assert C.calculate_cha2ds2_vasc(**dict(CHADS0, age=64)).components["age"] == 0
    assert C.calculate_cha2ds2_vasc(**dict(CHADS0, age=65)).components["age"] == 1
    assert C.calculate_cha2ds2_vasc(**dict(CHADS0, age=74)).components["age"] == 1
    assert C.calculate_cha2ds2_vasc(**dict(CHADS0, age=75)).components["age"] == 2
    m1 = C.calculate_cha2ds2_vasc(**dict(CHADS0, hypertension=True))
    assert (m1.score, m1.category) == (1, "intermediate risk")
    f2 = C.calculate_cha2ds2_vasc(**dict(CHADS0, sex="female", hypertension=True))
    assert (f2.score, f2.category) == (2, "intermediate risk")
    m2 = C.calculate_cha2ds2_vasc(**dict(CHADS0, stroke_tia_thromboembolism=True))
    assert (m2.score, m2.category) == (2, "high risk")
    full = dict(
        age=80,
        sex="female",
        chf=True,
        hypertension=True,
        diabetes=True,
        stroke_tia_thromboembolism=True,
        vascular_disease=True,
    )
    assert C.calculate_cha2ds2_vasc(**full).score == 9


# ----------------------------------------------------------------------------- HAS-BLED (Pisters 2010)

HB0 = dict(
    age=60,
    uncontrolled_hypertension=False,
    abnormal_renal_function=False,
    abnormal_liver_function=False,
    stroke_history=False,
    bleeding_history_or_predisposition=False,
    labile_inr=False,
    antiplatelet_or_nsaid_use=False,
    alcohol_use=False,
)


def test_has_bled():
    assert C.calculate_has_bled(**dict(HB0, age=65)).score == 0  # "elderly" is > 65
    assert C.calculate_has_bled(**dict(HB0, age=66)).score == 1
    two = C.calculate_has_bled(**dict(HB0, age=66, stroke_history=True))
    assert (two.score, two.category) == (2, "moderate risk")
    three = C.calculate_has_bled(**dict(HB0, age=66, stroke_history=True, alcohol_use=True))
    assert (three.score, three.category) == (3, "high risk")
    assert "3.74" in three.interpretation  # Pisters 2010: 3.74 bleeds per 100 patient-years
    everything = {k: (True if isinstance(v, bool) else 80) for k, v in HB0.items()}
    assert C.calculate_has_bled(**everything).score == 9


# ----------------------------------------------------------------------------- Wells DVT (Wells 2003)


def test_wells_dvt():
    keys = (
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
    none = dict.fromkeys(keys, False) | {"alternative_diagnosis_as_likely": False}
    assert C.calculate_wells_dvt(**dict(none, alternative_diagnosis_as_likely=True)).score == -2
    one = C.calculate_wells_dvt(**dict(none, previous_dvt=True))
    assert (one.score, one.category) == (1, "DVT unlikely")
    two = C.calculate_wells_dvt(**dict(none, previous_dvt=True, pitting_edema=True))
    assert (two.score, two.category) == (2, "DVT likely")
    assert (
        C.calculate_wells_dvt(**dict.fromkeys(keys, True), alternative_diagnosis_as_likely=False).score == 9
    )
    assert C.calculate_wells_dvt(**dict.fromkeys(keys, True), alternative_diagnosis_as_likely=True).score == 7


# ----------------------------------------------------------------------------- QTc and MAP


def test_qtc_formulas():
    # QT 400 ms at HR 100 (RR 0.6 s): Bazett 400/0.6^0.5 = 516.4; Fridericia 400/0.6^(1/3) = 474.3;
    # Framingham 400 + 154 x 0.4 = 461.6; Hodges 400 + 1.75 x 40 = 470.
    expected = {"bazett": 516.40, "fridericia": 474.25, "framingham": 461.6, "hodges": 470.0}
    for formula, value in expected.items():
        assert C.calculate_qtc(400, 100, formula).score == pytest.approx(value, abs=0.01), formula
    for formula in expected:  # at 60 beats/min every correction is the identity
        assert C.calculate_qtc(400, 60, formula).score == pytest.approx(400)


def test_qtc_bands():
    assert C.calculate_qtc(449, 60).category == "normal"
    assert C.calculate_qtc(450, 60).category == "prolonged"
    assert C.calculate_qtc(455, 60, sex="female").category == "normal"
    assert C.calculate_qtc(460, 60, sex="female").category == "prolonged"
    assert C.calculate_qtc(500, 60).category == "prolonged"
    assert C.calculate_qtc(501, 60).category == "markedly prolonged"
    assert C.calculate_qtc(390, 60).category == "short"
    assert C.calculate_qtc(391, 60).category == "normal"


def test_map():
    assert C.calculate_map(120, 80).score == pytest.approx(93.333, abs=1e-3)
    assert C.calculate_map(95, 50).category == "at or above target"  # 65.0
    assert C.calculate_map(94, 50).category == "below target"  # 64.7
    with pytest.raises(CalculatorInputError, match="'diastolic_bp' must be at most systolic_bp"):
        C.calculate_map(80, 90)


# ----------------------------------------------------------------------------- MELD-Na (OPTN/UNOS 2016)


def test_meld_na_worked_example():
    # MELD(i) = 0.957 ln 1.2 + 0.378 ln 2 + 1.120 ln 1.5 + 0.643 = 1.5336 -> 15 (x10, to the tenth);
    # > 11, so MELD = 15 + 1.32 x 7 - 0.033 x 15 x 7 = 20.775 -> 21.
    r = C.calculate_meld_na(2.0, 1.5, 1.2, 130, False)
    assert r.components["meld_i"] == 15 and r.components["sodium_term_applied"] is True
    assert (r.score, r.category) == (21, "MELD 20-29")


def test_meld_na_bounds_and_rules():
    assert C.calculate_meld_na(0.5, 0.9, 0.5, 140, False).score == 6  # all set to 1.0: 0.643 -> 6
    # Dialysis sets creatinine to 4.0: 0.957 ln 4 + 0.643 = 1.9697 -> 20; sodium 137 adds nothing.
    assert C.calculate_meld_na(1.0, 1.0, 0.8, 137, True).score == 20
    assert C.calculate_meld_na(1.0, 1.0, 9.0, 137, False).score == 20  # creatinine capped at 4.0
    # INR 1.55: 0.643 + 1.12 ln 1.55 = 1.1338 -> MELD(i) 11: no sodium term even at Na 125.
    eleven = C.calculate_meld_na(1.0, 1.55, 1.0, 125, False)
    assert (eleven.score, eleven.components["sodium_term_applied"]) == (11, False)
    # INR 1.6: 1.1694 -> 12 > 11: 12 + 1.32 x 12 - 0.033 x 12 x 12 = 23.088 -> 23 (Na 125).
    assert C.calculate_meld_na(1.0, 1.6, 1.0, 125, False).score == 23
    assert C.calculate_meld_na(1.0, 1.6, 1.0, 110, False).score == 23  # sodium bounded at 125
    assert C.calculate_meld_na(30, 5, 4, 125, False).score == 40  # capped at 40
    assert C.calculate_meld_na(1.0, 1.6, 1.0, 137, False).category == "MELD 10-19"
    assert C.calculate_meld_na(0.5, 0.9, 0.5, 140, False).category == "MELD < 10"


# ----------------------------------------------------------------------------- Child-Pugh (Pugh 1973)

CP0 = dict(bilirubin_mg_dl=1.0, albumin_g_dl=4.0, inr=1.0, ascites="none", encephalopathy="none")


@pytest.mark.parametrize(
    "arg,table",
    [
        ("bilirubin_mg_dl", [(1.9, 1), (2.0, 2), (3.0, 2), (3.1, 3)]),
        ("albumin_g_dl", [(3.6, 1), (3.5, 2), (2.8, 2), (2.7, 3)]),
        ("inr", [(1.69, 1), (1.7, 2), (2.3, 2), (2.31, 3)]),
    ],
)
def test_child_pugh_lab_bands(arg, table):
    key = arg.split("_")[0]
    for value, points in table:
        assert C.calculate_child_pugh(**dict(CP0, **{arg: value})).components[key] == points, value


def test_child_pugh_classes():
    assert (C.calculate_child_pugh(**CP0).score, C.calculate_child_pugh(**CP0).category) == (5, "Class A")
    six = C.calculate_child_pugh(**dict(CP0, ascites="mild"))
    seven = C.calculate_child_pugh(**dict(CP0, ascites="mild", encephalopathy="grade_1_2"))
    assert (six.score, six.category, seven.score, seven.category) == (6, "Class A", 7, "Class B")
    nine = C.calculate_child_pugh(2.5, 3.0, 1.8, "mild", "none")
    assert (nine.score, nine.category) == (9, "Class B")
    ten = C.calculate_child_pugh(2.5, 3.0, 1.8, "mild", "grade_1_2")
    assert (ten.score, ten.category) == (10, "Class C")
    assert C.calculate_child_pugh(5, 2, 3, "moderate_severe", "grade_3_4").score == 15


# ------------------------------------------------------------------ Glasgow-Blatchford (Blatchford 2000)

GBS0 = dict(
    bun_mg_dl=10,
    hemoglobin_g_dl=15,
    sex="male",
    systolic_bp=120,
    heart_rate=80,
    melena=False,
    syncope=False,
    hepatic_disease=False,
    cardiac_failure=False,
)


@pytest.mark.parametrize(
    "arg,key,table",
    [
        # urea mmol/L = BUN / 2.8: 6.5 -> 18.2, 8 -> 22.4, 10 -> 28, 25 -> 70 mg/dL
        (
            "bun_mg_dl",
            "urea",
            [(18.1, 0), (18.2, 2), (22.3, 2), (22.4, 3), (27.9, 3), (28.0, 4), (69.9, 4), (70.0, 6)],
        ),
        ("hemoglobin_g_dl", "hemoglobin", [(13.0, 0), (12.9, 1), (12.0, 1), (11.9, 3), (10.0, 3), (9.9, 6)]),
        ("systolic_bp", "systolic_bp", [(110, 0), (109, 1), (100, 1), (99, 2), (90, 2), (89, 3)]),
        ("heart_rate", "heart_rate_ge_100", [(99, 0), (100, 1)]),
    ],
)
def test_glasgow_blatchford_bands(arg, key, table):
    for value, points in table:
        assert C.calculate_glasgow_blatchford(**dict(GBS0, **{arg: value})).components[key] == points, value


def test_glasgow_blatchford_women_and_categories():
    women = [(12.0, 0), (11.9, 1), (10.0, 1), (9.9, 6)]
    for hb, points in women:
        r = C.calculate_glasgow_blatchford(**dict(GBS0, sex="female", hemoglobin_g_dl=hb))
        assert r.components["hemoglobin"] == points
    one = C.calculate_glasgow_blatchford(**dict(GBS0, melena=True))
    assert (one.score, one.category) == (1, "very low risk")
    two = C.calculate_glasgow_blatchford(**dict(GBS0, syncope=True))
    assert (two.score, two.category) == (2, "not low risk")
    worst = dict(
        bun_mg_dl=80,
        hemoglobin_g_dl=8,
        sex="male",
        systolic_bp=80,
        heart_rate=120,
        melena=True,
        syncope=True,
        hepatic_disease=True,
        cardiac_failure=True,
    )
    assert C.calculate_glasgow_blatchford(**worst).score == 23


# ----------------------------------------------------------------------------- renal equations


def test_cockcroft_gault():
    # (140 - 60) x 70 / (72 x 1.2) = 64.81 mL/min; female x 0.85 = 55.09.
    assert C.calculate_creatinine_clearance(60, 70, 1.2, "male").score == pytest.approx(64.815, abs=1e-3)
    female = C.calculate_creatinine_clearance(60, 70, 1.2, "female")
    assert female.score == pytest.approx(55.093, abs=1e-3) and female.category == "moderate impairment"
    assert C.calculate_creatinine_clearance(60, 70, 1.2, "male").category == "mild impairment"
    assert C.calculate_creatinine_clearance(40, 72, 1.0, "male").score == pytest.approx(100)  # 100 x 72 / 72
    assert C.calculate_creatinine_clearance(40, 72, 1.0, "male").category == "normal"
    assert C.calculate_creatinine_clearance(40, 64.8, 1.0, "male").category == "normal"  # exactly 90.0
    assert C.calculate_creatinine_clearance(40, 64.7, 1.0, "male").category == "mild impairment"


def test_ckd_epi_2021():
    # Inker 2021: 142 x min(Scr/k, 1)^a x max(Scr/k, 1)^-1.2 x 0.9938^age x 1.012 [female]
    # female 50 y, 1.0 mg/dL: 142 x 1.4286^-1.2 x 0.9938^50 x 1.012 = 68.6
    f = C.calculate_ckd_epi_2021(1.0, 50, "female")
    assert f.score == pytest.approx(68.64, abs=0.05) and f.category == "G2"
    m = C.calculate_ckd_epi_2021(1.0, 50, "male")  # 142 x 1.1111^-1.2 x 0.9938^50 = 91.7
    assert m.score == pytest.approx(91.69, abs=0.05) and m.category == "G1"
    low = C.calculate_ckd_epi_2021(0.8, 40, "male")  # 142 x 0.8889^-0.302 x 0.9938^40 = 114.7
    assert low.score == pytest.approx(114.73, abs=0.05)


@pytest.mark.parametrize(
    "gfr,cat",
    [
        (90, "G1"),
        (89.99, "G2"),
        (60, "G2"),
        (59.99, "G3a"),
        (45, "G3a"),
        (44.99, "G3b"),
        (30, "G3b"),
        (29.99, "G4"),
        (15, "G4"),
        (14.99, "G5"),
    ],
)
def test_kdigo_gfr_categories(gfr, cat):
    assert _kdigo_g(gfr)[0] == cat


def test_bedside_schwartz():
    r = C.calculate_bedside_schwartz(height_cm=120, creatinine_mg_dl=0.5, age=8)  # 0.413 x 120 / 0.5
    assert r.score == pytest.approx(99.12) and r.category == "G1"


def test_fena():
    # Espinel 1976: (UNa x PCr) / (PNa x UCr) x 100 = 20 x 2 / (140 x 100) x 100 = 0.286 %
    r = C.calculate_fena(20, 140, 100, 2.0)
    assert r.score == pytest.approx(0.2857, abs=1e-4) and r.category == "prerenal"
    assert C.calculate_fena(70, 140, 100, 2.0).category == "indeterminate"  # exactly 1 %
    assert C.calculate_fena(140, 140, 100, 2.0).category == "indeterminate"  # exactly 2 %
    assert C.calculate_fena(141, 140, 100, 2.0).category == "intrinsic renal"
    assert C.calculate_fena(69, 140, 100, 2.0).category == "prerenal"


def test_free_water_deficit():
    # Adrogue & Madias 2000: 70-kg man (TBW 0.6): 42 x (160/140 - 1) = 6.0 L.
    r = C.calculate_free_water_deficit(160, 70, 40, "male")
    assert r.score == pytest.approx(6.0) and r.category == "free-water deficit"
    old_woman = C.calculate_free_water_deficit(155, 60, 70, "female")  # TBW 0.45 x 60 = 27 L
    assert old_woman.components["total_body_water_fraction"] == 0.45
    assert old_woman.score == pytest.approx(27 * (155 / 140 - 1))
    assert (
        C.calculate_free_water_deficit(150, 70, 64, "female").components["total_body_water_fraction"] == 0.5
    )
    assert C.calculate_free_water_deficit(150, 70, 65, "male").components["total_body_water_fraction"] == 0.5
    assert (
        C.calculate_free_water_deficit(150, 30, 10, "female").components["total_body_water_fraction"] == 0.6
    )
    assert C.calculate_free_water_deficit(140, 70, 40, "male").category == "no deficit"


# ----------------------------------------------------------------------------- general formulas


@pytest.mark.parametrize(
    "weight,cat",
    [
        (18.4, "underweight"),
        (18.5, "normal weight"),
        (24.9, "normal weight"),
        (25.0, "overweight"),
        (29.9, "overweight"),
        (30.0, "obesity class I"),
        (34.9, "obesity class I"),
        (35.0, "obesity class II"),
        (39.9, "obesity class II"),
        (40.0, "obesity class III"),
    ],
)
def test_bmi_who_bands(weight, cat):
    r = C.calculate_bmi(weight, 100)  # height 1 m: BMI equals the weight
    assert r.score == pytest.approx(weight) and r.category == cat


def test_bmi_example():
    assert C.calculate_bmi(70, 175).score == pytest.approx(22.857, abs=1e-3)


def test_anion_gap():
    r = C.calculate_anion_gap(140, 104, 24)
    assert (r.score, r.category) == (12, "elevated")
    assert C.calculate_anion_gap(140, 105, 24).category == "normal"  # 11
    assert C.calculate_anion_gap(140, 113, 24).category == "normal"  # 3
    assert C.calculate_anion_gap(140, 114, 24).category == "low"  # 2
    corrected = C.calculate_anion_gap(140, 107, 24, albumin_g_dl=2.0)  # 9 + 2.5 x 2 = 14
    assert corrected.score == 9 and corrected.components["albumin_corrected_gap"] == 14
    assert corrected.category == "elevated"


def test_corrected_calcium():
    # Payne 1973: Ca + 0.8 x (4.0 - albumin): 8.0 + 1.6 = 9.6
    r = C.calculate_corrected_calcium(8.0, 2.0)
    assert r.score == pytest.approx(9.6) and r.category == "normal"
    assert C.calculate_corrected_calcium(8.4, 4.0).category == "hypocalcaemia"
    assert C.calculate_corrected_calcium(8.5, 4.0).category == "normal"
    assert C.calculate_corrected_calcium(10.5, 4.0).category == "normal"
    assert C.calculate_corrected_calcium(10.6, 4.0).category == "hypercalcaemia"


def test_corrected_sodium():
    assert C.calculate_corrected_sodium(130, 600).score == pytest.approx(138.0)  # Katz: + 1.6 x 5
    assert C.calculate_corrected_sodium(130, 600, "hillier").score == pytest.approx(
        142.0
    )  # Hillier: + 2.4 x 5
    assert C.calculate_corrected_sodium(134, 100).category == "hyponatraemia"
    assert C.calculate_corrected_sodium(135, 100).category == "normal"
    assert C.calculate_corrected_sodium(145, 100).category == "normal"
    assert C.calculate_corrected_sodium(146, 100).category == "hypernatraemia"


def test_serum_osmolality():
    # 2 x 140 + 90/18 + 14/2.8 = 280 + 5 + 5 = 290
    r = C.calculate_serum_osmolality(140, 90, 14)
    assert r.score == pytest.approx(290) and r.category == "normal"
    assert C.calculate_serum_osmolality(140, 90, 14, ethanol_mg_dl=370).score == pytest.approx(390)
    gap = C.calculate_serum_osmolality(140, 90, 14, measured_osmolality_mosm_kg=310)
    assert gap.components["osmolal_gap"] == pytest.approx(20) and gap.category == "elevated osmolal gap"
    assert C.calculate_serum_osmolality(140, 90, 14, measured_osmolality_mosm_kg=300).category == "normal"
    assert C.calculate_serum_osmolality(130, 90, 14).category == "low"  # 270
