"""The library contract: names, signatures, docstrings, tool schemas, result shape, input errors.

Every calculator is exercised with one valid input (VALID) and with invalid inputs; errors must
be ``CalculatorInputError`` (a ``ValueError``) whose message names the function, the argument
and its valid range.
"""

from __future__ import annotations

import inspect
import math
import re
import typing

import pytest

from envs import calculators as C
from envs.calculators import CALCULATORS, CalculatorInputError, ScoreResult
from envs.core.tools import ToolDefinition, parse_google_docstring

from .examples import VALID

# Names and argument names fixed by the requirement (more arguments with defaults are allowed).
REQUIRED = {
    "calculate_gcs": ["eye", "verbal", "motor"],
    "calculate_qsofa": ["respiratory_rate", "systolic_bp", "altered_mentation"],
    "calculate_sirs": ["temperature_c", "heart_rate", "respiratory_rate", "wbc_k_per_ul"],
    "calculate_curb65": ["confusion", "bun_mg_dl", "respiratory_rate", "systolic_bp", "diastolic_bp", "age"],
    "calculate_news2": [
        "respiratory_rate",
        "spo2",
        "on_supplemental_oxygen",
        "temperature_c",
        "systolic_bp",
        "heart_rate",
        "consciousness",
    ],
    "calculate_sofa": [
        "pao2_fio2_ratio",
        "on_mechanical_ventilation",
        "platelets_k_per_ul",
        "bilirubin_mg_dl",
        "map_mmhg",
        "gcs",
        "creatinine_mg_dl",
    ],
    "calculate_apache2": None,
    "calculate_heart_score": [
        "history",
        "ecg",
        "age",
        "risk_factor_count",
        "atherosclerotic_disease",
        "troponin_x_uln",
    ],
    "calculate_wells_pe": [
        "clinical_signs_dvt",
        "pe_most_likely",
        "heart_rate",
        "immobilization_or_recent_surgery",
        "previous_dvt_pe",
        "hemoptysis",
        "malignancy",
    ],
    "calculate_wells_dvt": None,
    "calculate_cha2ds2_vasc": [
        "age",
        "sex",
        "chf",
        "hypertension",
        "diabetes",
        "stroke_tia_thromboembolism",
        "vascular_disease",
    ],
    "calculate_has_bled": None,
    "calculate_meld_na": ["bilirubin_mg_dl", "inr", "creatinine_mg_dl", "sodium_mmol_l", "on_dialysis"],
    "calculate_child_pugh": ["bilirubin_mg_dl", "albumin_g_dl", "inr", "ascites", "encephalopathy"],
    "calculate_esi_level": None,
    "calculate_bishop_score": ["dilation_cm", "effacement_percent", "station", "consistency", "position"],
    "calculate_apgar": ["heart_rate", "respiratory_effort", "muscle_tone", "reflex_irritability", "color"],
    "calculate_biophysical_profile": None,
    "administer_phq9": ["responses"],
    "administer_gad7": ["responses"],
    "assess_suicide_risk": None,
    "calculate_timi_ua": None,
    "calculate_centor": None,
    "calculate_perc": None,
    "calculate_creatinine_clearance": ["age", "weight_kg", "creatinine_mg_dl", "sex"],
    "calculate_ckd_epi_2021": ["creatinine_mg_dl", "age", "sex"],
    "calculate_bmi": ["weight_kg", "height_cm"],
    "calculate_map": ["systolic_bp", "diastolic_bp"],
    "calculate_anion_gap": ["sodium", "chloride", "bicarbonate"],
    "calculate_corrected_calcium": ["calcium_mg_dl", "albumin_g_dl"],
    "calculate_qtc": ["qt_ms", "heart_rate", "formula"],
    "calculate_tirads": ["composition", "echogenicity", "shape", "margin", "echogenic_foci"],
    "fleischner_recommendation": ["nodule_type", "size_mm", "multiple", "risk"],
    "calculate_birads": None,
    "calculate_lung_rads": None,
    "calculate_revised_trauma_score": ["gcs", "systolic_bp", "respiratory_rate"],
    "calculate_parkland": ["weight_kg", "tbsa_percent"],
    "calculate_aa_gradient": None,
    "calculate_fena": None,
}

# (function, argument, invalid value) - one or more per calculator, including the requirement's examples.
INVALID = [
    ("calculate_gcs", "eye", 5),
    ("calculate_gcs", "motor", 0),
    ("calculate_gcs", "verbal", 4.5),
    ("calculate_gcs", "eye", True),
    ("calculate_gcs", "eye", "4"),
    ("calculate_qsofa", "respiratory_rate", -1),
    ("calculate_qsofa", "altered_mentation", 1),
    ("calculate_sirs", "heart_rate", -5),
    ("calculate_sirs", "temperature_c", float("nan")),
    ("calculate_news2", "consciousness", "confused"),
    ("calculate_news2", "spo2", 101),
    ("calculate_news2", "spo2_scale", 3),
    ("calculate_sofa", "gcs", 16),
    ("calculate_sofa", "platelets_k_per_ul", -1),
    ("calculate_apache2", "fio2", 0.1),
    ("calculate_apache2", "admission_type", "surgical"),
    ("calculate_shock_index", "systolic_bp", 0),
    ("calculate_aa_gradient", "fio2", 1.5),
    ("calculate_curb65", "age", 17),
    ("calculate_curb65", "bun_mg_dl", float("inf")),
    ("calculate_crb65", "confusion", None),
    ("calculate_wells_pe", "heart_rate", -1),
    ("calculate_wells_pe", "model", "four_tier"),
    ("calculate_perc", "spo2", 120),
    ("calculate_pesi", "sex", "unknown"),
    ("calculate_spesi", "age", 150),
    ("calculate_heart_score", "history", "very"),
    ("calculate_heart_score", "troponin_x_uln", -0.1),
    ("calculate_timi_ua", "cad_risk_factor_count", 6),
    ("calculate_cha2ds2_vasc", "sex", "F"),
    ("calculate_has_bled", "labile_inr", "yes"),
    ("calculate_wells_dvt", "previous_dvt", 0),
    ("calculate_qtc", "formula", "rautaharju"),
    ("calculate_qtc", "heart_rate", 0),
    ("calculate_map", "systolic_bp", 10),
    ("calculate_meld_na", "inr", 0),
    ("calculate_meld_na", "on_dialysis", "no"),
    ("calculate_child_pugh", "ascites", "severe"),
    ("calculate_glasgow_blatchford", "hemoglobin_g_dl", 0),
    ("calculate_creatinine_clearance", "weight_kg", -70),
    ("calculate_ckd_epi_2021", "creatinine_mg_dl", 0),
    ("calculate_bedside_schwartz", "age", 25),
    ("calculate_fena", "serum_sodium_mmol_l", 0),
    ("calculate_free_water_deficit", "target_sodium_mmol_l", 100),
    ("calculate_bmi", "height_cm", 0),
    ("calculate_anion_gap", "chloride", -1),
    ("calculate_corrected_calcium", "albumin_g_dl", 0),
    ("calculate_corrected_sodium", "formula", "kats"),
    ("calculate_serum_osmolality", "bun_mg_dl", 0),
    ("calculate_esi_level", "expected_resources", -1),
    ("calculate_esi_level", "age_years", -1),
    ("calculate_centor", "age", 2),
    ("calculate_revised_trauma_score", "gcs", 2),
    ("calculate_parkland", "tbsa_percent", 101),
    ("calculate_alvarado", "neutrophil_percent", 101),
    ("calculate_ottawa_ankle", "malleolar_pain", "yes"),
    ("calculate_nihss", "motor_arm_left", 5),
    ("calculate_abcd2", "clinical_features", "weakness"),
    ("calculate_bishop_score", "effacement_percent", 140),
    ("calculate_bishop_score", "station", 6),
    ("calculate_bishop_score", "consistency", "hard"),
    ("calculate_apgar", "color", "blue"),
    ("calculate_apgar", "heart_rate", -1),
    ("calculate_biophysical_profile", "body_movements_count", -1),
    ("administer_phq9", "responses", [1, 1, 1]),
    ("administer_phq9", "responses", [0, 0, 0, 0, 0, 0, 0, 0, 4]),
    ("administer_gad7", "responses", "0000000"),
    ("assess_suicide_risk", "suicidal_behavior", "recent"),
    ("administer_epds", "responses", [0] * 9 + [True]),
    ("administer_audit_c", "responses", [5, 0, 0]),
    ("administer_cage", "guilty", 1),
    ("calculate_ciwa_ar", "orientation", 5),
    ("calculate_tirads", "echogenic_foci", "punctate"),
    ("calculate_tirads", "shape", "round"),
    ("calculate_birads", "calcification_morphology", "pleomorphic"),
    ("fleischner_recommendation", "size_mm", 31),
    ("fleischner_recommendation", "risk", "medium"),
    ("calculate_lung_rads", "context", "follow_up"),
]


def test_at_least_forty_instruments_and_exports():
    assert len(CALCULATORS) >= 40
    for name, fn in CALCULATORS.items():
        assert fn.__name__ == name and getattr(C, name) is fn and name in C.__all__
    assert set(VALID) == set(CALCULATORS), set(CALCULATORS) ^ set(VALID)


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_required_names_and_arguments(name):
    fn = CALCULATORS[name]
    params = list(inspect.signature(fn).parameters.values())
    if REQUIRED[name] is not None:
        assert [p.name for p in params[: len(REQUIRED[name])]] == REQUIRED[name]
        for extra in params[len(REQUIRED[name]) :]:
            assert extra.default is not inspect.Parameter.empty, (
                f"{name}: extra argument {extra.name} needs a default"
            )


@pytest.mark.parametrize("name", sorted(CALCULATORS))
def test_typed_and_documented_for_the_tool_framework(name):
    fn = CALCULATORS[name]
    hints = typing.get_type_hints(fn)
    assert hints["return"] is ScoreResult
    description, arg_docs = parse_google_docstring(fn.__doc__)
    assert description.endswith(".") and len(description.split(". ")) == 1, description
    for pname in inspect.signature(fn).parameters:
        assert pname in hints, f"{name}.{pname} is not annotated"
        assert arg_docs.get(pname), f"{name}: Args section does not describe {pname}"
    tool = ToolDefinition.from_function(fn)
    assert tool.name == name and tool.description == description
    for pname, schema in tool.parameters["properties"].items():
        assert schema.get("description"), (name, pname)
    # The framework's argument model accepts the valid example unchanged.
    tool.args_model(**VALID[name])


@pytest.mark.parametrize("name", sorted(CALCULATORS))
def test_result_shape_and_round_trip(name):
    result = CALCULATORS[name](**VALID[name])
    assert isinstance(result, ScoreResult)
    assert isinstance(result.score, (int, float)) and not isinstance(result.score, bool)
    assert math.isfinite(result.score)
    assert result.category and result.interpretation and result.reference and result.instrument
    assert isinstance(result.components, dict) and result.components
    # make_result skips validation: a full validation of the dump must give the same object.
    assert ScoreResult.model_validate(result.model_dump()) == result
    assert ScoreResult.model_validate_json(result.model_dump_json()) == result
    with pytest.raises(Exception):
        result.score = 0  # frozen


@pytest.mark.parametrize("name,argument,value", INVALID, ids=[f"{n}-{a}-{v!r}" for n, a, v in INVALID])
def test_invalid_inputs_raise_named_errors(name, argument, value):
    kwargs = dict(VALID[name], **{argument: value})
    with pytest.raises(CalculatorInputError) as info:
        CALCULATORS[name](**kwargs)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.function == name and err.argument == argument
    assert str(err).startswith(f"{name}: argument '{argument}' must be ")
    assert str(err).endswith(f"got {value!r}")


def test_error_messages_from_the_requirement():
    with pytest.raises(
        CalculatorInputError, match=r"^calculate_gcs: argument 'eye' must be an integer in 1\.\.4, got 5$"
    ):
        C.calculate_gcs(eye=5, verbal=5, motor=6)
    with pytest.raises(
        CalculatorInputError, match=r"argument 'heart_rate' must be a number in 0\.\.350 beats/min, got -10"
    ):
        C.calculate_shock_index(heart_rate=-10, systolic_bp=120)
    with pytest.raises(
        CalculatorInputError, match=r"argument 'effacement_percent' must be a number in 0\.\.100 %, got 140"
    ):
        C.calculate_bishop_score(
            dilation_cm=3, effacement_percent=140, station=0, consistency="soft", position="mid"
        )
    with pytest.raises(ValueError, match=r"'consciousness' must be one of 'alert', 'new_confusion'"):
        C.calculate_news2(
            respiratory_rate=18,
            spo2=97,
            on_supplemental_oxygen=False,
            temperature_c=37,
            systolic_bp=120,
            heart_rate=80,
            consciousness="drowsy",
        )


def test_numpy_scalars_are_accepted():
    np = pytest.importorskip("numpy")
    assert C.calculate_gcs(np.int64(4), np.int64(5), np.int64(6)).score == 15
    assert C.calculate_bmi(np.float64(70.0), np.float32(175.0)).score == pytest.approx(22.857, abs=1e-3)


def test_missing_optional_measurements_are_reported():
    with pytest.raises(CalculatorInputError, match="arterial_ph"):
        C.calculate_apache2(**{k: v for k, v in VALID["calculate_apache2"].items() if k != "arterial_ph"})
    with pytest.raises(CalculatorInputError, match="aa_gradient_mmhg"):
        C.calculate_apache2(**{k: v for k, v in VALID["calculate_apache2"].items() if k != "paco2_mmhg"})


def test_docstrings_state_units_or_choices():
    """Every numeric argument's description states a range (and units where it has any)."""
    for name, fn in CALCULATORS.items():
        _, arg_docs = parse_google_docstring(fn.__doc__)
        hints = typing.get_type_hints(fn)
        for pname, text in arg_docs.items():
            hint = hints[pname]
            if hint in (int, float) or hint in (int | None, float | None):
                assert re.search(r"\d", text), f"{name}.{pname}: no range in {text!r}"
