"""Published worked examples, band boundaries and invalid inputs: emergency, neurology,
obstetrics and psychiatry instruments.
"""

from __future__ import annotations

import pytest

from envs import calculators as C
from envs.calculators import CalculatorInputError


# ----------------------------------------------------------------------------- ESI v4 (Gilboy 2012 handbook)

ESI0 = dict(
    requires_immediate_lifesaving_intervention=False,
    high_risk_situation=False,
    confused_lethargic_or_disoriented=False,
    severe_pain_or_distress=False,
    expected_resources=0,
    age_years=40,
)


def test_esi_decision_points():
    # Handbook examples: apnoeic patient needing intubation (A) -> 1; chest pain suspicious of ACS (B) -> 2;
    # abdominal pain needing labs and CT (C, 2 resources) -> 3; ankle injury needing an X-ray -> 4;
    # prescription refill -> 5.
    assert (
        C.calculate_esi_level(**dict(ESI0, requires_immediate_lifesaving_intervention=True)).category
        == "ESI 1"
    )
    assert C.calculate_esi_level(**dict(ESI0, high_risk_situation=True)).category == "ESI 2"
    assert C.calculate_esi_level(**dict(ESI0, confused_lethargic_or_disoriented=True)).score == 2
    assert C.calculate_esi_level(**dict(ESI0, severe_pain_or_distress=True)).score == 2
    assert C.calculate_esi_level(**dict(ESI0, expected_resources=2)).category == "ESI 3"
    assert C.calculate_esi_level(**dict(ESI0, expected_resources=1)).category == "ESI 4"
    assert C.calculate_esi_level(**ESI0).category == "ESI 5"


@pytest.mark.parametrize(
    "age,hr_ok,hr_bad,rr_ok,rr_bad",
    [
        (0.1, 180, 181, 50, 51),  # < 3 months
        (2.0, 160, 161, 40, 41),  # 3 months - 3 years
        (5.0, 140, 141, 30, 31),  # 3 - 8 years
        (40.0, 100, 101, 20, 21),  # > 8 years
    ],
)
def test_esi_danger_zone_vitals(age, hr_ok, hr_bad, rr_ok, rr_bad):
    base = dict(ESI0, expected_resources=2, age_years=age)
    assert C.calculate_esi_level(**base, heart_rate=hr_ok, respiratory_rate=rr_ok, spo2=92).score == 3
    assert C.calculate_esi_level(**base, heart_rate=hr_bad).score == 2
    assert C.calculate_esi_level(**base, respiratory_rate=rr_bad).score == 2
    assert C.calculate_esi_level(**base, spo2=91).score == 2
    kept = C.calculate_esi_level(**base, heart_rate=hr_bad, uptriage_danger_zone=False)
    assert kept.score == 3 and kept.flags == (f"danger-zone vital: heart rate > {hr_ok}",)
    # danger-zone vitals matter only at decision point D (two or more resources)
    assert C.calculate_esi_level(**dict(base, expected_resources=1), heart_rate=hr_bad).score == 4


# ----------------------------------------------------------------------------- Centor / McIsaac

CENTOR0 = dict(
    age=30,
    tonsillar_exudate_or_swelling=False,
    tender_anterior_cervical_nodes=False,
    temperature_c=37.0,
    cough_absent=False,
)


def test_centor_mcisaac():
    assert C.calculate_centor(10, True, True, 38.5, True).score == 5  # McIsaac 1998: 4 criteria + age 3-14
    for age, points in [(3, 1), (14, 1), (15, 0), (44, 0), (45, -1)]:
        assert C.calculate_centor(**dict(CENTOR0, age=age)).components["age"] == points
    assert C.calculate_centor(**dict(CENTOR0, temperature_c=38.0)).score == 0
    assert C.calculate_centor(**dict(CENTOR0, temperature_c=38.1)).score == 1
    assert C.calculate_centor(**dict(CENTOR0, age=50)).score == -1
    one = C.calculate_centor(**dict(CENTOR0, cough_absent=True))
    two = C.calculate_centor(**dict(CENTOR0, cough_absent=True, tender_anterior_cervical_nodes=True))
    assert (one.category, two.category) == ("low risk", "intermediate risk")
    three = C.calculate_centor(
        **dict(CENTOR0, cough_absent=True, tender_anterior_cervical_nodes=True, temperature_c=38.5)
    )
    four = C.calculate_centor(
        **dict(
            CENTOR0,
            cough_absent=True,
            tender_anterior_cervical_nodes=True,
            temperature_c=38.5,
            tonsillar_exudate_or_swelling=True,
        )
    )
    assert (three.score, three.category, four.score, four.category) == (
        3,
        "intermediate risk",
        4,
        "high risk",
    )


# ------------------------------------------------------------------ Revised Trauma Score (Champion 1989)


def test_rts_weights_and_range():
    assert C.calculate_revised_trauma_score(15, 120, 16).score == pytest.approx(7.8408)
    assert C.calculate_revised_trauma_score(3, 0, 0).score == 0
    r = C.calculate_revised_trauma_score(10, 80, 35)  # codes 3, 3, 3 -> 0.9368x3 + 0.7326x3 + 0.2908x3
    assert (
        r.score == pytest.approx(5.8806) and r.components["triage_rts"] == 9 and r.category == "trauma center"
    )
    assert C.calculate_revised_trauma_score(15, 120, 16).category == "no triage criterion"


@pytest.mark.parametrize(
    "arg,key,table",
    [
        ("gcs", "gcs_code", [(13, 4), (12, 3), (9, 3), (8, 2), (6, 2), (5, 1), (4, 1), (3, 0)]),
        (
            "systolic_bp",
            "systolic_bp_code",
            [(90, 4), (89, 3), (76, 3), (75, 2), (50, 2), (49, 1), (1, 1), (0, 0)],
        ),
        (
            "respiratory_rate",
            "respiratory_rate_code",
            [(10, 4), (29, 4), (30, 3), (9, 2), (6, 2), (5, 1), (1, 1), (0, 0)],
        ),
    ],
)
def test_rts_codes(arg, key, table):
    base = dict(gcs=15, systolic_bp=120, respiratory_rate=16)
    for value, code in table:
        assert C.calculate_revised_trauma_score(**dict(base, **{arg: value})).components[key] == code, value


# ----------------------------------------------------------------------------- Parkland (Baxter 1968)


def test_parkland():
    r = C.calculate_parkland(70, 50)  # 4 x 70 x 50 = 14,000 mL; half in the first 8 h
    assert (
        r.score == 14000 and r.components["first_8h_ml"] == 7000 and r.components["first_8h_rate_ml_h"] == 875
    )
    assert r.components["next_16h_rate_ml_h"] == 437.5
    assert C.calculate_parkland(70, 19).category == "below resuscitation threshold"
    assert C.calculate_parkland(70, 20).category == "formal resuscitation"


# ----------------------------------------------------------------------------- Alvarado (1986)

ALV0 = dict(
    migration_to_rlq=False,
    anorexia=False,
    nausea_vomiting=False,
    rlq_tenderness=False,
    rebound_tenderness=False,
    temperature_c=37.0,
    wbc_k_per_ul=8,
    neutrophil_percent=60,
)


def test_alvarado():
    full = dict(
        migration_to_rlq=True,
        anorexia=True,
        nausea_vomiting=True,
        rlq_tenderness=True,
        rebound_tenderness=True,
        temperature_c=38.0,
        wbc_k_per_ul=15,
        neutrophil_percent=85,
    )
    assert (C.calculate_alvarado(**full).score, C.calculate_alvarado(**full).category) == (
        10,
        "very probable",
    )
    assert C.calculate_alvarado(**dict(ALV0, temperature_c=37.2)).score == 0
    assert C.calculate_alvarado(**dict(ALV0, temperature_c=37.3)).score == 1
    assert C.calculate_alvarado(**dict(ALV0, wbc_k_per_ul=10)).score == 0
    assert C.calculate_alvarado(**dict(ALV0, wbc_k_per_ul=10.1)).score == 2
    assert C.calculate_alvarado(**dict(ALV0, neutrophil_percent=75)).score == 0
    assert C.calculate_alvarado(**dict(ALV0, neutrophil_percent=76)).score == 1
    four = dict(ALV0, rlq_tenderness=True, wbc_k_per_ul=12)
    assert C.calculate_alvarado(**four).category == "unlikely"
    assert C.calculate_alvarado(**dict(four, anorexia=True)).category == "compatible"  # 5
    assert (
        C.calculate_alvarado(**dict(four, anorexia=True, migration_to_rlq=True)).category == "compatible"
    )  # 6
    seven = dict(four, anorexia=True, migration_to_rlq=True, nausea_vomiting=True)
    assert C.calculate_alvarado(**seven).category == "probable"
    assert C.calculate_alvarado(**dict(seven, rebound_tenderness=True)).category == "probable"  # 8
    assert (
        C.calculate_alvarado(**dict(seven, rebound_tenderness=True, neutrophil_percent=80)).category
        == "very probable"
    )


# ---------------------------------------------------------------------- Ottawa ankle rules (Stiell 1993)

OTT0 = dict(
    malleolar_pain=False,
    midfoot_pain=False,
    lateral_malleolus_tenderness=False,
    medial_malleolus_tenderness=False,
    fifth_metatarsal_base_tenderness=False,
    navicular_tenderness=False,
    unable_to_bear_weight=False,
)


def test_ottawa_ankle():
    assert C.calculate_ottawa_ankle(**dict(OTT0, malleolar_pain=True)).category == "no radiographs"
    assert (
        C.calculate_ottawa_ankle(
            **dict(OTT0, malleolar_pain=True, lateral_malleolus_tenderness=True)
        ).category
        == "ankle radiographs"
    )
    assert (
        C.calculate_ottawa_ankle(**dict(OTT0, midfoot_pain=True, navicular_tenderness=True)).category
        == "foot radiographs"
    )
    both = C.calculate_ottawa_ankle(
        **dict(OTT0, malleolar_pain=True, midfoot_pain=True, unable_to_bear_weight=True)
    )
    assert (both.score, both.category) == (2, "ankle and foot radiographs")
    # tenderness without pain in that zone does not trigger the rule
    assert C.calculate_ottawa_ankle(**dict(OTT0, fifth_metatarsal_base_tenderness=True)).score == 0


# ------------------------------------------------------------- NIHSS (Brott 1989), ABCD2 (Johnston 2007)

NIH0 = dict(
    loc=0,
    loc_questions=0,
    loc_commands=0,
    best_gaze=0,
    visual_fields=0,
    facial_palsy=0,
    motor_arm_left=0,
    motor_arm_right=0,
    motor_leg_left=0,
    motor_leg_right=0,
    limb_ataxia=0,
    sensory=0,
    best_language=0,
    dysarthria=0,
    extinction_inattention=0,
)


@pytest.mark.parametrize(
    "arms,cat",
    [(0, "no stroke symptoms"), (4, "minor stroke"), (5, "moderate stroke"), (8, "moderate stroke")],
)
def test_nihss_bands(arms, cat):
    left, right = min(arms, 4), max(arms - 4, 0)
    r = C.calculate_nihss(**dict(NIH0, motor_arm_left=left, motor_arm_right=right))
    assert (r.score, r.category) == (arms, cat)


def test_nihss_upper_bands_and_coma_rules():
    fifteen = dict(NIH0, motor_arm_left=4, motor_leg_left=4, facial_palsy=3, visual_fields=2, best_language=2)
    assert (C.calculate_nihss(**fifteen).score, C.calculate_nihss(**fifteen).category) == (
        15,
        "moderate stroke",
    )
    assert C.calculate_nihss(**dict(fifteen, sensory=1)).category == "moderate to severe stroke"  # 16
    twenty = dict(fifteen, sensory=2, best_gaze=2, dysarthria=1)
    assert (C.calculate_nihss(**twenty).score, C.calculate_nihss(**twenty).category) == (
        20,
        "moderate to severe stroke",
    )
    assert C.calculate_nihss(**dict(twenty, extinction_inattention=1)).category == "severe stroke"  # 21
    coma = dict(
        loc=3,
        loc_questions=2,
        loc_commands=2,
        best_gaze=2,
        visual_fields=3,
        facial_palsy=3,
        motor_arm_left=4,
        motor_arm_right=4,
        motor_leg_left=4,
        motor_leg_right=4,
        limb_ataxia=2,
        sensory=2,
        best_language=3,
        dysarthria=2,
        extinction_inattention=2,
    )
    assert C.calculate_nihss(**coma).score == 42
    with pytest.raises(CalculatorInputError, match="'best_language' must be 3 when loc is 3"):
        C.calculate_nihss(**dict(coma, best_language=0))


def test_abcd2():
    top = C.calculate_abcd2(65, 150, 95, "unilateral_weakness", 60, True)
    assert (top.score, top.category) == (7, "high risk")
    base = dict(
        age=59,
        systolic_bp=139,
        diastolic_bp=89,
        clinical_features="other",
        duration_minutes=9,
        diabetes=False,
    )
    assert C.calculate_abcd2(**base).score == 0
    for arg, value, points in [
        ("age", 60, 1),
        ("systolic_bp", 140, 1),
        ("diastolic_bp", 90, 1),
        ("duration_minutes", 10, 1),
        ("duration_minutes", 59, 1),
        ("duration_minutes", 60, 2),
        ("clinical_features", "speech_disturbance", 1),
        ("clinical_features", "unilateral_weakness", 2),
    ]:
        assert C.calculate_abcd2(**dict(base, **{arg: value})).score == points, (arg, value)
    three = C.calculate_abcd2(**dict(base, age=60, clinical_features="unilateral_weakness"))
    four = C.calculate_abcd2(**dict(base, age=60, systolic_bp=140, clinical_features="unilateral_weakness"))
    assert (three.category, four.category) == ("low risk", "moderate risk")
    five = C.calculate_abcd2(
        **dict(base, age=60, duration_minutes=60, clinical_features="unilateral_weakness")
    )
    six = C.calculate_abcd2(
        **dict(base, age=60, diabetes=True, duration_minutes=60, clinical_features="unilateral_weakness")
    )
    assert (five.score, five.category, six.score, six.category) == (5, "moderate risk", 6, "high risk")


# ------------------------------------------------------- Bishop (1964), Apgar (1953), BPP (Manning 1980)


def test_bishop_worked_example_and_bands():
    # 2 cm (1), 50 % (1), station -1 (2), soft (2), mid (1) = 7
    r = C.calculate_bishop_score(2, 50, -1, "soft", "mid")
    assert (r.score, r.category) == (7, "intermediate")
    assert C.calculate_bishop_score(0, 0, -3, "firm", "posterior").score == 0
    assert C.calculate_bishop_score(5, 80, 1, "soft", "anterior").score == 13
    assert C.calculate_bishop_score(1, 40, -2, "medium", "mid").category == "unfavorable"  # 1+1+1+1+1 = 5
    six = C.calculate_bishop_score(1, 40, -1, "medium", "mid")  # 1+1+2+1+1 = 6
    eight = C.calculate_bishop_score(3, 60, -1, "medium", "mid")  # 2+2+2+1+1 = 8
    nine = C.calculate_bishop_score(3, 60, -1, "soft", "mid")  # 9
    assert (six.score, six.category) == (6, "unfavorable")
    assert (eight.score, eight.category) == (8, "intermediate")
    assert (nine.score, nine.category) == (9, "favorable")


@pytest.mark.parametrize(
    "arg,key,table",
    [
        (
            "dilation_cm",
            "dilation",
            [(0, 0), (0.9, 0), (1, 1), (2, 1), (2.9, 1), (3, 2), (4, 2), (4.9, 2), (5, 3)],
        ),
        (
            "effacement_percent",
            "effacement",
            [(30, 0), (39, 0), (40, 1), (50, 1), (60, 2), (70, 2), (79, 2), (80, 3)],
        ),
        ("station", "station", [(-5, 0), (-3, 0), (-2, 1), (-1, 2), (0, 2), (1, 3), (2, 3)]),
    ],
)
def test_bishop_bands(arg, key, table):
    base = dict(dilation_cm=0, effacement_percent=0, station=-3, consistency="firm", position="posterior")
    for value, points in table:
        assert C.calculate_bishop_score(**dict(base, **{arg: value})).components[key] == points, value


def test_apgar():
    best = C.calculate_apgar(140, "strong", "active", "cry", "pink")
    assert (best.score, best.category) == (10, "reassuring")
    assert C.calculate_apgar(0, "absent", "limp", "none", "blue_pale").score == 0
    assert C.calculate_apgar(99, "strong", "active", "cry", "pink").components["heart_rate"] == 1
    assert C.calculate_apgar(100, "strong", "active", "cry", "pink").components["heart_rate"] == 2
    assert C.calculate_apgar(0, "strong", "active", "cry", "pink").components["heart_rate"] == 0
    seven = C.calculate_apgar(120, "weak", "some_flexion", "grimace", "pink")
    six = C.calculate_apgar(120, "weak", "some_flexion", "grimace", "acrocyanosis")
    four = C.calculate_apgar(90, "weak", "some_flexion", "grimace", "blue_pale")
    three = C.calculate_apgar(90, "weak", "limp", "grimace", "blue_pale")
    assert [r.score for r in (seven, six, four, three)] == [7, 6, 4, 3]
    assert [r.category for r in (seven, six, four, three)] == [
        "reassuring",
        "moderately abnormal",
        "moderately abnormal",
        "low",
    ]


def test_biophysical_profile():
    full = C.calculate_biophysical_profile(True, 3, True, 3.0, nst_reactive=True)
    assert (full.score, full.category, full.flags) == (10, "normal", ())
    oligo = C.calculate_biophysical_profile(True, 3, True, 2.0, nst_reactive=True)
    assert (oligo.score, oligo.category, oligo.flags) == (8, "normal", ("oligohydramnios",))
    assert (
        C.calculate_biophysical_profile(True, 3, True, 2.1, nst_reactive=True).components["amniotic_fluid"]
        == 2
    )
    assert (
        C.calculate_biophysical_profile(True, 2, True, 3.0, nst_reactive=True).components["body_movements"]
        == 0
    )
    six = C.calculate_biophysical_profile(False, 2, True, 3.0, nst_reactive=True)
    assert (six.score, six.category) == (6, "equivocal")
    four = C.calculate_biophysical_profile(False, 2, False, 3.0, nst_reactive=True)
    assert (four.score, four.category) == (4, "abnormal")
    us_only = C.calculate_biophysical_profile(True, 5, True, 4.0)
    assert (us_only.score, us_only.category) == (8, "normal") and "/8" in us_only.interpretation
    assert C.calculate_biophysical_profile(False, 5, True, 4.0).category == "incomplete"


# ----------------------------------------------------------------------------- questionnaires


@pytest.mark.parametrize(
    "total,cat",
    [
        (0, "minimal"),
        (4, "minimal"),
        (5, "mild"),
        (9, "mild"),
        (10, "moderate"),
        (14, "moderate"),
        (15, "moderately severe"),
        (19, "moderately severe"),
        (20, "severe"),
        (27, "severe"),
    ],
)
def test_phq9_bands(total, cat):
    responses = [min(3, max(0, total - 3 * k)) for k in range(8)] + [0]
    responses[8] = total - sum(responses[:8])
    r = C.administer_phq9(responses)
    assert (r.score, r.category) == (total, cat)


def test_phq9_item9_flag():
    assert C.administer_phq9([0] * 9).flags == ()
    flagged = C.administer_phq9([0] * 8 + [1])
    assert flagged.flags and "item 9" in flagged.interpretation and flagged.category == "minimal"


@pytest.mark.parametrize(
    "total,cat",
    [
        (4, "minimal"),
        (5, "mild"),
        (9, "mild"),
        (10, "moderate"),
        (14, "moderate"),
        (15, "severe"),
        (21, "severe"),
    ],
)
def test_gad7_bands(total, cat):
    responses = [min(3, max(0, total - 3 * k)) for k in range(7)]
    r = C.administer_gad7(responses)
    assert (r.score, r.category) == (total, cat)


@pytest.mark.parametrize(
    "total,cat",
    [
        (9, "depression unlikely"),
        (10, "possible depression"),
        (12, "possible depression"),
        (13, "probable depression"),
        (30, "probable depression"),
    ],
)
def test_epds_bands(total, cat):
    responses = [min(3, max(0, total - 3 * k)) for k in range(9)] + [0]
    responses[9] = total - sum(responses[:9])
    r = C.administer_epds(responses)
    assert (r.score, r.category) == (total, cat)
    assert bool(r.flags) == (responses[9] > 0)


def test_audit_c_and_cage():
    assert C.administer_audit_c([1, 1, 1], "male").category == "negative"  # 3 < 4
    assert C.administer_audit_c([2, 1, 1], "male").category == "positive"  # 4
    assert C.administer_audit_c([1, 1, 0], "female").category == "negative"  # 2 < 3
    assert C.administer_audit_c([1, 1, 1], "female").category == "positive"  # 3
    assert C.administer_cage(True, False, False, False).category == "negative"
    two = C.administer_cage(True, False, False, True)
    assert (two.score, two.category) == (2, "positive")


@pytest.mark.parametrize(
    "total,cat",
    [(0, "minimal"), (8, "minimal"), (9, "moderate"), (15, "moderate"), (16, "severe"), (67, "severe")],
)
def test_ciwa_ar_bands(total, cat):
    names = [
        "nausea_vomiting",
        "tremor",
        "paroxysmal_sweats",
        "anxiety",
        "agitation",
        "tactile_disturbances",
        "auditory_disturbances",
        "visual_disturbances",
        "headache",
    ]
    kw = {n: min(7, max(0, total - 7 * k)) for k, n in enumerate(names)}
    kw["orientation"] = total - sum(kw.values())
    r = C.calculate_ciwa_ar(**kw)
    assert (r.score, r.category) == (total, cat)


def test_cssrs_triage():
    none = C.assess_suicide_risk(False, False)
    assert (none.score, none.category, none.flags) == (0, "no risk identified", ())
    assert C.assess_suicide_risk(True, False).category == "low risk"
    assert C.assess_suicide_risk(True, True).category == "low risk"
    assert C.assess_suicide_risk(True, True, thoughts_with_method=True).category == "moderate risk"
    assert (
        C.assess_suicide_risk(False, False, suicidal_behavior="over_3_months_ago").category == "moderate risk"
    )
    assert C.assess_suicide_risk(True, True, intent=True).category == "high risk"
    assert C.assess_suicide_risk(True, True, thoughts_with_method=True, plan_with_intent=True).score == 3
    assert C.assess_suicide_risk(False, False, suicidal_behavior="past_3_months").category == "high risk"
    with pytest.raises(CalculatorInputError, match="'intent' must be false when suicidal_thoughts is false"):
        C.assess_suicide_risk(True, False, intent=True)
