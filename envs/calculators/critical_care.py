"""Critical-care instruments: GCS, qSOFA, SIRS, NEWS2, SOFA, shock index, A-a gradient.

Band edges on continuous measurements: the published tables are written for whole numbers
(NEWS2 "9-11", SOFA "1.2-1.9"). We read each band as "up to and including its printed upper
value" where the table is written with "<=" (NEWS2) and as "below the next band's lower value"
where it is written with "<" / ">=" (SOFA), so a non-integer input always lands in exactly one
band and integer inputs land exactly where the table puts them.
"""

from __future__ import annotations

from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_int,
    check_number,
    check_optional_number,
    make_result,
)

_CONSCIOUSNESS = ("alert", "new_confusion", "voice", "pain", "unresponsive")


def calculate_gcs(eye: int, verbal: int, motor: int) -> ScoreResult:
    """Glasgow Coma Scale total (3-15) with the traumatic-brain-injury severity band.

    Args:
        eye: Best eye opening, integer 1-4 (4 spontaneous, 3 to sound, 2 to pressure/pain, 1 none).
        verbal: Best verbal response, integer 1-5 (5 oriented, 4 confused, 3 words, 2 sounds, 1 none).
        motor: Best motor response, integer 1-6 (6 obeys, 5 localises, 4 normal flexion/withdraws,
            3 abnormal flexion, 2 extension, 1 none).
    """
    fn = "calculate_gcs"
    e = check_int(fn, "eye", eye, 1, 4)
    v = check_int(fn, "verbal", verbal, 1, 5)
    m = check_int(fn, "motor", motor, 1, 6)
    total = e + v + m
    if total <= 8:
        cat, text = (
            "severe",
            "severe impairment of consciousness (GCS 3-8): protect the airway (consider intubation)",
        )
    elif total <= 12:
        cat, text = "moderate", "moderate impairment of consciousness (GCS 9-12)"
    else:
        cat, text = "mild", "mild or no impairment of consciousness (GCS 13-15)"
    return make_result(
        "Glasgow Coma Scale",
        total,
        "points",
        cat,
        f"GCS {total} (E{e} V{v} M{m}): {text}.",
        {"eye": e, "verbal": v, "motor": m},
        "Teasdale G, Jennett B. Assessment of coma and impaired consciousness: a practical scale. "
        "Lancet 1974;2:81-84; severity bands (3-8 severe, 9-12 moderate, 13-15 mild) as used for head "
        "injury.",
    )


def calculate_qsofa(respiratory_rate: float, systolic_bp: float, altered_mentation: bool) -> ScoreResult:
    """Quick SOFA (qSOFA, Sepsis-3) bedside score for suspected infection outside the ICU.

    Args:
        respiratory_rate: Respiratory rate in breaths/min, 0-100 (>= 22 scores 1).
        systolic_bp: Systolic blood pressure in mmHg, 0-350 (<= 100 scores 1).
        altered_mentation: True if mentation is altered (any GCS < 15); scores 1.
    """
    fn = "calculate_qsofa"
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    am = check_bool(fn, "altered_mentation", altered_mentation)
    comps = {
        "respiratory_rate_ge_22": int(rr >= 22),
        "systolic_bp_le_100": int(sbp <= 100),
        "altered_mentation": int(am),
    }
    total = comps["respiratory_rate_ge_22"] + comps["systolic_bp_le_100"] + comps["altered_mentation"]
    if total >= 2:
        cat = "high risk"
        text = (
            "qSOFA >= 2: high risk of poor outcome in suspected infection; assess for organ "
            "dysfunction (full SOFA)."
        )
    else:
        cat = "not high risk"
        text = (
            "qSOFA < 2: not high risk by qSOFA; keep reassessing if infection is suspected (qSOFA is "
            "not a sepsis rule-out)."
        )
    return make_result(
        "qSOFA",
        total,
        "points",
        cat,
        f"qSOFA {total}/3: {text}",
        comps,
        "Seymour CW et al. Assessment of clinical criteria for sepsis (Sepsis-3). JAMA 2016;315:762-774; "
        "Singer M et al. The Third International Consensus Definitions for Sepsis. JAMA 2016;315:801-810.",
    )


def calculate_sirs(
    temperature_c: float,
    heart_rate: float,
    respiratory_rate: float,
    wbc_k_per_ul: float,
    paco2_mmhg: float | None = None,
    bands_percent: float | None = None,
) -> ScoreResult:
    """Systemic inflammatory response syndrome (SIRS) criteria count (ACCP/SCCM 1992).

    Args:
        temperature_c: Core temperature in degrees C, 25-45 (> 38 or < 36 meets the criterion).
        heart_rate: Heart rate in beats/min, 0-350 (> 90 meets the criterion).
        respiratory_rate: Respiratory rate in breaths/min, 0-100 (> 20 meets the criterion).
        wbc_k_per_ul: White cell count in 10^3/uL, 0-500 (> 12 or < 4 meets the criterion).
        paco2_mmhg: Optional PaCO2 in mmHg, 5-200 (< 32 also meets the respiratory criterion).
        bands_percent: Optional immature (band) neutrophils in percent, 0-100 (> 10 also meets
            the white-cell criterion).
    """
    fn = "calculate_sirs"
    t = check_number(fn, "temperature_c", temperature_c, 25, 45, "degrees C")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    wbc = check_number(fn, "wbc_k_per_ul", wbc_k_per_ul, 0, 500, "x10^3/uL")
    pc = check_optional_number(fn, "paco2_mmhg", paco2_mmhg, 5, 200, "mmHg")
    bands = check_optional_number(fn, "bands_percent", bands_percent, 0, 100, "%")
    comps = {
        "temperature": int(t > 38 or t < 36),
        "heart_rate": int(hr > 90),
        "respiratory": int(rr > 20 or (pc is not None and pc < 32)),
        "white_cells": int(wbc > 12 or wbc < 4 or (bands is not None and bands > 10)),
    }
    total = comps["temperature"] + comps["heart_rate"] + comps["respiratory"] + comps["white_cells"]
    met = total >= 2
    return make_result(
        "SIRS criteria",
        total,
        "criteria",
        "SIRS criteria met" if met else "SIRS criteria not met",
        f"{total}/4 SIRS criteria: "
        + (
            "meets the SIRS definition (>= 2 criteria)."
            if met
            else "does not meet the SIRS definition (< 2 criteria)."
        ),
        comps,
        "Bone RC et al. Definitions for sepsis and organ failure (ACCP/SCCM Consensus Conference). "
        "Chest 1992;101:1644-1655.",
    )


def _news2_rr(rr: float) -> int:
    return 3 if rr <= 8 else 1 if rr <= 11 else 0 if rr <= 20 else 2 if rr <= 24 else 3


def _news2_hr(hr: float) -> int:
    return 3 if hr <= 40 else 1 if hr <= 50 else 0 if hr <= 90 else 1 if hr <= 110 else 2 if hr <= 130 else 3


def _news2_sbp(sbp: float) -> int:
    return 3 if sbp <= 90 else 2 if sbp <= 100 else 1 if sbp <= 110 else 0 if sbp <= 219 else 3


def _news2_temp(t: float) -> int:
    return 3 if t <= 35.0 else 1 if t <= 36.0 else 0 if t <= 38.0 else 1 if t <= 39.0 else 2


def _news2_spo2(s: float, on_o2: bool, scale: int) -> int:
    if scale == 1:
        return 3 if s <= 91 else 2 if s <= 93 else 1 if s <= 95 else 0
    # Scale 2 (target 88-92 % in hypercapnic respiratory failure): high saturations score only
    # when they are achieved on supplemental oxygen.
    if s <= 83:
        return 3
    if s <= 85:
        return 2
    if s <= 87:
        return 1
    if s <= 92 or not on_o2:
        return 0
    return 1 if s <= 94 else 2 if s <= 96 else 3


def calculate_news2(
    respiratory_rate: float,
    spo2: float,
    on_supplemental_oxygen: bool,
    temperature_c: float,
    systolic_bp: float,
    heart_rate: float,
    consciousness: Literal["alert", "new_confusion", "voice", "pain", "unresponsive"],
    spo2_scale: Literal[1, 2] = 1,
) -> ScoreResult:
    """National Early Warning Score 2 (RCP 2017) with its clinical-risk band.

    Args:
        respiratory_rate: Respiratory rate in breaths/min, 0-100.
        spo2: Peripheral oxygen saturation in percent, 0-100.
        on_supplemental_oxygen: True if the patient is breathing supplemental oxygen (scores 2).
        temperature_c: Temperature in degrees C, 25-45.
        systolic_bp: Systolic blood pressure in mmHg, 0-350.
        heart_rate: Pulse in beats/min, 0-350.
        consciousness: ACVPU: "alert", "new_confusion", "voice", "pain" or "unresponsive"
            (anything but alert scores 3).
        spo2_scale: 1 (default) or 2; scale 2 only for prescribed target 88-92 % (hypercapnic
            respiratory failure).
    """
    fn = "calculate_news2"
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    s = check_number(fn, "spo2", spo2, 0, 100, "%")
    o2 = check_bool(fn, "on_supplemental_oxygen", on_supplemental_oxygen)
    t = check_number(fn, "temperature_c", temperature_c, 25, 45, "degrees C")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    avpu = check_choice(fn, "consciousness", consciousness, _CONSCIOUSNESS)
    if spo2_scale not in (1, 2) or type(spo2_scale) is bool:
        raise CalculatorInputError(fn, "spo2_scale", "1 or 2", spo2_scale)
    comps = {
        "respiratory_rate": _news2_rr(rr),
        "spo2": _news2_spo2(s, o2, spo2_scale),
        "supplemental_oxygen": 2 if o2 else 0,
        "systolic_bp": _news2_sbp(sbp),
        "heart_rate": _news2_hr(hr),
        "consciousness": 0 if avpu == "alert" else 3,
        "temperature": _news2_temp(t),
    }
    total = sum(comps.values())
    if total >= 7:
        cat, text = (
            "high",
            "emergency response: continuous monitoring and urgent assessment by a critical-care team",
        )
    elif total >= 5:
        cat, text = "medium", "urgent response: at least hourly observations and urgent clinician review"
    elif 3 in comps.values():
        cat, text = (
            "low-medium",
            "a single parameter scores 3: urgent ward-based review and at least hourly observations",
        )
    else:
        cat, text = (
            "low",
            (
                "continue routine observations (at least 12-hourly)"
                if total == 0
                else "ward-based response: observations at least every 4-6 hours"
            ),
        )
    return make_result(
        "NEWS2",
        total,
        "points",
        cat,
        f"NEWS2 {total} ({cat} clinical risk): {text}.",
        comps,
        "Royal College of Physicians. National Early Warning Score (NEWS) 2: standardising the "
        "assessment of acute-illness severity in the NHS. London: RCP, 2017.",
    )


def _sofa_cardio(
    map_mmhg: float, dopamine: float, dobutamine: float, epinephrine: float, norepinephrine: float
) -> int:
    if dopamine > 15 or epinephrine > 0.1 or norepinephrine > 0.1:
        return 4
    if dopamine > 5 or epinephrine > 0 or norepinephrine > 0:
        return 3
    if dopamine > 0 or dobutamine > 0:
        return 2
    return 1 if map_mmhg < 70 else 0


# Ferreira FL et al. JAMA 2001;286:1754-1758: ICU mortality by the initial SOFA score.
_SOFA_MORTALITY = (
    (1, "0-1", "0%"),
    (3, "2-3", "6.4%"),
    (5, "4-5", "20.2%"),
    (7, "6-7", "21.5%"),
    (9, "8-9", "33.3%"),
    (11, "10-11", "50.0%"),
    (24, "> 11", "95.2%"),
)


def calculate_sofa(
    pao2_fio2_ratio: float,
    on_mechanical_ventilation: bool,
    platelets_k_per_ul: float,
    bilirubin_mg_dl: float,
    map_mmhg: float,
    gcs: int,
    creatinine_mg_dl: float,
    dopamine_mcg_kg_min: float = 0.0,
    dobutamine_mcg_kg_min: float = 0.0,
    epinephrine_mcg_kg_min: float = 0.0,
    norepinephrine_mcg_kg_min: float = 0.0,
    urine_output_ml_day: float | None = None,
) -> ScoreResult:
    """Sequential Organ Failure Assessment (SOFA) score, 0-24, over six organ systems.

    Args:
        pao2_fio2_ratio: PaO2/FiO2 ratio in mmHg, 10-700.
        on_mechanical_ventilation: True if on mechanical ventilation or other respiratory
            support; respiratory points 3-4 (ratio < 200 / < 100) require it.
        platelets_k_per_ul: Platelet count in 10^3/uL, 0-2000.
        bilirubin_mg_dl: Total bilirubin in mg/dL, 0-80.
        map_mmhg: Mean arterial pressure in mmHg, 0-250.
        gcs: Glasgow Coma Scale total, integer 3-15.
        creatinine_mg_dl: Serum creatinine in mg/dL, 0-30.
        dopamine_mcg_kg_min: Dopamine dose in ug/kg/min given for at least 1 h, 0-100 (default 0).
        dobutamine_mcg_kg_min: Dobutamine dose in ug/kg/min (any dose scores 2), 0-100 (default 0).
        epinephrine_mcg_kg_min: Epinephrine dose in ug/kg/min, 0-10 (default 0).
        norepinephrine_mcg_kg_min: Norepinephrine dose in ug/kg/min, 0-10 (default 0).
        urine_output_ml_day: Optional urine output in mL/day, 0-20000 (< 500 scores 3, < 200 scores 4).
    """
    fn = "calculate_sofa"
    pf = check_number(fn, "pao2_fio2_ratio", pao2_fio2_ratio, 10, 700, "mmHg")
    vent = check_bool(fn, "on_mechanical_ventilation", on_mechanical_ventilation)
    plt = check_number(fn, "platelets_k_per_ul", platelets_k_per_ul, 0, 2000, "x10^3/uL")
    bili = check_number(fn, "bilirubin_mg_dl", bilirubin_mg_dl, 0, 80, "mg/dL")
    mp = check_number(fn, "map_mmhg", map_mmhg, 0, 250, "mmHg")
    g = check_int(fn, "gcs", gcs, 3, 15)
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0, 30, "mg/dL")
    dopa = check_number(fn, "dopamine_mcg_kg_min", dopamine_mcg_kg_min, 0, 100, "ug/kg/min")
    dobu = check_number(fn, "dobutamine_mcg_kg_min", dobutamine_mcg_kg_min, 0, 100, "ug/kg/min")
    epi = check_number(fn, "epinephrine_mcg_kg_min", epinephrine_mcg_kg_min, 0, 10, "ug/kg/min")
    norepi = check_number(fn, "norepinephrine_mcg_kg_min", norepinephrine_mcg_kg_min, 0, 10, "ug/kg/min")
    uo = check_optional_number(fn, "urine_output_ml_day", urine_output_ml_day, 0, 20000, "mL/day")

    if pf < 100 and vent:
        resp = 4
    elif pf < 200 and vent:
        resp = 3
    else:  # without respiratory support the respiratory score is capped at 2
        resp = 2 if pf < 300 else 1 if pf < 400 else 0
    coag = 4 if plt < 20 else 3 if plt < 50 else 2 if plt < 100 else 1 if plt < 150 else 0
    liver = 0 if bili < 1.2 else 1 if bili < 2.0 else 2 if bili < 6.0 else 3 if bili < 12.0 else 4
    cns = 0 if g == 15 else 1 if g >= 13 else 2 if g >= 10 else 3 if g >= 6 else 4
    renal = 0 if cr < 1.2 else 1 if cr < 2.0 else 2 if cr < 3.5 else 3 if cr < 5.0 else 4
    if uo is not None:  # the worse of the creatinine and urine-output criteria
        renal = max(renal, 4 if uo < 200 else 3 if uo < 500 else 0)
    comps = {
        "respiration": resp,
        "coagulation": coag,
        "liver": liver,
        "cardiovascular": _sofa_cardio(mp, dopa, dobu, epi, norepi),
        "cns": cns,
        "renal": renal,
    }
    total = sum(comps.values())
    for upper, band, mortality in _SOFA_MORTALITY:
        if total <= upper:
            break
    return make_result(
        "SOFA",
        total,
        "points",
        f"SOFA {band}",
        f"SOFA {total}/24: ICU mortality about {mortality} for an initial score of {band} (Ferreira 2001); "
        "an acute rise of >= 2 points with infection defines sepsis (Sepsis-3).",
        comps,
        "Vincent JL et al. The SOFA (Sepsis-related Organ Failure Assessment) score to describe organ "
        "dysfunction/failure. Intensive Care Med 1996;22:707-710; mortality bands: Ferreira FL et al. "
        "JAMA 2001;286:1754-1758.",
    )


def calculate_shock_index(heart_rate: float, systolic_bp: float) -> ScoreResult:
    """Shock index: heart rate divided by systolic blood pressure.

    Args:
        heart_rate: Heart rate in beats/min, 0-350.
        systolic_bp: Systolic blood pressure in mmHg, 1-350.
    """
    fn = "calculate_shock_index"
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 1, 350, "mmHg")
    si = hr / sbp
    if si >= 1.0:
        cat, text = (
            "shock likely",
            "shock index >= 1.0: haemodynamic compromise likely (Allgower: 1.0 threatening, 1.5 manifest "
            "shock)",
        )
    elif si > 0.7:
        cat, text = "elevated", "shock index above the normal 0.5-0.7 range"
    else:
        cat, text = "normal", "shock index within or below the normal 0.5-0.7 range"
    return make_result(
        "Shock index",
        si,
        "bpm/mmHg",
        cat,
        f"Shock index {si:.2f}: {text}.",
        {"heart_rate": hr, "systolic_bp": sbp},
        "Allgower M, Burri C. 'Schockindex'. Dtsch Med Wochenschr 1967;92:1947-1950.",
    )


def calculate_aa_gradient(
    pao2_mmhg: float,
    paco2_mmhg: float,
    fio2: float,
    age: float | None = None,
    atmospheric_pressure_mmhg: float = 760.0,
    respiratory_quotient: float = 0.8,
) -> ScoreResult:
    """Alveolar-arterial (A-a) oxygen gradient from the alveolar gas equation.

    Args:
        pao2_mmhg: Arterial PaO2 in mmHg, 10-700.
        paco2_mmhg: Arterial PaCO2 in mmHg, 5-200.
        fio2: Inspired oxygen fraction, 0.21-1.0 (room air 0.21).
        age: Optional age in years, 0-120; gives the age-expected upper normal (age/4 + 4) on room air.
        atmospheric_pressure_mmhg: Barometric pressure in mmHg, 400-800 (default 760, sea level).
        respiratory_quotient: Respiratory quotient, 0.6-1.2 (default 0.8).
    """
    fn = "calculate_aa_gradient"
    pao2 = check_number(fn, "pao2_mmhg", pao2_mmhg, 10, 700, "mmHg")
    paco2 = check_number(fn, "paco2_mmhg", paco2_mmhg, 5, 200, "mmHg")
    f = check_number(fn, "fio2", fio2, 0.21, 1.0)
    a = check_optional_number(fn, "age", age, 0, 120, "years")
    patm = check_number(fn, "atmospheric_pressure_mmhg", atmospheric_pressure_mmhg, 400, 800, "mmHg")
    rq = check_number(fn, "respiratory_quotient", respiratory_quotient, 0.6, 1.2)
    # Alveolar gas equation; 47 mmHg is the water vapour pressure at 37 degrees C.
    alveolar = f * (patm - 47.0) - paco2 / rq
    gradient = alveolar - pao2
    upper = a / 4.0 + 4.0 if a is not None else None
    comps = {"alveolar_po2_mmhg": alveolar, "expected_upper_normal_mmhg": upper}
    if upper is None:
        cat = "not classified"
        text = "give age for the age-expected normal"
    elif f > 0.21:
        cat = "not classified"
        text = "the age-expected normal applies to room air only (FiO2 0.21); the gradient widens with FiO2"
    elif gradient > upper:
        cat, text = (
            "elevated",
            f"above the age-expected upper normal of {upper:.1f} mmHg: V/Q mismatch, shunt or diffusion "
            "defect",
        )
    else:
        cat, text = (
            "normal",
            f"within the age-expected normal (<= {upper:.1f} mmHg): hypoxaemia, if any, is from "
            "hypoventilation or low FiO2",
        )
    return make_result(
        "A-a gradient",
        gradient,
        "mmHg",
        cat,
        f"A-a gradient {gradient:.1f} mmHg: {text}.",
        comps,
        "Alveolar gas equation (PAO2 = FiO2 x (Patm - PH2O) - PaCO2/RQ); West JB. Respiratory "
        "Physiology: The Essentials. Age-expected normal: age/4 + 4 mmHg (room air).",
    )
