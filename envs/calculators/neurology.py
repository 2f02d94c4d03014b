"""Neurology instruments: NIH Stroke Scale and the ABCD2 score after TIA."""

from __future__ import annotations

from typing import Literal

from ._core import (
    CalculatorInputError,
    ScoreResult,
    check_bool,
    check_choice,
    check_int,
    check_number,
    make_result,
)

# (argument name, maximum points) in the order of the NIHSS form.
_NIHSS_ITEMS = (
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


def calculate_nihss(
    loc: int,
    loc_questions: int,
    loc_commands: int,
    best_gaze: int,
    visual_fields: int,
    facial_palsy: int,
    motor_arm_left: int,
    motor_arm_right: int,
    motor_leg_left: int,
    motor_leg_right: int,
    limb_ataxia: int,
    sensory: int,
    best_language: int,
    dysarthria: int,
    extinction_inattention: int,
) -> ScoreResult:
    """NIH Stroke Scale total (0-42) from its 15 items; untestable ("UN") items are scored 0.

    Args:
        loc: 1a level of consciousness, integer 0-3 (3 = coma: 1b, 1c and sensory must then be 2,
            best_language 3, as the NIHSS instructions score them).
        loc_questions: 1b LOC questions (month, age), integer 0-2.
        loc_commands: 1c LOC commands (eyes, grip), integer 0-2.
        best_gaze: 2 best gaze, integer 0-2.
        visual_fields: 3 visual fields, integer 0-3.
        facial_palsy: 4 facial palsy, integer 0-3.
        motor_arm_left: 5a motor left arm, integer 0-4.
        motor_arm_right: 5b motor right arm, integer 0-4.
        motor_leg_left: 6a motor left leg, integer 0-4.
        motor_leg_right: 6b motor right leg, integer 0-4.
        limb_ataxia: 7 limb ataxia, integer 0-2.
        sensory: 8 sensory, integer 0-2.
        best_language: 9 best language, integer 0-3.
        dysarthria: 10 dysarthria, integer 0-2.
        extinction_inattention: 11 extinction and inattention (neglect), integer 0-2.
    """
    fn = "calculate_nihss"
    values = (
        loc,
        loc_questions,
        loc_commands,
        best_gaze,
        visual_fields,
        facial_palsy,
        motor_arm_left,
        motor_arm_right,
        motor_leg_left,
        motor_leg_right,
        limb_ataxia,
        sensory,
        best_language,
        dysarthria,
        extinction_inattention,
    )
    comps = {name: check_int(fn, name, v, 0, hi) for (name, hi), v in zip(_NIHSS_ITEMS, values)}
    if comps["loc"] == 3:  # NIHSS instructions: a coma patient (1a = 3) scores 2 on 1b, 1c and 8 and 3 on 9
        for name, forced in (("loc_questions", 2), ("loc_commands", 2), ("sensory", 2), ("best_language", 3)):
            if comps[name] != forced:
                raise CalculatorInputError(
                    fn,
                    name,
                    f"{forced} when loc is 3 (the NIHSS scores a coma patient {forced} on this item)",
                    comps[name],
                )
    total = sum(comps.values())
    if total == 0:
        cat = "no stroke symptoms"
    elif total <= 4:
        cat = "minor stroke"
    elif total <= 15:
        cat = "moderate stroke"
    elif total <= 20:
        cat = "moderate to severe stroke"
    else:
        cat = "severe stroke"
    return make_result(
        "NIH Stroke Scale",
        total,
        "points",
        cat,
        f"NIHSS {total}/42: {cat}.",
        comps,
        "Brott T et al. Measurements of acute cerebral infarction: a clinical examination scale. Stroke "
        "1989;20:864-870; NIH Stroke Scale form (NINDS); severity bands (0, 1-4, 5-15, 16-20, 21-42) as "
        "commonly used in stroke practice, not part of the scale itself.",
    )


def calculate_abcd2(
    age: int,
    systolic_bp: float,
    diastolic_bp: float,
    clinical_features: Literal["unilateral_weakness", "speech_disturbance", "other"],
    duration_minutes: float,
    diabetes: bool,
) -> ScoreResult:
    """ABCD2 score (0-7) for 2-day stroke risk after a transient ischaemic attack.

    Args:
        age: Age in years, integer 18-120 (>= 60 scores 1).
        systolic_bp: First systolic blood pressure after the TIA in mmHg, 0-350 (>= 140 scores 1).
        diastolic_bp: First diastolic blood pressure in mmHg, 0-250 (>= 90 scores 1).
        clinical_features: "unilateral_weakness" (2), "speech_disturbance" without weakness (1)
            or "other" (0).
        duration_minutes: Symptom duration in minutes, 0-1440 (10-59: 1, >= 60: 2).
        diabetes: True for diabetes (1).
    """
    fn = "calculate_abcd2"
    a = check_int(fn, "age", age, 18, 120, "years")
    sbp = check_number(fn, "systolic_bp", systolic_bp, 0, 350, "mmHg")
    dbp = check_number(fn, "diastolic_bp", diastolic_bp, 0, 250, "mmHg")
    cf = check_choice(
        fn, "clinical_features", clinical_features, ("unilateral_weakness", "speech_disturbance", "other")
    )
    dur = check_number(fn, "duration_minutes", duration_minutes, 0, 1440, "min")
    comps = {
        "age_ge_60": int(a >= 60),
        "blood_pressure": int(sbp >= 140 or dbp >= 90),
        "clinical_features": {"unilateral_weakness": 2, "speech_disturbance": 1, "other": 0}[cf],
        "duration": 2 if dur >= 60 else 1 if dur >= 10 else 0,
        "diabetes": int(check_bool(fn, "diabetes", diabetes)),
    }
    total = sum(comps.values())
    if total >= 6:
        cat, text = "high risk", "2-day stroke risk 8.1%"
    elif total >= 4:
        cat, text = "moderate risk", "2-day stroke risk 4.1%"
    else:
        cat, text = "low risk", "2-day stroke risk 1.0%"
    return make_result(
        "ABCD2",
        total,
        "points",
        cat,
        f"ABCD2 {total}/7 ({cat}): {text}.",
        comps,
        "Johnston SC et al. Validation and refinement of scores to predict very early stroke risk after "
        "transient ischaemic attack. Lancet 2007;369:283-292.",
    )
