"""Property tests: our calculators against independent open-source implementations.

For every instrument with a peer, thousands of random valid inputs are scored by us and by each
peer (``medcalc`` = medcalc-bench, ``open_medicine``, ``clincalc``; adapters in ``peers.py``) and
the scores must agree. Where a peer departs from the published definition, the strategy
restricts or special-cases the inputs and the comment says which definition we follow and why.

Speed: hypothesis costs about 1 ms per example and tens of microseconds per drawn value, so each
example is a batch of ``BATCH`` inputs and each input is one drawn integer decoded into all its
fields (see :func:`batch`): ``EXAMPLES x BATCH`` = 2,000 inputs per instrument, and shrinking
still reduces a failing batch to its simplest failing input.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from envs import calculators as C

from . import peers as P
from . import peers_clincalc as Q

BATCH, EXAMPLES = 40, 50
PEER = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.data_too_large])

class Domain:
    """A finite set of input values, indexed 0..size-1 (index 0 is what shrinking goes to)."""

    def __init__(self, size: int, decode):
        self.size, self.decode = size, decode


def ints(lo: int, hi: int) -> Domain:
    return Domain(hi - lo + 1, lambda k: lo + k)


def tenths(lo: float, hi: float) -> Domain:
    """Numbers with one decimal (as charted) in lo..hi."""
    a, z = round(lo * 10), round(hi * 10)
    return Domain(z - a + 1, lambda k: (a + k) / 10)


def hundredths(lo: float, hi: float) -> Domain:
    a, z = round(lo * 100), round(hi * 100)
    return Domain(z - a + 1, lambda k: (a + k) / 100)


def choice(values) -> Domain:
    values = list(values)
    return Domain(len(values), values.__getitem__)


def opt(dom: Domain) -> Domain:
    """None (not measured) or a value of ``dom``."""
    return Domain(dom.size + 1, lambda k: None if k == 0 else dom.decode(k - 1))


def items(n: int, lo: int, hi: int) -> Domain:
    """A questionnaire: ``n`` answers in lo..hi."""
    base = hi - lo + 1
    return Domain(base ** n, lambda k: [lo + (k // base ** i) % base for i in range(n)])


b = choice([False, True])
sexes = choice(["male", "female"])


def batch(bools: tuple[str, ...] = (), **fields: Domain):
    """A hypothesis strategy for a batch of keyword-argument dicts.

    Each case is one integer drawn by hypothesis and decoded in mixed radix into the fields
    (one draw per case instead of one per field: generation, not the calculators, was the cost).
    Shrinking an integer towards 0 moves every field towards the first value of its domain.
    """
    fields = dict(fields, **{name: b for name in bools})
    names = list(fields)
    sizes = [fields[n].size for n in names]
    total = 1
    for size in sizes:
        total *= size

    def decode(code: int) -> dict:
        out = {}
        for name, size in zip(names, sizes):
            code, k = divmod(code, size)
            out[name] = fields[name].decode(k)
        return out

    return st.lists(st.integers(0, total - 1).map(decode), min_size=BATCH, max_size=BATCH)


def agree(ours, kw: dict, *peer_fns, tol: float = 0.0):
    mine = ours(**kw).score
    for peer in peer_fns:
        theirs = peer(**kw)
        assert theirs == pytest.approx(mine, abs=tol), f"{peer.__name__} gave {theirs}, we gave {mine} for {kw}"
    return mine


# ----------------------------------------------------------------------------- critical care


@PEER
@given(batch(eye=ints(1, 4), verbal=ints(1, 5), motor=ints(1, 6)))
def test_gcs_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_gcs, kw, P.gcs_medcalc, P.gcs_open_medicine, Q.gcs_clincalc)


@PEER
@given(batch(bools=('altered_mentation',), respiratory_rate=ints(0, 60), systolic_bp=ints(40, 250)))
def test_qsofa_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_qsofa, kw, P.qsofa_open_medicine, Q.qsofa_clincalc)


@PEER
@given(batch(temperature_c=tenths(33, 42), heart_rate=ints(91, 200), respiratory_rate=ints(4, 50),
             wbc_k_per_ul=tenths(0.5, 40), paco2_mmhg=opt(ints(15, 80))))
def test_sirs_vs_medcalc(cases):
    # Heart rate is drawn > 90 only: medcalc-bench 1.7.0 also adds the heart-rate point in its
    # "<= 90" branch (sirs_criteria.py), contradicting Bone 1992 (HR > 90); we follow Bone 1992.
    for kw in cases:
        agree(C.calculate_sirs, kw, P.sirs_medcalc)


@PEER
@given(batch(bools=('on_supplemental_oxygen',), respiratory_rate=ints(4, 45), spo2=ints(75, 100),
             temperature_c=tenths(33, 41.5), systolic_bp=ints(60, 250), heart_rate=ints(30, 180),
             consciousness=choice(["alert", "new_confusion", "voice", "pain", "unresponsive"]),
             spo2_scale=choice([1, 2])))
def test_news2_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_news2, kw, P.news2_open_medicine, Q.news2_clincalc)


@PEER
@given(batch(bools=('on_mechanical_ventilation',), pao2_fio2_ratio=ints(40, 600), platelets_k_per_ul=ints(5, 400),
             bilirubin_mg_dl=tenths(0.2, 20), map_mmhg=ints(40, 110), gcs=ints(3, 15),
             creatinine_mg_dl=tenths(0.3, 8), dopamine_mcg_kg_min=choice([0.0, 3.0, 5.0, 8.0, 15.0, 20.0]),
             dobutamine_mcg_kg_min=choice([0.0, 0.0, 5.0]),
             epinephrine_mcg_kg_min=choice([0.0, 0.0, 0.05, 0.1, 0.2]),
             norepinephrine_mcg_kg_min=choice([0.0, 0.0, 0.05, 0.1, 0.3])))
def test_sofa_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_sofa, kw, Q.sofa_clincalc)
        # open-medicine has no ventilation input (it scores the respiratory rows 3-4 from the ratio
        # alone, while Vincent 1996 requires respiratory support) and no dobutamine input (any
        # dobutamine scores 2): compare only where neither can matter.
        if (kw["on_mechanical_ventilation"] or kw["pao2_fio2_ratio"] >= 200) and kw["dobutamine_mcg_kg_min"] == 0:
            agree(C.calculate_sofa, kw, P.sofa_open_medicine)


@PEER
@given(batch(bools=('acute_renal_failure', 'severe_organ_insufficiency_or_immunocompromised',), temperature_c=tenths(28, 42.5), map_mmhg=ints(35, 180), heart_rate=ints(30, 200),
             respiratory_rate=ints(3, 55), fio2=choice([0.21, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0]),
             pao2_mmhg=ints(40, 400), paco2_mmhg=ints(20, 80), arterial_ph=hundredths(7.0, 7.8),
             sodium_mmol_l=ints(105, 185), potassium_mmol_l=tenths(2.0, 7.5), creatinine_mg_dl=tenths(0.3, 5), hematocrit_percent=tenths(15, 65), wbc_k_per_ul=tenths(0.5, 45),
             gcs=ints(3, 15), age=ints(16, 95),
             admission_type=choice(["nonoperative", "emergency_postoperative", "elective_postoperative"])))
def test_apache2_vs_peers(cases):
    for kw in cases:
        aa = kw["fio2"] * 713.0 - kw["paco2_mmhg"] / 0.8 - kw["pao2_mmhg"]
        if kw["fio2"] >= 0.5 and (aa < 0 or min(abs(aa - e) for e in (200, 350, 500)) < 1e-6):
            continue  # impossible gas (negative gradient) or a float tie at a band edge
        # open-medicine computes the A-a gradient from PaCO2 as we do; clincalc takes the gradient.
        mine = agree(C.calculate_apache2, kw, P.apache2_open_medicine)
        assert Q.apache2_clincalc(**dict(kw, aa_gradient_mmhg=aa)) == mine, kw


@PEER
@given(batch(pao2_mmhg=ints(40, 600), paco2_mmhg=ints(15, 90),
             fio2=choice([0.21, 0.3, 0.4, 0.5, 1.0]), age=opt(ints(18, 95))))
def test_aa_gradient_vs_open_medicine(cases):
    for kw in cases:  # open-medicine rounds to one decimal
        agree(C.calculate_aa_gradient, kw, P.aa_gradient_open_medicine, tol=0.051)


# ----------------------------------------------------------------------------- pulmonary


@PEER
@given(batch(bools=('confusion',), bun_mg_dl=tenths(2, 60), respiratory_rate=ints(8, 45),
             systolic_bp=ints(60, 200), diastolic_bp=ints(30, 110), age=ints(18, 100)))
def test_curb65_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_curb65, kw, P.curb65_medcalc)
        # open-medicine scores BUN > 20 mg/dL (curb65.py), not > 19: BUN in (19, 20] differs.
        if not 19 < kw["bun_mg_dl"] <= 20:
            agree(C.calculate_curb65, kw, P.curb65_open_medicine)
        # clincalc scores the paper's urea > 7 mmol/L, i.e. BUN > 19.6 mg/dL; the requirement (and
        # the usual US statement) is BUN > 19 mg/dL, so BUN in (19, 19.6] is scored differently.
        if not 19 < kw["bun_mg_dl"] <= 19.6:
            agree(C.calculate_curb65, kw, Q.curb65_clincalc)


@PEER
@given(batch(bools=('confusion',), respiratory_rate=ints(8, 45), systolic_bp=ints(60, 200),
             diastolic_bp=ints(30, 110), age=ints(18, 100)))
def test_crb65_vs_open_medicine(cases):
    for kw in cases:
        agree(C.calculate_crb65, kw, P.crb65_open_medicine)


@PEER
@given(batch(bools=('clinical_signs_dvt', 'pe_most_likely', 'immobilization_or_recent_surgery', 'previous_dvt_pe', 'hemoptysis', 'malignancy',), heart_rate=ints(40, 180)))
def test_wells_pe_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_wells_pe, kw, P.wells_pe_medcalc, P.wells_pe_open_medicine, Q.wells_pe_clincalc)


@PEER
@given(batch(bools=('unilateral_leg_swelling', 'hemoptysis', 'recent_surgery_or_trauma', 'prior_pe_or_dvt', 'hormone_use',), age=ints(18, 100), heart_rate=ints(40, 180), spo2=ints(80, 100)))
def test_perc_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_perc, kw, P.perc_medcalc, P.perc_open_medicine, Q.perc_clincalc)


# ----------------------------------------------------------------------------- cardiology


@PEER
@given(batch(bools=('atherosclerotic_disease',), history=choice(["slightly", "moderately", "highly"]),
             ecg=choice(["normal", "nonspecific", "st_deviation"]), age=ints(18, 100),
             risk_factor_count=ints(0, 6),
             troponin_x_uln=tenths(0, 6)))
def test_heart_score_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_heart_score, kw, P.heart_open_medicine, Q.heart_clincalc)
        # medcalc-bench scores known atherosclerotic disease as 2 only together with >= 3 risk factors
        # (it gives 1 for atherosclerosis alone); Six 2008 gives 2 for ">= 3 risk factors or history of
        # atherosclerotic disease", which we follow.
        if not (kw["atherosclerotic_disease"] and kw["risk_factor_count"] < 3):
            agree(C.calculate_heart_score, kw, P.heart_medcalc)


@PEER
@given(batch(bools=('known_cad_stenosis_50', 'aspirin_past_7_days', 'st_deviation_05mm', 'positive_cardiac_marker',), age=ints(18, 100), cad_risk_factor_count=ints(0, 5), angina_episodes_24h=ints(0, 5)))
def test_timi_ua_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_timi_ua, kw, P.timi_open_medicine, Q.timi_clincalc)


@PEER
@given(batch(bools=('chf', 'hypertension', 'diabetes', 'stroke_tia_thromboembolism', 'vascular_disease',), age=ints(18, 100), sex=choice(["male", "female"])))
def test_cha2ds2_vasc_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_cha2ds2_vasc, kw, P.chads_medcalc, P.chads_open_medicine, Q.chads_clincalc)


@PEER
@given(batch(bools=('uncontrolled_hypertension', 'abnormal_renal_function', 'abnormal_liver_function', 'stroke_history', 'bleeding_history_or_predisposition', 'labile_inr', 'antiplatelet_or_nsaid_use', 'alcohol_use',), age=ints(18, 100)))
def test_has_bled_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_has_bled, kw, P.hasbled_medcalc, P.hasbled_open_medicine, Q.hasbled_clincalc)


@PEER
@given(batch(bools=P._DVT_KEYS))
def test_wells_dvt_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_wells_dvt, kw, P.wells_dvt_medcalc, P.wells_dvt_open_medicine, Q.wells_dvt_clincalc)


@PEER
@given(batch(qt_ms=ints(250, 600), heart_rate=ints(35, 180),
             formula=choice(["bazett", "fridericia", "framingham", "hodges"])))
def test_qtc_vs_peers(cases):
    for kw in cases:
        # medcalc-bench rounds the RR interval to 3 decimals (seconds) before correcting: <= 1 ms apart.
        agree(C.calculate_qtc, kw, P.qtc_medcalc, tol=1.0)
        if kw["formula"] in ("bazett", "fridericia"):  # open-medicine has these two only, rounded to 1 ms
            agree(C.calculate_qtc, kw, P.qtc_open_medicine, tol=0.51)


@PEER
@given(batch(systolic_bp=ints(70, 250), diastolic_bp=ints(30, 69)))
def test_map_vs_medcalc(cases):
    for kw in cases:
        agree(C.calculate_map, kw, P.map_medcalc, tol=0.0051)


# ----------------------------------------------------------------------------- hepatology / GI

meld_fields = dict(bilirubin_mg_dl=tenths(0.3, 30), inr=tenths(0.8, 5), creatinine_mg_dl=tenths(0.3, 6),
                   sodium_mmol_l=ints(115, 150), on_dialysis=b)


@PEER
@given(batch(**meld_fields))
def test_meld_na_vs_peers(cases):
    for kw in cases:
        result = C.calculate_meld_na(**kw)
        # clincalc's "meld" is MELD without sodium: it must equal our MELD(i) (same bounds, same rounding).
        if 6 <= result.components["meld_i"] <= 40:
            assert Q.meld_clincalc(**kw) == result.components["meld_i"], kw
        # medcalc-bench applies "dialysis sets creatinine to 4.0" only when creatinine is >= 1.0
        # (meldna.py checks "< 1.0" first); OPTN applies it whatever the creatinine.
        if not (kw["on_dialysis"] and kw["creatinine_mg_dl"] < 1.0):
            assert P.meld_na_medcalc(**kw) == result.score, kw
        # open-medicine is not compared: it uses Kim 2008's form "MELD - Na - 0.025 MELD (140 - Na)
        # + 140" but clamps sodium to 125-137 (meld_na.py), so a normal sodium adds 3 points (MELD(i) 6
        # with Na 140 gives 9); OPTN/UNOS 2016, which we follow, adds nothing at Na >= 137.


@PEER
@given(batch(bilirubin_mg_dl=tenths(0.3, 10), albumin_g_dl=tenths(1.5, 5), inr=tenths(0.8, 4),
             ascites=choice(["none", "mild", "moderate_severe"]),
             encephalopathy=choice(["none", "grade_1_2", "grade_3_4"])))
def test_child_pugh_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_child_pugh, kw, P.child_pugh_open_medicine, Q.child_pugh_clincalc)
        # medcalc-bench mis-scores the exact band edges: albumin 2.8 g/dL as 3 points ("<= 2.8"),
        # bilirubin 2.0 mg/dL as 0 and 3.0 as 3. Pugh 1973: bilirubin < 2 / 2-3 / > 3 and albumin
        # > 3.5 / 2.8-3.5 / < 2.8, so 2.0 and 3.0 score 2 and 2.8 scores 2 (as the other peers do).
        if kw["albumin_g_dl"] != 2.8 and kw["bilirubin_mg_dl"] not in (2.0, 3.0):
            agree(C.calculate_child_pugh, kw, P.child_pugh_medcalc)


@PEER
@given(batch(bools=('melena', 'syncope', 'hepatic_disease', 'cardiac_failure',), bun_mg_dl=tenths(5, 100), hemoglobin_g_dl=tenths(5, 17), sex=choice(["male", "female"]),
             systolic_bp=ints(60, 180), heart_rate=ints(50, 150)))
def test_glasgow_blatchford_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_glasgow_blatchford, kw, Q.gbs_clincalc)
        # medcalc-bench mis-scores exact band edges: haemoglobin 12.0 and 13.0 g/dL (men), 10.0 and
        # 12.0 (women), and BUN 70.0 mg/dL (0 instead of 6). Blatchford 2000 bands start at their
        # printed lower value (men 12.0-12.9 = 1; urea >= 25 mmol/L = 6), as clincalc agrees.
        if kw["hemoglobin_g_dl"] not in (10.0, 12.0, 13.0) and kw["bun_mg_dl"] != 70.0:
            agree(C.calculate_glasgow_blatchford, kw, P.gbs_medcalc)
        # open-medicine scores syncope, hepatic disease and cardiac failure 1 point each; Blatchford
        # 2000 gives 2 each (as the other peers do). Compare where none is present.
        if not (kw["syncope"] or kw["hepatic_disease"] or kw["cardiac_failure"]):
            agree(C.calculate_glasgow_blatchford, kw, P.gbs_open_medicine)


# ----------------------------------------------------------------------------- renal


@PEER
@given(batch(age=ints(18, 100), weight_kg=tenths(35, 200), creatinine_mg_dl=tenths(0.3, 8), sex=sexes))
def test_creatinine_clearance_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_creatinine_clearance, kw, P.cg_open_medicine, tol=0.051)  # rounds to 1 decimal
        agree(C.calculate_creatinine_clearance, kw, Q.cg_clincalc, tol=0.051)


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
            agree(C.calculate_ckd_epi_2021, kw, P.ckd_epi_medcalc, tol=0.0051)  # 3 decimals
        agree(C.calculate_ckd_epi_2021, kw, P.ckd_epi_open_medicine, tol=0.051)  # 1 decimal
        agree(C.calculate_ckd_epi_2021, kw, Q.ckd_epi_clincalc, tol=0.5)  # whole number


@PEER
@given(batch(urine_sodium_mmol_l=ints(1, 200), serum_sodium_mmol_l=ints(115, 160),
             urine_creatinine_mg_dl=ints(10, 300), serum_creatinine_mg_dl=tenths(0.4, 10)))
def test_fena_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_fena, kw, P.fena_medcalc, Q.fena_clincalc, tol=0.0051)  # both round to 2 decimals


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
        agree(C.calculate_bmi, kw, P.bmi_medcalc, tol=0.0051)
        agree(C.calculate_bmi, kw, P.bmi_open_medicine, Q.bmi_clincalc, tol=0.051)


@PEER
@given(batch(sodium=ints(110, 170), chloride=ints(70, 130), bicarbonate=ints(3, 45)))
def test_anion_gap_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_anion_gap, kw, P.anion_gap_medcalc, P.anion_gap_open_medicine, Q.anion_gap_clincalc,
              tol=1e-9)


@PEER
@given(batch(sodium=ints(110, 170), chloride=ints(70, 130), bicarbonate=ints(3, 45),
             albumin_g_dl=tenths(1, 6)))
def test_albumin_corrected_anion_gap_vs_open_medicine(cases):
    for kw in cases:
        mine = C.calculate_anion_gap(**kw).components["albumin_corrected_gap"]
        r = P.om_ag.calculate_anion_gap(P.om_ag.AnionGapParams(**{k if k != "albumin_g_dl" else "albumin": v
                                                                  for k, v in kw.items()}))
        assert f"{mine:.1f}" in r.interpretation, (kw, r.interpretation)


@PEER
@given(batch(calcium_mg_dl=tenths(4, 15), albumin_g_dl=tenths(1, 6)))
def test_corrected_calcium_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_corrected_calcium, kw, P.calcium_medcalc, tol=0.0051)
        agree(C.calculate_corrected_calcium, kw, P.calcium_open_medicine, Q.calcium_clincalc, tol=0.051)


@PEER
@given(batch(sodium_mmol_l=ints(110, 170), glucose_mg_dl=ints(100, 2000)))
def test_corrected_sodium_vs_peers(cases):
    for kw in cases:
        # medcalc-bench implements Hillier (0.024 per mg/dL); open-medicine reports Katz.
        agree(C.calculate_corrected_sodium, dict(kw, formula="hillier"), P.sodium_medcalc, tol=0.0051)
        agree(C.calculate_corrected_sodium, dict(kw, formula="katz"), P.sodium_open_medicine, tol=0.051)
        for formula in ("katz", "hillier"):
            agree(C.calculate_corrected_sodium, dict(kw, formula=formula), Q.sodium_clincalc, tol=0.051)


@PEER
@given(batch(sodium_mmol_l=ints(110, 170), glucose_mg_dl=ints(20, 1500), bun_mg_dl=ints(2, 150)))
def test_serum_osmolality_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_serum_osmolality, kw, P.osm_medcalc, tol=0.0051)
        agree(C.calculate_serum_osmolality, kw, P.osm_open_medicine, tol=0.051)


# ----------------------------------------------------------------------------- obstetrics


@PEER
@given(batch(dilation_cm=ints(0, 6), effacement_percent=choice([0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100]),
             station=ints(-3, 2), consistency=choice(["firm", "medium", "soft"]),
             position=choice(["posterior", "mid", "anterior"])))
def test_bishop_vs_open_medicine(cases):
    # open-medicine takes whole centimetres 0-6 and stations -3..+2 (Bishop 1964's range); we
    # accept any real dilation and stations -5..+5 and place values between bands in the lower one.
    for kw in cases:
        agree(C.calculate_bishop_score, kw, P.bishop_open_medicine)


@PEER
@given(batch(heart_rate=ints(0, 200), respiratory_effort=choice(["absent", "weak", "strong"]),
             muscle_tone=choice(["limp", "some_flexion", "active"]),
             reflex_irritability=choice(["none", "grimace", "cry"]),
             color=choice(["blue_pale", "acrocyanosis", "pink"])))
def test_apgar_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_apgar, kw, P.apgar_open_medicine, Q.apgar_clincalc)


# ----------------------------------------------------------------------------- psychiatry



@PEER
@given(batch(responses=items(9, 0, 3)))
def test_phq9_vs_peers(cases):
    for kw in cases:
        agree(C.administer_phq9, kw, P.phq9_open_medicine, Q.phq9_clincalc)


@PEER
@given(batch(responses=items(7, 0, 3)))
def test_gad7_vs_peers(cases):
    for kw in cases:
        agree(C.administer_gad7, kw, P.gad7_open_medicine, Q.gad7_clincalc)


@PEER
@given(batch(responses=items(10, 0, 3)))
def test_epds_vs_peers(cases):
    for kw in cases:
        agree(C.administer_epds, kw, P.epds_open_medicine, Q.epds_clincalc)


@PEER
@given(batch(responses=items(3, 0, 4), sex=sexes))
def test_audit_c_vs_peers(cases):
    for kw in cases:
        result = agree(C.administer_audit_c, kw, P.audit_c_open_medicine, Q.audit_c_clincalc)
        positive = clincalc_positive = Q.clincalc.calculate("auditc", kw)["working"]["screen_positive"]
        assert (C.administer_audit_c(**kw).category == "positive") == positive, (kw, result, clincalc_positive)


@PEER
@given(batch(bools=('cut_down', 'annoyed', 'guilty', 'eye_opener')))
def test_cage_vs_open_medicine(cases):
    for kw in cases:
        agree(C.administer_cage, kw, P.cage_open_medicine)


ciwa_items = dict(nausea_vomiting=ints(0, 7), tremor=ints(0, 7), paroxysmal_sweats=ints(0, 7),
                  anxiety=ints(0, 7), agitation=ints(0, 7), tactile_disturbances=ints(0, 7),
                  auditory_disturbances=ints(0, 7), visual_disturbances=ints(0, 7),
                  headache=ints(0, 7), orientation=ints(0, 4))


@PEER
@given(batch(**ciwa_items))
def test_ciwa_ar_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_ciwa_ar, kw, P.ciwa_open_medicine, Q.ciwa_clincalc)


# ----------------------------------------------------------------------------- emergency / neurology


@PEER
@given(batch(bools=('tonsillar_exudate_or_swelling', 'tender_anterior_cervical_nodes', 'cough_absent',), age=ints(3, 100),
             temperature_c=tenths(36, 40.5)))
def test_centor_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_centor, kw, P.centor_medcalc, P.centor_open_medicine, Q.centor_clincalc)


@PEER
@given(batch(gcs=ints(3, 15), systolic_bp=ints(0, 220), respiratory_rate=ints(0, 60)))
def test_revised_trauma_score_vs_open_medicine(cases):
    for kw in cases:
        agree(C.calculate_revised_trauma_score, kw, P.rts_open_medicine, tol=0.00051)  # 4 decimals


@PEER
@given(batch(weight_kg=tenths(3, 200), tbsa_percent=ints(1, 100)))
def test_parkland_vs_open_medicine(cases):
    for kw in cases:
        agree(C.calculate_parkland, kw, P.parkland_open_medicine, tol=0.51)  # whole mL


@PEER
@given(batch(bools=('migration_to_rlq', 'anorexia', 'nausea_vomiting', 'rlq_tenderness', 'rebound_tenderness',), temperature_c=tenths(36, 40), wbc_k_per_ul=tenths(3, 25), neutrophil_percent=ints(40, 95)))
def test_alvarado_vs_clincalc(cases):
    for kw in cases:
        agree(C.calculate_alvarado, kw, Q.alvarado_clincalc)


@PEER
@given(batch(bools=('malleolar_pain', 'midfoot_pain', 'lateral_malleolus_tenderness', 'medial_malleolus_tenderness', 'fifth_metatarsal_base_tenderness', 'navicular_tenderness', 'unable_to_bear_weight')))
def test_ottawa_ankle_vs_open_medicine(cases):
    for kw in cases:
        ours = C.calculate_ottawa_ankle(**kw)
        theirs = P.ottawa_open_medicine(**kw)
        assert theirs == ours.score or bool(theirs) == bool(ours.score), (kw, theirs, ours.category)


nihss_items = {name: ints(0, hi) for name, hi in
               (("loc", 3), ("loc_questions", 2), ("loc_commands", 2), ("best_gaze", 2), ("visual_fields", 3),
                ("facial_palsy", 3), ("motor_arm_left", 4), ("motor_arm_right", 4), ("motor_leg_left", 4),
                ("motor_leg_right", 4), ("limb_ataxia", 2), ("sensory", 2), ("best_language", 3),
                ("dysarthria", 2), ("extinction_inattention", 2))}


@PEER
@given(batch(**nihss_items))
def test_nihss_vs_peers(cases):
    for kw in cases:
        if kw["loc"] == 3:
            # NIHSS instructions for a coma patient (1a = 3), enforced by us and by clincalc: 1b, 1c and 8
            # score 2, 9 scores 3.
            kw.update(loc_questions=2, loc_commands=2, sensory=2, best_language=3)
        agree(C.calculate_nihss, kw, P.nihss_open_medicine)
        # clincalc adds consistency rules we do not impose: in coma, dysarthria 2 and motor >= 3; ataxia
        # only in limbs that can move (motor < 4). Compare where neither applies.
        limbs = ("motor_arm_left", "motor_arm_right", "motor_leg_left", "motor_leg_right")
        if kw["loc"] < 3 and all(kw[limb] < 4 for limb in limbs):
            agree(C.calculate_nihss, kw, Q.nihss_clincalc)


@PEER
@given(batch(bools=('diabetes',), age=ints(18, 100), systolic_bp=ints(80, 220), diastolic_bp=ints(40, 130),
             clinical_features=choice(["unilateral_weakness", "speech_disturbance", "other"]),
             duration_minutes=ints(0, 300)))
def test_abcd2_vs_peers(cases):
    for kw in cases:
        agree(C.calculate_abcd2, kw, P.abcd2_open_medicine, Q.abcd2_clincalc)
