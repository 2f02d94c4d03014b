"""APACHE II (Knaus 1985): acute physiology, age and chronic health points.

Each physiology variable is the worst value in the first 24 h in the ICU. The published table
gives whole-number bands with gaps (e.g. temperature 38.5-38.9 then 39-40.9); we use the lower
edge of each band as an inclusive threshold going outward from the normal band (">= 39" on the
high side, "< 36" on the low side), so every real value falls in exactly one band and the
printed values score exactly as in the table.

Oxygenation follows the paper: with FiO2 >= 0.5 the A-a gradient is scored, otherwise PaO2.
When the A-a gradient is not given it is computed from the alveolar gas equation at sea level
(FiO2 x 713 - PaCO2 / 0.8 - PaO2). Serum bicarbonate replaces arterial pH only when no blood
gas is available, as the paper allows.
"""

from __future__ import annotations

from bisect import bisect_right
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

_ADMISSION = ("nonoperative", "emergency_postoperative", "elective_postoperative")


def _bands(high: tuple, low: tuple) -> tuple[tuple[float, ...], tuple[int, ...]]:
    """Compile (threshold, points) pairs into a bisect table.

    ``high`` pairs score "value >= threshold", ``low`` pairs "value < threshold", anything in
    between scores 0. The result is (ascending thresholds, points per interval), so that
    ``points[bisect_right(thresholds, value)]`` is the score (one C-level search per variable).
    """
    low_sorted = sorted(low)
    high_sorted = sorted(high)
    thresholds = tuple(t for t, _ in low_sorted) + tuple(t for t, _ in high_sorted)
    points = tuple(p for _, p in low_sorted) + (0,) + tuple(p for _, p in high_sorted)
    return thresholds, points


def _up(value: float, bands: tuple[tuple[float, ...], tuple[int, ...]]) -> int:
    return bands[1][bisect_right(bands[0], value)]


# (high side, low side) as printed in Knaus 1985, Fig. 1
_TEMP = _bands(((41, 4), (39, 3), (38.5, 1)), ((30, 4), (32, 3), (34, 2), (36, 1)))
_MAP = _bands(((160, 4), (130, 3), (110, 2)), ((50, 4), (70, 2)))
_HR = _bands(((180, 4), (140, 3), (110, 2)), ((40, 4), (55, 3), (70, 2)))
_RR = _bands(((50, 4), (35, 3), (25, 1)), ((6, 4), (10, 2), (12, 1)))
_PH = _bands(((7.7, 4), (7.6, 3), (7.5, 1)), ((7.15, 4), (7.25, 3), (7.33, 2)))
_HCO3 = _bands(((52, 4), (41, 3), (32, 1)), ((15, 4), (18, 3), (22, 2)))
_NA = _bands(((180, 4), (160, 3), (155, 2), (150, 1)), ((111, 4), (120, 3), (130, 2)))
_K = _bands(((7, 4), (6, 3), (5.5, 1)), ((2.5, 4), (3, 2), (3.5, 1)))
_CR = _bands(((3.5, 4), (2, 3), (1.5, 2)), ((0.6, 2),))
_HCT = _bands(((60, 4), (50, 2), (46, 1)), ((20, 4), (30, 2)))
_WBC = _bands(((40, 4), (20, 2), (15, 1)), ((1, 4), (3, 2)))

# Approximate hospital death rates by APACHE II band (Knaus 1985, Fig. 2): nonoperative / postoperative.
_MORTALITY = (
    (4, "0-4", "4%", "1%"),
    (9, "5-9", "8%", "3%"),
    (14, "10-14", "15%", "7%"),
    (19, "15-19", "25%", "12%"),
    (24, "20-24", "40%", "30%"),
    (29, "25-29", "55%", "35%"),
    (34, "30-34", "73%", "73%"),
    (71, "> 34", "85%", "88%"),
)


def calculate_apache2(
    temperature_c: float,
    map_mmhg: float,
    heart_rate: float,
    respiratory_rate: float,
    fio2: float,
    pao2_mmhg: float,
    sodium_mmol_l: float,
    potassium_mmol_l: float,
    creatinine_mg_dl: float,
    hematocrit_percent: float,
    wbc_k_per_ul: float,
    gcs: int,
    age: int,
    arterial_ph: float | None = None,
    serum_bicarbonate_mmol_l: float | None = None,
    paco2_mmhg: float | None = None,
    aa_gradient_mmhg: float | None = None,
    acute_renal_failure: bool = False,
    severe_organ_insufficiency_or_immunocompromised: bool = False,
    admission_type: Literal[
        "nonoperative", "emergency_postoperative", "elective_postoperative"
    ] = "nonoperative",
) -> ScoreResult:
    """APACHE II severity-of-disease score (0-71) from the worst first-24-hour ICU values.

    Args:
        temperature_c: Rectal (core) temperature in degrees C, 20-45.
        map_mmhg: Mean arterial pressure in mmHg, 0-250.
        heart_rate: Heart rate in beats/min, 0-350.
        respiratory_rate: Respiratory rate in breaths/min (ventilated or not), 0-100.
        fio2: Inspired oxygen fraction, 0.21-1.0 (>= 0.5 scores the A-a gradient, else PaO2).
        pao2_mmhg: Arterial PaO2 in mmHg, 10-700.
        sodium_mmol_l: Serum sodium in mmol/L, 80-220.
        potassium_mmol_l: Serum potassium in mmol/L, 1-12.
        creatinine_mg_dl: Serum creatinine in mg/dL, 0.1-30 (points doubled with acute renal failure).
        hematocrit_percent: Haematocrit in percent, 5-80.
        wbc_k_per_ul: White cell count in 10^3/uL, 0-500.
        gcs: Glasgow Coma Scale total, integer 3-15 (scores 15 - GCS).
        age: Age in years, integer 16-120.
        arterial_ph: Arterial pH, 6.5-8.0; required unless serum_bicarbonate_mmol_l is given.
        serum_bicarbonate_mmol_l: Venous bicarbonate in mmol/L, 1-80; used only when no arterial pH.
        paco2_mmhg: Arterial PaCO2 in mmHg, 5-200; needed to compute the A-a gradient when
            fio2 >= 0.5 and aa_gradient_mmhg is not given.
        aa_gradient_mmhg: A-a oxygen gradient in mmHg, 0-800 (optional, used when fio2 >= 0.5).
        acute_renal_failure: True if acute renal failure (creatinine points are doubled).
        severe_organ_insufficiency_or_immunocompromised: True for a history of severe organ
            insufficiency (cirrhosis, NYHA IV, severe COPD, dialysis) or immunocompromise.
        admission_type: "nonoperative", "emergency_postoperative" or "elective_postoperative"
            (chronic health points: 5 for the first two, 2 for elective postoperative).
    """
    fn = "calculate_apache2"
    t = check_number(fn, "temperature_c", temperature_c, 20, 45, "degrees C")
    mp = check_number(fn, "map_mmhg", map_mmhg, 0, 250, "mmHg")
    hr = check_number(fn, "heart_rate", heart_rate, 0, 350, "beats/min")
    rr = check_number(fn, "respiratory_rate", respiratory_rate, 0, 100, "breaths/min")
    f = check_number(fn, "fio2", fio2, 0.21, 1.0)
    pao2 = check_number(fn, "pao2_mmhg", pao2_mmhg, 10, 700, "mmHg")
    na = check_number(fn, "sodium_mmol_l", sodium_mmol_l, 80, 220, "mmol/L")
    k = check_number(fn, "potassium_mmol_l", potassium_mmol_l, 1, 12, "mmol/L")
    cr = check_number(fn, "creatinine_mg_dl", creatinine_mg_dl, 0.1, 30, "mg/dL")
    hct = check_number(fn, "hematocrit_percent", hematocrit_percent, 5, 80, "%")
    wbc = check_number(fn, "wbc_k_per_ul", wbc_k_per_ul, 0, 500, "x10^3/uL")
    g = check_int(fn, "gcs", gcs, 3, 15)
    a = check_int(fn, "age", age, 16, 120, "years")
    ph = check_optional_number(fn, "arterial_ph", arterial_ph, 6.5, 8.0)
    hco3 = check_optional_number(fn, "serum_bicarbonate_mmol_l", serum_bicarbonate_mmol_l, 1, 80, "mmol/L")
    paco2 = check_optional_number(fn, "paco2_mmhg", paco2_mmhg, 5, 200, "mmHg")
    aa = check_optional_number(fn, "aa_gradient_mmhg", aa_gradient_mmhg, 0, 800, "mmHg")
    arf = check_bool(fn, "acute_renal_failure", acute_renal_failure)
    chronic = check_bool(
        fn, "severe_organ_insufficiency_or_immunocompromised", severe_organ_insufficiency_or_immunocompromised
    )
    adm = check_choice(fn, "admission_type", admission_type, _ADMISSION)

    if f >= 0.5:
        if aa is None:
            if paco2 is None:
                raise CalculatorInputError(
                    fn, "aa_gradient_mmhg", "given (or paco2_mmhg given) when fio2 >= 0.5", None
                )
            aa = f * 713.0 - paco2 / 0.8 - pao2
        oxygenation = 4 if aa >= 500 else 3 if aa >= 350 else 2 if aa >= 200 else 0
    else:
        oxygenation = 0 if pao2 > 70 else 1 if pao2 >= 61 else 3 if pao2 >= 55 else 4
    if ph is not None:
        acid_base = _up(ph, _PH)
    elif hco3 is not None:
        acid_base = _up(hco3, _HCO3)
    else:
        raise CalculatorInputError(fn, "arterial_ph", "given (or serum_bicarbonate_mmol_l given)", None)
    creat = _up(cr, _CR) * (2 if arf else 1)
    comps = {
        "temperature": _up(t, _TEMP),
        "mean_arterial_pressure": _up(mp, _MAP),
        "heart_rate": _up(hr, _HR),
        "respiratory_rate": _up(rr, _RR),
        "oxygenation": oxygenation,
        "acid_base": acid_base,
        "sodium": _up(na, _NA),
        "potassium": _up(k, _K),
        "creatinine": creat,
        "hematocrit": _up(hct, _HCT),
        "white_cells": _up(wbc, _WBC),
        "gcs": 15 - g,
    }
    aps = sum(comps.values())
    age_points = 0 if a <= 44 else 2 if a <= 54 else 3 if a <= 64 else 5 if a <= 74 else 6
    chronic_points = (2 if adm == "elective_postoperative" else 5) if chronic else 0
    comps["acute_physiology_score"] = aps
    comps["age_points"] = age_points
    comps["chronic_health_points"] = chronic_points
    total = aps + age_points + chronic_points
    for upper, band, nonop, postop in _MORTALITY:
        if total <= upper:
            break
    mortality = nonop if adm == "nonoperative" else postop
    return make_result(
        "APACHE II",
        total,
        "points",
        f"APACHE II {band}",
        f"APACHE II {total} (acute physiology {aps}, age {age_points}, chronic health {chronic_points}): "
        f"approximate hospital mortality {mortality} for "
        f"{'nonoperative' if adm == 'nonoperative' else 'postoperative'} "
        f"patients in the {band} band (Knaus 1985).",
        comps,
        "Knaus WA, Draper EA, Wagner DP, Zimmerman JE. APACHE II: a severity of disease classification "
        "system. Crit Care Med 1985;13:818-829.",
    )
