"""Property tests against independent implementations: renal, general, obstetric,
psychiatric, emergency and neurology instruments.

For every instrument with a peer, thousands of random valid inputs are scored by us and by each
peer (``medcalc`` = medcalc-bench, ``open_medicine``, ``clincalc``; adapters in ``peers.py``) and
the scores must agree. Where a peer departs from the published definition, the strategy
restricts or special-cases the inputs and the comment says which definition we follow and why.

Input domains, batching and the agreement check are in ``peer_strategies.py``.
"""

from __future__ import annotations

import pytest
from hypothesis import given

from envs import calculators as C

from . import peers as P
from . import peers_clincalc as Q
from .peer_strategies import PEER, assert_agree, batch, choice, hundredths, ints, items, sexes, tenths


# ----------------------------------------------------------------------------- renal


@PEER
@given(batch(age=ints(18, 100), weight_kg=tenths(35, 200), creatinine_mg_dl=tenths(0.3, 8), sex=sexes))
def test_creatinine_clearance_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_creatinine_clearance, kw, P.cg_open_medicine, tol=0.051)  # rounds to 1 decimal
        assert_agree(C.calculate_creatinine_clearance, kw, Q.cg_clincalc, tol=0.051)


@PEER
@given(batch(age=ints(18, 100), weight_kg=tenths(67, 79), creatinine_mg_dl=tenths(0.3, 8), sex=sexes))
def test_creatinine_clearance_vs_medcalc(cases):
    # medcalc-bench does not use the weight it is given: it substitutes ideal or adjusted body weight
    # by BMI (min(IBW, weight) for a normal BMI). Cockcroft & Gault 1976 used actual weight, which we
    # follow. At 190 cm a weight of 67-79 kg has a normal BMI and lies below the Devine IBW for both
    # sexes, so medcalc then uses the actual weight too and the results must agree.
    for kw in cases:
        mine = C.calculate_creatinine_clearance(**kw).score
        assert P.cg_medcalc(**kw, height_cm=190.0) == pytest.approx(mine, abs=0.0051), kw


@PEER
@given(batch(creatinine_mg_dl=hundredths(0.3, 8), age=ints(18, 100), sex=sexes))
def test_ckd_epi_2021_vs_peers(cases):
    for kw in cases:
        # medcalc-bench uses kappa 0.7 instead of 0.9 for men with creatinine <= 0.9 mg/dL
        # (ckd_epi_2021_creatinine.py); Inker 2021: kappa 0.9 for men. Compare elsewhere.
        if not (kw["sex"] == "male" and kw["creatinine_mg_dl"] <= 0.9):
            assert_agree(C.calculate_ckd_epi_2021, kw, P.ckd_epi_medcalc, tol=0.0051)  # 3 decimals
        assert_agree(C.calculate_ckd_epi_2021, kw, P.ckd_epi_open_medicine, tol=0.051)  # 1 decimal
        assert_agree(C.calculate_ckd_epi_2021, kw, Q.ckd_epi_clincalc, tol=0.5)  # whole number


@PEER
@given(
    batch(
        urine_sodium_mmol_l=ints(1, 200),
        serum_sodium_mmol_l=ints(115, 160),
        urine_creatinine_mg_dl=ints(10, 300),
        serum_creatinine_mg_dl=tenths(0.4, 10),
    )
)
def test_fena_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_fena, kw, P.fena_medcalc, Q.fena_clincalc, tol=0.0051)  # both round to 2 decimals


@PEER
@given(batch(sodium_mmol_l=ints(146, 190), weight_kg=tenths(30, 150), age=ints(18, 100), sex=sexes))
def test_free_water_deficit_vs_peers(cases):
    for kw in cases:
        result = C.calculate_free_water_deficit(**kw)
        assert P.fwd_medcalc(**kw) == pytest.approx(result.score, abs=0.0051), kw  # same TBW table
        # clincalc asks the caller for the TBW fraction; give it the one we chose (Adrogue 2000).
        fraction = result.components["total_body_water_fraction"]
        assert Q.fwd_clincalc(**kw, tbw_fraction=fraction) == pytest.approx(result.score, abs=0.051), kw


# ----------------------------------------------------------------------------- general


@PEER
@given(batch(weight_kg=tenths(20, 250), height_cm=tenths(100, 220)))
def test_bmi_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_bmi, kw, P.bmi_medcalc, tol=0.0051)
        assert_agree(C.calculate_bmi, kw, P.bmi_open_medicine, Q.bmi_clincalc, tol=0.051)


@PEER
@given(batch(sodium=ints(110, 170), chloride=ints(70, 130), bicarbonate=ints(3, 45)))
def test_anion_gap_vs_peers(cases):
    for kw in cases:
        assert_agree(
            C.calculate_anion_gap,
            kw,
            P.anion_gap_medcalc,
            P.anion_gap_open_medicine,
            Q.anion_gap_clincalc,
            tol=1e-9,
        )


@PEER
@given(
    batch(sodium=ints(110, 170), chloride=ints(70, 130), bicarbonate=ints(3, 45), albumin_g_dl=tenths(1, 6))
)
def test_albumin_corrected_anion_gap_vs_open_medicine(cases):
    for kw in cases:
        mine = C.calculate_anion_gap(**kw).components["albumin_corrected_gap"]
        r = P.om_ag.calculate_anion_gap(
            P.om_ag.AnionGapParams(**{k if k != "albumin_g_dl" else "albumin": v for k, v in kw.items()})
        )
        assert f"{mine:.1f}" in r.interpretation, (kw, r.interpretation)


@PEER
@given(batch(calcium_mg_dl=tenths(4, 15), albumin_g_dl=tenths(1, 6)))
def test_corrected_calcium_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_corrected_calcium, kw, P.calcium_medcalc, tol=0.0051)
        assert_agree(C.calculate_corrected_calcium, kw, P.calcium_open_medicine, Q.calcium_clincalc, tol=0.051)


@PEER
@given(batch(sodium_mmol_l=ints(110, 170), glucose_mg_dl=ints(100, 2000)))
def test_corrected_sodium_vs_peers(cases):
    for kw in cases:
        # medcalc-bench implements Hillier (0.024 per mg/dL); open-medicine reports Katz.
        assert_agree(C.calculate_corrected_sodium, dict(kw, formula="hillier"), P.sodium_medcalc, tol=0.0051)
        assert_agree(C.calculate_corrected_sodium, dict(kw, formula="katz"), P.sodium_open_medicine, tol=0.051)
        for formula in ("katz", "hillier"):
            assert_agree(C.calculate_corrected_sodium, dict(kw, formula=formula), Q.sodium_clincalc, tol=0.051)


@PEER
@given(batch(sodium_mmol_l=ints(110, 170), glucose_mg_dl=ints(20, 1500), bun_mg_dl=ints(2, 150)))
def test_serum_osmolality_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_serum_osmolality, kw, P.osm_medcalc, tol=0.0051)
        assert_agree(C.calculate_serum_osmolality, kw, P.osm_open_medicine, tol=0.051)


# ----------------------------------------------------------------------------- obstetrics


@PEER
@given(
    batch(
        dilation_cm=ints(0, 6),
        effacement_percent=choice([0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100]),
        station=ints(-3, 2),
        consistency=choice(["firm", "medium", "soft"]),
        position=choice(["posterior", "mid", "anterior"]),
    )
)
def test_bishop_vs_open_medicine(cases):
    # open-medicine takes whole centimetres 0-6 and stations -3..+2 (Bishop 1964's range); we
    # accept any real dilation and stations -5..+5 and place values between bands in the lower one.
    for kw in cases:
        assert_agree(C.calculate_bishop_score, kw, P.bishop_open_medicine)


@PEER
@given(
    batch(
        heart_rate=ints(0, 200),
        respiratory_effort=choice(["absent", "weak", "strong"]),
        muscle_tone=choice(["limp", "some_flexion", "active"]),
        reflex_irritability=choice(["none", "grimace", "cry"]),
        color=choice(["blue_pale", "acrocyanosis", "pink"]),
    )
)
def test_apgar_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_apgar, kw, P.apgar_open_medicine, Q.apgar_clincalc)


# ----------------------------------------------------------------------------- psychiatry


@PEER
@given(batch(responses=items(9, 0, 3)))
def test_phq9_vs_peers(cases):
    for kw in cases:
        assert_agree(C.administer_phq9, kw, P.phq9_open_medicine, Q.phq9_clincalc)


@PEER
@given(batch(responses=items(7, 0, 3)))
def test_gad7_vs_peers(cases):
    for kw in cases:
        assert_agree(C.administer_gad7, kw, P.gad7_open_medicine, Q.gad7_clincalc)


@PEER
@given(batch(responses=items(10, 0, 3)))
def test_epds_vs_peers(cases):
    for kw in cases:
        assert_agree(C.administer_epds, kw, P.epds_open_medicine, Q.epds_clincalc)


@PEER
@given(batch(responses=items(3, 0, 4), sex=sexes))
def test_audit_c_vs_peers(cases):
    for kw in cases:
        result = assert_agree(C.administer_audit_c, kw, P.audit_c_open_medicine, Q.audit_c_clincalc)
        positive = clincalc_positive = Q.clincalc.calculate("auditc", kw)["working"]["screen_positive"]
        assert (C.administer_audit_c(**kw).category == "positive") == positive, (
            kw,
            result,
            clincalc_positive,
        )


@PEER
@given(batch(bools=("cut_down", "annoyed", "guilty", "eye_opener")))
def test_cage_vs_open_medicine(cases):
    for kw in cases:
        assert_agree(C.administer_cage, kw, P.cage_open_medicine)


ciwa_items = dict(
    nausea_vomiting=ints(0, 7),
    tremor=ints(0, 7),
    paroxysmal_sweats=ints(0, 7),
    anxiety=ints(0, 7),
    agitation=ints(0, 7),
    tactile_disturbances=ints(0, 7),
    auditory_disturbances=ints(0, 7),
    visual_disturbances=ints(0, 7),
    headache=ints(0, 7),
    orientation=ints(0, 4),
)


@PEER
@given(batch(**ciwa_items))
def test_ciwa_ar_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_ciwa_ar, kw, P.ciwa_open_medicine, Q.ciwa_clincalc)


# ----------------------------------------------------------------------------- emergency / neurology


@PEER
@given(
    batch(
        bools=(
            "tonsillar_exudate_or_swelling",
            "tender_anterior_cervical_nodes",
            "cough_absent",
        ),
        age=ints(3, 100),
        temperature_c=tenths(36, 40.5),
    )
)
def test_centor_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_centor, kw, P.centor_medcalc, P.centor_open_medicine, Q.centor_clincalc)


@PEER
@given(batch(gcs=ints(3, 15), systolic_bp=ints(0, 220), respiratory_rate=ints(0, 60)))
def test_revised_trauma_score_vs_open_medicine(cases):
    for kw in cases:
        assert_agree(C.calculate_revised_trauma_score, kw, P.rts_open_medicine, tol=0.00051)  # 4 decimals


@PEER
@given(batch(weight_kg=tenths(3, 200), tbsa_percent=ints(1, 100)))
def test_parkland_vs_open_medicine(cases):
    for kw in cases:
        assert_agree(C.calculate_parkland, kw, P.parkland_open_medicine, tol=0.51)  # whole mL


@PEER
@given(
    batch(
        bools=(
            "migration_to_rlq",
            "anorexia",
            "nausea_vomiting",
            "rlq_tenderness",
            "rebound_tenderness",
        ),
        temperature_c=tenths(36, 40),
        wbc_k_per_ul=tenths(3, 25),
        neutrophil_percent=ints(40, 95),
    )
)
def test_alvarado_vs_clincalc(cases):
    for kw in cases:
        assert_agree(C.calculate_alvarado, kw, Q.alvarado_clincalc)


@PEER
@given(
    batch(
        bools=(
            "malleolar_pain",
            "midfoot_pain",
            "lateral_malleolus_tenderness",
            "medial_malleolus_tenderness",
            "fifth_metatarsal_base_tenderness",
            "navicular_tenderness",
            "unable_to_bear_weight",
        )
    )
)
def test_ottawa_ankle_vs_open_medicine(cases):
    for kw in cases:
        ours = C.calculate_ottawa_ankle(**kw)
        theirs = P.ottawa_open_medicine(**kw)
        assert theirs == ours.score or bool(theirs) == bool(ours.score), (kw, theirs, ours.category)


nihss_items = {
    name: ints(0, hi)
    for name, hi in (
        ("loc", 3),
        ("loc_questions", 2),
        ("loc_commands", 2),
        ("best_gaze", 2),
        ("visual_fields", 3),
        ("facial_palsy", 3),
        ("motor_arm_left", 4),
        ("motor_arm_right", 4),
        ("motor_leg_left", 4),
        ("motor_leg_right", 4),
        ("limb_ataxia", 2),
        ("sensory", 2),
        ("best_language", 3),
        ("dysarthria", 2),
        ("extinction_inattention", 2),
    )
}


@PEER
@given(batch(**nihss_items))
def test_nihss_vs_peers(cases):
    for kw in cases:
        if kw["loc"] == 3:
            # NIHSS instructions for a coma patient (1a = 3), enforced by us and by clincalc: 1b, 1c and 8
            # score 2, 9 scores 3.
            kw.update(loc_questions=2, loc_commands=2, sensory=2, best_language=3)
        assert_agree(C.calculate_nihss, kw, P.nihss_open_medicine)
        # clincalc adds consistency rules we do not impose: in coma, dysarthria 2 and motor >= 3; ataxia
        # only in limbs that can move (motor < 4). Compare where neither applies.
        limbs = ("motor_arm_left", "motor_arm_right", "motor_leg_left", "motor_leg_right")
        if kw["loc"] < 3 and all(kw[limb] < 4 for limb in limbs):
            assert_agree(C.calculate_nihss, kw, Q.nihss_clincalc)


@PEER
@given(
    batch(
        bools=("diabetes",),
        age=ints(18, 100),
        systolic_bp=ints(80, 220),
        diastolic_bp=ints(40, 130),
        clinical_features=choice(["unilateral_weakness", "speech_disturbance", "other"]),
        duration_minutes=ints(0, 300),
    )
)
def test_abcd2_vs_peers(cases):
    for kw in cases:
        assert_agree(C.calculate_abcd2, kw, P.abcd2_open_medicine, Q.abcd2_clincalc)
