"""Obstetric and newborn instruments: Bishop score, Apgar score, biophysical profile.

Bishop (1964) scored dilation and effacement in whole-number bands (dilation 0 / 1-2 / 3-4 /
>= 5 cm; effacement 0-30 / 40-50 / 60-70 / >= 80 %). Real measurements between the printed
bands (2.5 cm, 35 %) are placed in the lower band, i.e. a band starts at its printed lower value.
"""

from __future__ import annotations

from typing import Literal

from ._core import ScoreResult, check_bool, check_choice, check_int, check_number, make_result


def calculate_bishop_score(
    dilation_cm: float,
    effacement_percent: float,
    station: int,
    consistency: Literal["firm", "medium", "soft"],
    position: Literal["posterior", "mid", "anterior"],
) -> ScoreResult:
    """Bishop pre-induction cervical score (0-13).

    Args:
        dilation_cm: Cervical dilation in cm, 0-10 (closed: 0, 1-2: 1, 3-4: 2, >= 5: 3).
        effacement_percent: Effacement in percent, 0-100 (0-30: 0, 40-50: 1, 60-70: 2, >= 80: 3).
        station: Fetal station relative to the ischial spines, integer -5 to +5 (<= -3: 0, -2: 1,
            -1 or 0: 2, >= +1: 3).
        consistency: Cervical consistency: "firm" (0), "medium" (1) or "soft" (2).
        position: Cervical position: "posterior" (0), "mid" (1) or "anterior" (2).
    """
    fn = "calculate_bishop_score"
    d = check_number(fn, "dilation_cm", dilation_cm, 0, 10, "cm")
    e = check_number(fn, "effacement_percent", effacement_percent, 0, 100, "%")
    st = check_int(fn, "station", station, -5, 5)
    c = check_choice(fn, "consistency", consistency, ("firm", "medium", "soft"))
    p = check_choice(fn, "position", position, ("posterior", "mid", "anterior"))
    comps = {
        "dilation": 0 if d < 1 else 1 if d < 3 else 2 if d < 5 else 3,
        "effacement": 0 if e < 40 else 1 if e < 60 else 2 if e < 80 else 3,
        "station": 0 if st <= -3 else 1 if st == -2 else 2 if st <= 0 else 3,
        "consistency": {"firm": 0, "medium": 1, "soft": 2}[c],
        "position": {"posterior": 0, "mid": 1, "anterior": 2}[p],
    }
    total = sum(comps.values())
    if total >= 9:
        cat, text = (
            "favorable",
            "likelihood of vaginal delivery after induction similar to spontaneous labour",
        )
    elif total >= 7:
        cat, text = "intermediate", "neither clearly favourable nor unfavourable"
    else:
        cat, text = "unfavorable", "cervical ripening is recommended before induction"
    return make_result(
        "Bishop score",
        total,
        "points",
        cat,
        f"Bishop {total}/13 ({cat}): {text}.",
        comps,
        "Bishop EH. Pelvic scoring for elective induction. Obstet Gynecol 1964;24:266-268; thresholds "
        "(> 8 favourable, <= 6 unfavourable): ACOG Practice Bulletin No. 107, Induction of labor, 2009.",
    )


def calculate_apgar(
    heart_rate: float,
    respiratory_effort: Literal["absent", "weak", "strong"],
    muscle_tone: Literal["limp", "some_flexion", "active"],
    reflex_irritability: Literal["none", "grimace", "cry"],
    color: Literal["blue_pale", "acrocyanosis", "pink"],
) -> ScoreResult:
    """Apgar score (0-10) of a newborn at 1, 5 or 10 minutes.

    Args:
        heart_rate: Heart rate in beats/min, 0-300 (0 absent: 0, < 100: 1, >= 100: 2).
        respiratory_effort: "absent" (0), "weak" (slow/irregular, 1) or "strong" (good cry, 2).
        muscle_tone: "limp" (0), "some_flexion" (1) or "active" (active motion, 2).
        reflex_irritability: Response to stimulation: "none" (0), "grimace" (1) or "cry"
            (cough, sneeze or cry, 2).
        color: "blue_pale" (0), "acrocyanosis" (body pink, extremities blue, 1) or "pink" (2).
    """
    fn = "calculate_apgar"
    hr = check_number(fn, "heart_rate", heart_rate, 0, 300, "beats/min")
    r = check_choice(fn, "respiratory_effort", respiratory_effort, ("absent", "weak", "strong"))
    t = check_choice(fn, "muscle_tone", muscle_tone, ("limp", "some_flexion", "active"))
    x = check_choice(fn, "reflex_irritability", reflex_irritability, ("none", "grimace", "cry"))
    c = check_choice(fn, "color", color, ("blue_pale", "acrocyanosis", "pink"))
    comps = {
        "heart_rate": 0 if hr == 0 else 1 if hr < 100 else 2,
        "respiratory_effort": {"absent": 0, "weak": 1, "strong": 2}[r],
        "muscle_tone": {"limp": 0, "some_flexion": 1, "active": 2}[t],
        "reflex_irritability": {"none": 0, "grimace": 1, "cry": 2}[x],
        "color": {"blue_pale": 0, "acrocyanosis": 1, "pink": 2}[c],
    }
    total = sum(comps.values())
    if total >= 7:
        cat, text = "reassuring", "reassuring"
    elif total >= 4:
        cat, text = (
            "moderately abnormal",
            "moderately abnormal: continue assessment and support; repeat every 5 min to 20 min",
        )
    else:
        cat, text = (
            "low",
            "low: needs resuscitation per neonatal resuscitation guidance; repeat every 5 min to 20 min",
        )
    return make_result(
        "Apgar score",
        total,
        "points",
        cat,
        f"Apgar {total}/10: {text}.",
        comps,
        "Apgar V. A proposal for a new method of evaluation of the newborn infant. Curr Res Anesth Analg "
        "1953;32:260-267; bands: AAP/ACOG Committee Opinion No. 644, The Apgar Score, 2015.",
    )


def calculate_biophysical_profile(
    fetal_breathing: bool,
    body_movements_count: int,
    fetal_tone: bool,
    deepest_vertical_pocket_cm: float,
    nst_reactive: bool | None = None,
) -> ScoreResult:
    """Fetal biophysical profile (Manning): 0-10 with the nonstress test, 0-8 without it.

    Args:
        fetal_breathing: True for >= 1 episode of rhythmic breathing lasting >= 30 s within 30 min (2).
        body_movements_count: Discrete body or limb movements seen in 30 min, integer 0-100 (>= 3 scores 2).
        fetal_tone: True for >= 1 episode of extension with return to flexion of a limb or trunk,
            or opening and closing of a hand (2).
        deepest_vertical_pocket_cm: Single deepest vertical pocket of amniotic fluid in cm, 0-30
            (> 2 cm scores 2; <= 2 cm is oligohydramnios).
        nst_reactive: Nonstress test result: True reactive (2), False non-reactive (0), None not
            performed (the ultrasound-only profile out of 8).
    """
    fn = "calculate_biophysical_profile"
    comps: dict[str, int | None] = {
        "fetal_breathing": 2 * check_bool(fn, "fetal_breathing", fetal_breathing),
        "body_movements": 2 * (check_int(fn, "body_movements_count", body_movements_count, 0, 100) >= 3),
        "fetal_tone": 2 * check_bool(fn, "fetal_tone", fetal_tone),
    }
    dvp = check_number(fn, "deepest_vertical_pocket_cm", deepest_vertical_pocket_cm, 0, 30, "cm")
    comps["amniotic_fluid"] = 2 * (dvp > 2)
    if nst_reactive is not None:
        comps["nonstress_test"] = 2 * check_bool(fn, "nst_reactive", nst_reactive)
    else:
        comps["nonstress_test"] = None
    total = sum(v for v in comps.values() if v is not None)
    maximum = 8 if nst_reactive is None else 10
    oligo = dvp <= 2
    flags: tuple[str, ...] = ("oligohydramnios",) if oligo else ()
    if maximum == 8 and total < 8:
        cat, text = (
            "incomplete",
            "an ultrasound component is abnormal: perform the nonstress test for the full profile",
        )
    elif total >= 8:
        cat = "normal"
        text = (
            "normal score, but oligohydramnios (deepest pocket <= 2 cm) requires further evaluation"
            if oligo
            else "normal: low risk of fetal asphyxia"
        )
    elif total == 6:
        cat, text = "equivocal", "equivocal: repeat within 24 h or consider delivery at or near term"
    else:
        cat, text = "abnormal", "abnormal (<= 4): evaluate promptly for delivery"
    return make_result(
        "Biophysical profile",
        total,
        "points",
        cat,
        f"BPP {total}/{maximum}: {text}.",
        comps,
        "Manning FA, Platt LD, Sipos L. Antepartum fetal evaluation: development of a fetal biophysical "
        "profile. Am J Obstet Gynecol 1980;136:787-795; interpretation: ACOG Practice Bulletin No. 229, "
        "Antepartum fetal surveillance, 2021.",
        flags,
    )
