"""Helpers shared by the peer adapters (no peer package is imported here)."""

from __future__ import annotations


def _mc(fn, inputs: dict) -> float:
    return fn(inputs)["Answer"]


def _om(module, func: str, params_cls: str, **kwargs) -> float:
    params = getattr(module, params_cls)(**kwargs)
    return getattr(module, func)(params).value


def _trop_points(x):
    return 0 if x <= 1 else 1 if x <= 3 else 2


_DVT_KEYS = (
    "active_cancer",
    "paralysis_paresis_or_cast",
    "bedridden_or_major_surgery",
    "localized_tenderness",
    "entire_leg_swollen",
    "calf_swelling_3cm",
    "pitting_edema",
    "collateral_superficial_veins",
    "previous_dvt",
    "alternative_diagnosis_as_likely",
)


_NIHSS_OURS = (
    "loc",
    "loc_questions",
    "loc_commands",
    "best_gaze",
    "visual_fields",
    "facial_palsy",
    "motor_arm_left",
    "motor_arm_right",
    "motor_leg_left",
    "motor_leg_right",
    "limb_ataxia",
    "sensory",
    "best_language",
    "dysarthria",
    "extinction_inattention",
)
