"""Published worked examples, band boundaries (both sides) and invalid inputs: critical care and
pulmonary instruments. Each test names the source whose table or text the expected numbers
come from; hand-worked examples are computed from that source's published table or equation.
"""

from __future__ import annotations

import pytest

from envs import calculators as C
from envs.calculators import CalculatorInputError


# ----------------------------------------------------------------------------- GCS (Teasdale & Jennett 1974)


@pytest.mark.parametrize(
    "e,v,m,score,cat",
    [
        (4, 5, 6, 15, "mild"),
        (1, 1, 1, 3, "severe"),
        (2, 2, 4, 8, "severe"),
        (2, 2, 5, 9, "moderate"),  # 8 | 9 boundary
        (3, 4, 5, 12, "moderate"),
        (4, 4, 5, 13, "mild"),  # 12 | 13 boundary
    ],
)
def test_gcs_bands(e, v, m, score, cat):
    r = C.calculate_gcs(e, v, m)
    assert (r.score, r.category) == (score, cat)
    assert r.components == {"eye": e, "verbal": v, "motor": m}


# ----------------------------------------------------------------------------- qSOFA (Seymour 2016)


@pytest.mark.parametrize(
    "rr,sbp,am,score,cat",
    [
        (22, 100, False, 2, "high risk"),
        (21, 100, False, 1, "not high risk"),
        (22, 101, False, 1, "not high risk"),
        (21, 101, True, 1, "not high risk"),
        (30, 80, True, 3, "high risk"),
        (16, 120, False, 0, "not high risk"),
    ],
)
def test_qsofa_thresholds(rr, sbp, am, score, cat):
    r = C.calculate_qsofa(rr, sbp, am)
    assert (r.score, r.category) == (score, cat)


# ----------------------------------------------------------------------------- SIRS (Bone 1992)


def test_sirs_each_criterion_both_sides():
    base = dict(temperature_c=37.0, heart_rate=80, respiratory_rate=16, wbc_k_per_ul=8.0)
    assert C.calculate_sirs(**base).score == 0
    for arg, inside, outside in [
        ("temperature_c", 38.0, 38.1),
        ("temperature_c", 36.0, 35.9),
        ("heart_rate", 90, 91),
        ("respiratory_rate", 20, 21),
        ("wbc_k_per_ul", 12.0, 12.1),
        ("wbc_k_per_ul", 4.0, 3.9),
    ]:
        assert C.calculate_sirs(**dict(base, **{arg: inside})).score == 0, (arg, inside)
        assert C.calculate_sirs(**dict(base, **{arg: outside})).score == 1, (arg, outside)
    assert C.calculate_sirs(**base, paco2_mmhg=32).score == 0
    assert C.calculate_sirs(**base, paco2_mmhg=31).score == 1
    assert C.calculate_sirs(**base, bands_percent=10).score == 0
    assert C.calculate_sirs(**base, bands_percent=11).score == 1


def test_sirs_definition_needs_two():
    one = C.calculate_sirs(temperature_c=38.5, heart_rate=80, respiratory_rate=16, wbc_k_per_ul=8)
    two = C.calculate_sirs(temperature_c=38.5, heart_rate=95, respiratory_rate=16, wbc_k_per_ul=8)
    assert (one.score, one.category) == (1, "SIRS criteria not met")
    assert (two.score, two.category) == (2, "SIRS criteria met")


# ----------------------------------------------------------------------------- NEWS2 (RCP 2017 chart)

NORMAL = dict(
    respiratory_rate=16,
    spo2=97,
    on_supplemental_oxygen=False,
    temperature_c=37.0,
    systolic_bp=120,
    heart_rate=70,
    consciousness="alert",
)


@pytest.mark.parametrize(
    "arg,table",
    [
        ("respiratory_rate", [(8, 3), (9, 1), (11, 1), (12, 0), (20, 0), (21, 2), (24, 2), (25, 3)]),
        ("spo2", [(91, 3), (92, 2), (93, 2), (94, 1), (95, 1), (96, 0)]),
        ("systolic_bp", [(90, 3), (91, 2), (100, 2), (101, 1), (110, 1), (111, 0), (219, 0), (220, 3)]),
        (
            "heart_rate",
            [(40, 3), (41, 1), (50, 1), (51, 0), (90, 0), (91, 1), (110, 1), (111, 2), (130, 2), (131, 3)],
        ),
        (
            "temperature_c",
            [(35.0, 3), (35.1, 1), (36.0, 1), (36.1, 0), (38.0, 0), (38.1, 1), (39.0, 1), (39.1, 2)],
        ),
    ],
)
def test_news2_chart_rows(arg, table):
    key = {"spo2": "spo2", "temperature_c": "temperature"}.get(arg, arg)
    for value, points in table:
        r = C.calculate_news2(**dict(NORMAL, **{arg: value}))
        assert r.components[key] == points, (arg, value)
        assert r.score == points


def test_news2_spo2_scale2_and_oxygen():
    # RCP 2017 SpO2 scale 2: <= 83: 3, 84-85: 2, 86-87: 1, 88-92 (or >= 93 on air): 0,
    # 93-94 on oxygen: 1, 95-96 on oxygen: 2, >= 97 on oxygen: 3; oxygen itself scores 2.
    for spo2, on_o2, points in [
        (83, False, 3),
        (84, False, 2),
        (85, False, 2),
        (86, False, 1),
        (87, False, 1),
        (88, False, 0),
        (92, True, 0),
        (93, False, 0),
        (99, False, 0),
        (93, True, 1),
        (94, True, 1),
        (95, True, 2),
        (96, True, 2),
        (97, True, 3),
    ]:
        r = C.calculate_news2(**dict(NORMAL, spo2=spo2, on_supplemental_oxygen=on_o2, spo2_scale=2))
        assert r.components["spo2"] == points, (spo2, on_o2)
        assert r.components["supplemental_oxygen"] == (2 if on_o2 else 0)


def test_news2_worked_example_and_bands():
    # RR 22 (2) SpO2 95 (1) air (0) SBP 105 (1) HR 115 (2) alert (0) 38.5 C (1) = 7: high.
    r = C.calculate_news2(22, 95, False, 38.5, 105, 115, "alert")
    assert (r.score, r.category) == (7, "high")
    assert C.calculate_news2(22, 95, False, 38.5, 105, 100, "alert").score == 6
    assert C.calculate_news2(22, 95, False, 38.5, 105, 100, "alert").category == "medium"
    five = C.calculate_news2(**dict(NORMAL, heart_rate=115, systolic_bp=105, temperature_c=38.5, spo2=95))
    assert (five.score, five.category) == (5, "medium")
    four = C.calculate_news2(**dict(NORMAL, heart_rate=115, systolic_bp=105, temperature_c=38.5))
    assert (four.score, four.category) == (4, "low")
    red = C.calculate_news2(**dict(NORMAL, respiratory_rate=25))  # a single 3 with total 3
    assert (red.score, red.category) == (3, "low-medium")
    new_confusion = C.calculate_news2(**dict(NORMAL, consciousness="new_confusion"))
    assert (new_confusion.score, new_confusion.category) == (3, "low-medium")
    assert C.calculate_news2(**NORMAL).score == 0


# ----------------------------------------------------------------------------- SOFA (Vincent 1996)

SOFA0 = dict(
    pao2_fio2_ratio=450,
    on_mechanical_ventilation=False,
    platelets_k_per_ul=200,
    bilirubin_mg_dl=0.8,
    map_mmhg=85,
    gcs=15,
    creatinine_mg_dl=0.9,
)


def test_sofa_worked_example():
    # PF 250 unventilated (2), platelets 120 (1), bilirubin 1.5 (1), MAP 65 (1), GCS 13 (1),
    # creatinine 2.0 (2).
    r = C.calculate_sofa(250, False, 120, 1.5, 65, 13, 2.0)
    assert r.components == {
        "respiration": 2,
        "coagulation": 1,
        "liver": 1,
        "cardiovascular": 1,
        "cns": 1,
        "renal": 2,
    }
    assert (r.score, r.category) == (8, "SOFA 8-9")


@pytest.mark.parametrize(
    "arg,key,table",
    [
        ("pao2_fio2_ratio", "respiration", [(400, 0), (399, 1), (300, 1), (299, 2), (199, 2), (99, 2)]),
        (
            "platelets_k_per_ul",
            "coagulation",
            [(150, 0), (149, 1), (100, 1), (99, 2), (50, 2), (49, 3), (20, 3), (19, 4)],
        ),
        (
            "bilirubin_mg_dl",
            "liver",
            [(1.1, 0), (1.2, 1), (1.9, 1), (2.0, 2), (5.9, 2), (6.0, 3), (11.9, 3), (12.0, 4)],
        ),
        ("map_mmhg", "cardiovascular", [(70, 0), (69, 1)]),
        ("gcs", "cns", [(15, 0), (14, 1), (13, 1), (12, 2), (10, 2), (9, 3), (6, 3), (5, 4), (3, 4)]),
        (
            "creatinine_mg_dl",
            "renal",
            [(1.1, 0), (1.2, 1), (1.9, 1), (2.0, 2), (3.4, 2), (3.5, 3), (4.9, 3), (5.0, 4)],
        ),
    ],
)
def test_sofa_organ_bands(arg, key, table):
    for value, points in table:
        assert C.calculate_sofa(**dict(SOFA0, **{arg: value})).components[key] == points, (arg, value)


def test_sofa_respiratory_support_and_vasopressors():
    vent = dict(SOFA0, on_mechanical_ventilation=True)
    assert C.calculate_sofa(**dict(vent, pao2_fio2_ratio=199)).components["respiration"] == 3
    assert C.calculate_sofa(**dict(vent, pao2_fio2_ratio=200)).components["respiration"] == 2
    assert C.calculate_sofa(**dict(vent, pao2_fio2_ratio=99)).components["respiration"] == 4
    assert C.calculate_sofa(**dict(vent, pao2_fio2_ratio=100)).components["respiration"] == 3
    cv = lambda **kw: C.calculate_sofa(**dict(SOFA0, **kw)).components["cardiovascular"]  # noqa: E731
    assert cv(dopamine_mcg_kg_min=5) == 2 and cv(dopamine_mcg_kg_min=5.1) == 3
    assert cv(dopamine_mcg_kg_min=15) == 3 and cv(dopamine_mcg_kg_min=15.1) == 4
    assert cv(dobutamine_mcg_kg_min=20) == 2
    assert cv(epinephrine_mcg_kg_min=0.1) == 3 and cv(epinephrine_mcg_kg_min=0.11) == 4
    assert cv(norepinephrine_mcg_kg_min=0.1) == 3 and cv(norepinephrine_mcg_kg_min=0.11) == 4
    renal = lambda uo: C.calculate_sofa(**SOFA0, urine_output_ml_day=uo).components["renal"]  # noqa: E731
    assert (renal(500), renal(499), renal(200), renal(199)) == (0, 3, 3, 4)


def test_sofa_ferreira_bands():
    assert C.calculate_sofa(**SOFA0).category == "SOFA 0-1"
    r = C.calculate_sofa(50, True, 10, 15, 50, 3, 6, norepinephrine_mcg_kg_min=0.3)
    assert (r.score, r.category) == (24, "SOFA > 11")


# ----------------------------------------------------------------------------- shock index, A-a gradient


def test_shock_index():
    # Allgower 1967: HR/SBP; 1.0 marks impending shock.
    assert C.calculate_shock_index(120, 100).score == pytest.approx(1.2)
    assert C.calculate_shock_index(120, 100).category == "shock likely"
    assert C.calculate_shock_index(100, 100).category == "shock likely"
    assert C.calculate_shock_index(99, 100).category == "elevated"
    assert C.calculate_shock_index(71, 100).category == "elevated"
    assert C.calculate_shock_index(70, 100).category == "normal"


def test_aa_gradient():
    # Alveolar gas equation at sea level: PAO2 = 0.21 x 713 - 40/0.8 = 99.73; gradient = 99.73 - 90 = 9.73.
    r = C.calculate_aa_gradient(pao2_mmhg=90, paco2_mmhg=40, fio2=0.21, age=40)
    assert r.score == pytest.approx(9.73, abs=1e-6)
    assert r.category == "normal" and r.components["expected_upper_normal_mmhg"] == 14
    assert C.calculate_aa_gradient(pao2_mmhg=60, paco2_mmhg=40, fio2=0.21, age=40).category == "elevated"
    assert (
        C.calculate_aa_gradient(pao2_mmhg=85.73, paco2_mmhg=40, fio2=0.21, age=40).category == "normal"
    )  # 14.0
    assert C.calculate_aa_gradient(pao2_mmhg=85.7, paco2_mmhg=40, fio2=0.21, age=40).category == "elevated"
    assert (
        C.calculate_aa_gradient(pao2_mmhg=200, paco2_mmhg=40, fio2=0.5, age=40).category == "not classified"
    )


# ----------------------------------------------------------------------------- CURB-65 / CRB-65 (Lim 2003)

CURB0 = dict(confusion=False, bun_mg_dl=15, respiratory_rate=20, systolic_bp=120, diastolic_bp=70, age=50)


def test_curb65_each_criterion_both_sides():
    assert C.calculate_curb65(**CURB0).score == 0
    for arg, no, yes in [
        ("bun_mg_dl", 19, 19.1),
        ("respiratory_rate", 29, 30),
        ("systolic_bp", 90, 89),
        ("diastolic_bp", 61, 60),
        ("age", 64, 65),
        ("confusion", False, True),
    ]:
        assert C.calculate_curb65(**dict(CURB0, **{arg: no})).score == 0, arg
        assert C.calculate_curb65(**dict(CURB0, **{arg: yes})).score == 1, arg


@pytest.mark.parametrize(
    "n,cat", [(0, "low risk"), (1, "low risk"), (2, "moderate risk"), (3, "high risk"), (5, "high risk")]
)
def test_curb65_bands(n, cat):
    flags = [
        ("confusion", True),
        ("bun_mg_dl", 30),
        ("respiratory_rate", 32),
        ("systolic_bp", 80),
        ("age", 80),
    ]
    r = C.calculate_curb65(**dict(CURB0, **dict(flags[:n])))
    assert (r.score, r.category) == (n, cat)


def test_crb65_bands():
    base = {k: v for k, v in CURB0.items() if k != "bun_mg_dl"}
    assert C.calculate_crb65(**base).category == "low risk"
    assert C.calculate_crb65(**dict(base, age=65)).category == "increased risk"
    assert C.calculate_crb65(**dict(base, age=65, confusion=True)).score == 2
    r = C.calculate_crb65(**dict(base, age=65, confusion=True, respiratory_rate=30))
    assert (r.score, r.category) == (3, "high risk")


# -------------------------------------------------------------- Wells PE (Wells 2000), PERC (Kline 2004)

WPE0 = dict(
    clinical_signs_dvt=False,
    pe_most_likely=False,
    heart_rate=80,
    immobilization_or_recent_surgery=False,
    previous_dvt_pe=False,
    hemoptysis=False,
    malignancy=False,
)


def test_wells_pe_points_and_tiers():
    everything = dict(
        clinical_signs_dvt=True,
        pe_most_likely=True,
        heart_rate=101,
        immobilization_or_recent_surgery=True,
        previous_dvt_pe=True,
        hemoptysis=True,
        malignancy=True,
    )
    assert C.calculate_wells_pe(**everything).score == 12.5
    assert C.calculate_wells_pe(**dict(WPE0, heart_rate=100)).score == 0
    assert C.calculate_wells_pe(**dict(WPE0, heart_rate=101)).score == 1.5
    four = C.calculate_wells_pe(**dict(WPE0, pe_most_likely=True, hemoptysis=True))
    assert (four.score, four.category) == (4.0, "PE unlikely")
    four_half = C.calculate_wells_pe(**dict(WPE0, pe_most_likely=True, previous_dvt_pe=True))
    assert (four_half.score, four_half.category) == (4.5, "PE likely")
    tier = lambda **kw: C.calculate_wells_pe(**dict(WPE0, **kw), model="three_tier").category  # noqa: E731
    assert tier(previous_dvt_pe=True) == "low probability"  # 1.5
    assert tier(hemoptysis=True, malignancy=True) == "moderate probability"  # 2.0
    assert tier(clinical_signs_dvt=True, pe_most_likely=True) == "moderate probability"  # 6.0
    assert tier(clinical_signs_dvt=True, pe_most_likely=True, hemoptysis=True) == "high probability"  # 7.0


def test_perc():
    base = dict(
        age=49,
        heart_rate=99,
        spo2=95,
        unilateral_leg_swelling=False,
        hemoptysis=False,
        recent_surgery_or_trauma=False,
        prior_pe_or_dvt=False,
        hormone_use=False,
    )
    r = C.calculate_perc(**base)
    assert (r.score, r.category) == (0, "PERC negative")
    for arg, value in [("age", 50), ("heart_rate", 100), ("spo2", 94), ("hormone_use", True)]:
        r = C.calculate_perc(**dict(base, **{arg: value}))
        assert (r.score, r.category) == (1, "PERC positive"), arg


# ------------------------------------------------------------- PESI (Aujesky 2005), sPESI (Jimenez 2010)

PESI0 = dict(
    age=40,
    sex="female",
    cancer=False,
    heart_failure=False,
    chronic_lung_disease=False,
    heart_rate=80,
    systolic_bp=120,
    respiratory_rate=16,
    temperature_c=37.0,
    altered_mental_status=False,
    spo2=97,
)


def test_pesi_worked_example_and_classes():
    # 70-year-old man with cancer and pulse 115: 70 + 10 + 30 + 20 = 130, class V.
    r = C.calculate_pesi(**dict(PESI0, age=70, sex="male", cancer=True, heart_rate=115))
    assert (r.score, r.category) == (130, "Class V")
    for age, cls in [
        (65, "Class I"),
        (66, "Class II"),
        (85, "Class II"),
        (86, "Class III"),
        (105, "Class III"),
        (106, "Class IV"),
        (120, "Class IV"),
    ]:
        assert C.calculate_pesi(**dict(PESI0, age=age)).category == cls, age
    assert (
        C.calculate_pesi(**dict(PESI0, age=96, sex="male", respiratory_rate=30)).score == 126
    )  # Class V edge
    assert C.calculate_pesi(**dict(PESI0, age=96, sex="male", respiratory_rate=30)).category == "Class V"
    for arg, value, points in [
        ("heart_rate", 110, 20),
        ("systolic_bp", 99, 30),
        ("temperature_c", 35.9, 20),
        ("spo2", 89, 20),
        ("altered_mental_status", True, 60),
    ]:
        assert C.calculate_pesi(**dict(PESI0, **{arg: value})).score == 40 + points, arg
    assert (
        C.calculate_pesi(**dict(PESI0, heart_rate=109, systolic_bp=100, temperature_c=36, spo2=90)).score
        == 40
    )


def test_spesi():
    base = dict(
        age=80, cancer=False, chronic_cardiopulmonary_disease=False, heart_rate=109, systolic_bp=100, spo2=90
    )
    assert (C.calculate_spesi(**base).score, C.calculate_spesi(**base).category) == (0, "low risk")
    for arg, value in [("age", 81), ("heart_rate", 110), ("systolic_bp", 99), ("spo2", 89), ("cancer", True)]:
        r = C.calculate_spesi(**dict(base, **{arg: value}))
        assert (r.score, r.category) == (1, "high risk"), arg


def test_invalid_examples_from_requirement():
    with pytest.raises(CalculatorInputError, match="'heart_rate' must be a number in 0..350"):
        C.calculate_sirs(temperature_c=37, heart_rate=-1, respiratory_rate=16, wbc_k_per_ul=8)
