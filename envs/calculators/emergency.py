"""Emergency-medicine instruments: ESI v4 triage, Centor/McIsaac, Revised Trauma Score,
Parkland burn formula, Alvarado score and the Ottawa ankle rules.

ESI v4 danger-zone vitals by age (Gilboy et al., ESI Implementation Handbook v4):
< 3 months HR > 180 or RR > 50; 3 months-3 years HR > 160 or RR > 40; 3-8 years HR > 140 or
RR > 30; > 8 years HR > 100 or RR > 20; any age SpO2 < 92 %. At decision point D the handbook
says the nurse "considers" up-triage to ESI 2; a deterministic tool must decide, so by default
danger-zone vitals up-triage to ESI 2 (``uptriage_danger_zone=False`` keeps ESI 3 and reports
the vitals in ``flags``).
"""

from __future__ import annotations

from ._core import (
    ScoreResult,
    check_bool,
    check_int,
    check_number,
    check_optional_number,
    make_result,
)


def _danger_zone(age_years: float, hr: float | None, rr: float | None, spo2: float | None) -> list[str]:
    if age_years < 0.25:
        hr_max, rr_max = 180, 50
    elif age_years < 3:
        hr_max, rr_max = 160, 40
    elif age_years <= 8:
        hr_max, rr_max = 140, 30
    else:
        hr_max, rr_max = 100, 20
    out = []
    if hr is not None and hr > hr_max:
        out.append(f"heart rate > {hr_max}")
    if rr is not None and rr > rr_max:
        out.append(f"respiratory rate > {rr_max}")
    if spo2 is not None and spo2 < 92:
        out.append("SpO2 < 92%")
    return out


def calculate_esi_level(
    requires_immediate_lifesaving_intervention: bool,
    high_risk_situation: bool,
    confused_lethargic_or_disoriented: bool,
    severe_pain_or_distress: bool,
    expected_resources: int,
    age_years: float,
    heart_rate: float | None = None,
    respiratory_rate: float | None = None,
    spo2: float | None = None,
    uptriage_danger_zone: bool = True,
) -> ScoreResult:
    """Emergency Severity Index (ESI v4) five-level triage acuity, 1 (most urgent) to 5.

    Args:
        requires_immediate_lifesaving_intervention: Decision A: needs an immediate airway, emergency
            medication or haemodynamic intervention (ESI 1).
        high_risk_situation: Decision B: a high-risk situation that should not wait (ESI 2).
        confused_lethargic_or_disoriented: Decision B: new confusion, lethargy or disorientation (ESI 2).
        severe_pain_or_distress: Decision B: severe pain or distress (pain >= 7/10) (ESI 2).
        expected_resources: Decision C: number of different resources expected (labs, imaging, IV
            fluids, IV/IM medication, specialty consult, simple or complex procedure), integer 0-10.
        age_years: Age in years, 0-120 (sets the danger-zone vital-sign limits).
        heart_rate: Heart rate in beats/min, 0-350 (optional; decision D).
        respiratory_rate: Respiratory rate in breaths/min, 0-150 (optional; decision D).
        spo2: Oxygen saturation in percent, 0-100 (optional; decision D, < 92 is danger zone).
        uptriage_danger_zone: If True (default), danger-zone vitals in a 2+-resource patient give ESI 2.
    """
    fn = "calculate_esi_level"
    a = check_bool(
        fn, "requires_immediate_lifesaving_intervention", requires_immediate_lifesaving_intervention
    )
    hr_sit = check_bool(fn, "high_risk_situation", high_risk_situation)
    conf = check_bool(fn, "confused_lethargic_or_disoriented", confused_lethargic_or_disoriented)
    pain = check_bool(fn, "severe_pain_or_distress", severe_pain_or_distress)
    res = check_int(fn, "expected_resources", expected_resources, 0, 10)
    age = check_number(fn, "age_years", age_years, 0, 120, "years")
    hr = check_optional_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    rr = check_optional_number(fn, "respiratory_rate", respiratory_rate, 0, 150, "breaths/min")
    sat = check_optional_number(fn, "spo2", spo2, 0, 100, "%")
    up = check_bool(fn, "uptriage_danger_zone", uptriage_danger_zone)
    danger = _danger_zone(age, hr, rr, sat)
    flags: tuple[str, ...] = ()
    if a:
        level, why = 1, "requires immediate life-saving intervention"
    elif hr_sit or conf or pain:
        reasons = [
            r
            for r, v in (
                ("high-risk situation", hr_sit),
                ("new confusion/lethargy/disorientation", conf),
                ("severe pain or distress", pain),
            )
            if v
        ]
        level, why = 2, ", ".join(reasons)
    elif res >= 2:
        if danger and up:
            level, why = 2, "two or more resources with danger-zone vitals (" + ", ".join(danger) + ")"
        else:
            level, why = 3, "two or more resources expected"
            if danger:
                flags = tuple("danger-zone vital: " + d for d in danger)
    elif res == 1:
        level, why = 4, "one resource expected"
    else:
        level, why = 5, "no resources expected"
    comps = {
        "decision_a_lifesaving": a,
        "decision_b_high_risk": hr_sit or conf or pain,
        "expected_resources": res,
        "danger_zone_vitals": bool(danger),
    }
    return make_result(
        "Emergency Severity Index v4",
        level,
        "level",
        f"ESI {level}",
        f"ESI {level}: {why}.",
        comps,
        "Gilboy N, Tanabe P, Travers D, Rosenau AM. Emergency Severity Index (ESI): a triage tool for "
        "emergency department care, version 4. Implementation Handbook 2012 edition. AHRQ Publication "
        "12-0014.",
        flags,
    )


def calculate_centor(
    age: int,
    tonsillar_exudate_or_swelling: bool,
    tender_anterior_cervical_nodes: bool,
    temperature_c: float,
    cough_absent: bool,
) -> ScoreResult:
    """Modified Centor (McIsaac) score (-1 to 5) for group A streptococcal pharyngitis.

    Args:
        age: Age in years, integer 3-120 (3-14: +1, 15-44: 0, >= 45: -1).
        tonsillar_exudate_or_swelling: True for tonsillar exudate or swelling.
        tender_anterior_cervical_nodes: True for tender or swollen anterior cervical nodes.
        temperature_c: Highest temperature in degrees C, 30-45 (> 38 scores 1).
        cough_absent: True if there is no cough.
    """
    fn = "calculate_centor"
    a = check_int(fn, "age", age, 3, 120, "years")
    t = check_number(fn, "temperature_c", temperature_c, 30, 45, "degrees C")
    comps = {
        "tonsillar_exudate_or_swelling": int(
            check_bool(fn, "tonsillar_exudate_or_swelling", tonsillar_exudate_or_swelling)
        ),
        "tender_anterior_cervical_nodes": int(
            check_bool(fn, "tender_anterior_cervical_nodes", tender_anterior_cervical_nodes)
        ),
        "temperature_gt_38": int(t > 38),
        "cough_absent": int(check_bool(fn, "cough_absent", cough_absent)),
        "age": 1 if a <= 14 else 0 if a <= 44 else -1,
    }
    total = sum(comps.values())
    if total <= 1:
        cat, text = "low risk", "streptococcal infection 1-10%: no testing or antibiotics"
    elif total <= 3:
        cat, text = (
            "intermediate risk",
            "streptococcal infection 11-35%: rapid antigen test or culture, treat if positive",
        )
    else:
        cat, text = (
            "high risk",
            "streptococcal infection 51-53%: test (or treat empirically per local guidance)",
        )
    return make_result(
        "Centor score (McIsaac)",
        total,
        "points",
        cat,
        f"McIsaac {total} ({cat}): {text}.",
        comps,
        "Centor RM et al. Med Decis Making 1981;1:239-246; McIsaac WJ et al. A clinical score to reduce "
        "unnecessary antibiotic use in patients with sore throat. CMAJ 1998;158:75-83; McIsaac WJ et al. "
        "JAMA 2004;291:1587-1595.",
    )


def calculate_revised_trauma_score(gcs: int, systolic_bp: float, respiratory_rate: float) -> ScoreResult:
    """Revised Trauma Score (weighted RTS, 0-7.8408) with the coded triage values.

    Args:
        gcs: Glasgow Coma Scale total, integer 3-15.
        systolic_bp: Systolic blood pressure in mmHg, 0-350.
        respiratory_rate: Respiratory rate in breaths/min, 0-100.
    """
    fn = "calculate_revised_trauma_score"
    g = check_int(fn, "gcs", gcs, 3, 15)
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    gcs_code = 4 if g >= 13 else 3 if g >= 9 else 2 if g >= 6 else 1 if g >= 4 else 0
    sbp_code = 4 if sbp > 89 else 3 if sbp >= 76 else 2 if sbp >= 50 else 1 if sbp > 0 else 0
    if rr > 29:
        rr_code = 3
    elif rr >= 10:
        rr_code = 4
    elif rr >= 6:
        rr_code = 2
    elif rr > 0:
        rr_code = 1
    else:
        rr_code = 0
    rts = 0.9368 * gcs_code + 0.7326 * sbp_code + 0.2908 * rr_code
    t_rts = gcs_code + sbp_code + rr_code
    if t_rts < 12:
        cat, text = "trauma center", "triage RTS < 12: transfer to a trauma centre"
    else:
        cat, text = "no triage criterion", "triage RTS 12 (normal physiology)"
    return make_result(
        "Revised Trauma Score",
        rts,
        "points",
        cat,
        f"RTS {rts:.4f} (coded {t_rts}/12): {text}.",
        {
            "gcs_code": gcs_code,
            "systolic_bp_code": sbp_code,
            "respiratory_rate_code": rr_code,
            "triage_rts": t_rts,
        },
        "Champion HR et al. A revision of the Trauma Score. J Trauma 1989;29:623-629.",
    )


def calculate_parkland(weight_kg: float, tbsa_percent: float) -> ScoreResult:
    """Parkland formula: 24-hour crystalloid volume (mL) = 4 mL x kg x %TBSA burned.

    Args:
        weight_kg: Body weight in kg, 1-350.
        tbsa_percent: Total body surface area with partial- or full-thickness burns in percent, 0-100.
    """
    fn = "calculate_parkland"
    w = check_number(fn, "weight_kg", weight_kg, 1, 350, "kg")
    tbsa = check_number(fn, "tbsa_percent", tbsa_percent, 0, 100, "%")
    total = 4.0 * w * tbsa
    first8 = total / 2.0
    if tbsa >= 20:
        cat = "formal resuscitation"
        text = "TBSA >= 20%: formal fluid resuscitation indicated; titrate to urine output 0.5 mL/kg/h"
    else:
        cat = "below resuscitation threshold"
        text = "TBSA < 20%: formal burn resuscitation usually not required in adults"
    return make_result(
        "Parkland formula",
        total,
        "mL/24 h",
        cat,
        f"Parkland {total:.0f} mL lactated Ringer's over 24 h from the time of burn ({first8:.0f} mL in "
        "the first "
        f"8 h, {first8:.0f} mL over the next 16 h); {text}.",
        {
            "first_8h_ml": first8,
            "next_16h_ml": first8,
            "first_8h_rate_ml_h": first8 / 8.0,
            "next_16h_rate_ml_h": first8 / 16.0,
        },
        "Baxter CR, Shires T. Physiological response to crystalloid resuscitation of severe burns. Ann N Y "
        "Acad Sci 1968;150:874-894.",
    )


def calculate_alvarado(
    migration_to_rlq: bool,
    anorexia: bool,
    nausea_vomiting: bool,
    rlq_tenderness: bool,
    rebound_tenderness: bool,
    temperature_c: float,
    wbc_k_per_ul: float,
    neutrophil_percent: float,
) -> ScoreResult:
    """Alvarado (MANTRELS) score (0-10) for acute appendicitis.

    Args:
        migration_to_rlq: True for migration of pain to the right lower quadrant (1).
        anorexia: True for anorexia (1).
        nausea_vomiting: True for nausea or vomiting (1).
        rlq_tenderness: True for right-lower-quadrant tenderness (2).
        rebound_tenderness: True for rebound pain (1).
        temperature_c: Temperature in degrees C, 30-45 (>= 37.3 scores 1).
        wbc_k_per_ul: White cell count in 10^3/uL, 0-500 (> 10 scores 2).
        neutrophil_percent: Neutrophils in percent of white cells, 0-100 (> 75, left shift, scores 1).
    """
    fn = "calculate_alvarado"
    t = check_number(fn, "temperature_c", temperature_c, 30, 45, "degrees C")
    wbc = check_number(fn, "wbc_k_per_ul", wbc_k_per_ul, 0, 500, "x10^3/uL")
    neut = check_number(fn, "neutrophil_percent", neutrophil_percent, 0, 100, "%")
    comps = {
        "migration_to_rlq": int(check_bool(fn, "migration_to_rlq", migration_to_rlq)),
        "anorexia": int(check_bool(fn, "anorexia", anorexia)),
        "nausea_vomiting": int(check_bool(fn, "nausea_vomiting", nausea_vomiting)),
        "rlq_tenderness": 2 * check_bool(fn, "rlq_tenderness", rlq_tenderness),
        "rebound_tenderness": int(check_bool(fn, "rebound_tenderness", rebound_tenderness)),
        "elevated_temperature": int(t >= 37.3),
        "leukocytosis": 2 * (wbc > 10),
        "left_shift": int(neut > 75),
    }
    total = sum(comps.values())
    if total >= 9:
        cat = "very probable"
    elif total >= 7:
        cat = "probable"
    elif total >= 5:
        cat = "compatible"
    else:
        cat = "unlikely"
    return make_result(
        "Alvarado score",
        total,
        "points",
        cat,
        f"Alvarado {total}/10: appendicitis {cat}.",
        comps,
        "Alvarado A. A practical score for the early diagnosis of acute appendicitis. Ann Emerg Med "
        "1986;15:557-564.",
    )


def calculate_ottawa_ankle(
    malleolar_pain: bool,
    midfoot_pain: bool,
    lateral_malleolus_tenderness: bool,
    medial_malleolus_tenderness: bool,
    fifth_metatarsal_base_tenderness: bool,
    navicular_tenderness: bool,
    unable_to_bear_weight: bool,
) -> ScoreResult:
    """Ottawa ankle and foot rules: which radiographs an acute ankle injury needs (0-2 series).

    Args:
        malleolar_pain: True for pain in the malleolar zone.
        midfoot_pain: True for pain in the midfoot zone.
        lateral_malleolus_tenderness: True for bone tenderness at the posterior edge or tip of the
            lateral malleolus (distal 6 cm).
        medial_malleolus_tenderness: True for bone tenderness at the posterior edge or tip of the
            medial malleolus (distal 6 cm).
        fifth_metatarsal_base_tenderness: True for bone tenderness at the base of the fifth metatarsal.
        navicular_tenderness: True for bone tenderness at the navicular.
        unable_to_bear_weight: True if unable to bear weight (four steps) both immediately and in the ED.
    """
    fn = "calculate_ottawa_ankle"
    mp = check_bool(fn, "malleolar_pain", malleolar_pain)
    fp = check_bool(fn, "midfoot_pain", midfoot_pain)
    lat = check_bool(fn, "lateral_malleolus_tenderness", lateral_malleolus_tenderness)
    med = check_bool(fn, "medial_malleolus_tenderness", medial_malleolus_tenderness)
    mt5 = check_bool(fn, "fifth_metatarsal_base_tenderness", fifth_metatarsal_base_tenderness)
    nav = check_bool(fn, "navicular_tenderness", navicular_tenderness)
    nwb = check_bool(fn, "unable_to_bear_weight", unable_to_bear_weight)
    ankle = mp and (lat or med or nwb)
    foot = fp and (mt5 or nav or nwb)
    if ankle and foot:
        cat = "ankle and foot radiographs"
    elif ankle:
        cat = "ankle radiographs"
    elif foot:
        cat = "foot radiographs"
    else:
        cat = "no radiographs"
    return make_result(
        "Ottawa ankle rules",
        int(ankle) + int(foot),
        "radiograph series",
        cat,
        f"Ottawa ankle rules: {cat}"
        + (" indicated." if ankle or foot else " needed (fracture very unlikely)."),
        {"ankle_series": ankle, "foot_series": foot},
        "Stiell IG et al. Decision rules for the use of radiography in acute ankle injuries. JAMA "
        "1993;269:1127-1132.",
    )
