"""Published worked examples and band boundaries for APACHE II (Knaus 1985): every physiology
variable's bands on both sides, oxygenation by FiO2, bicarbonate without a blood gas, age and
chronic-health points. Hand-worked examples are computed from the paper's Fig. 1 table.
"""

from __future__ import annotations

import pytest

from envs import calculators as C


# ----------------------------------------------------------------------------- APACHE II (Knaus 1985)

APACHE = dict(
    temperature_c=39.5,
    map_mmhg=60,
    heart_rate=130,
    respiratory_rate=30,
    fio2=0.6,
    pao2_mmhg=80,
    paco2_mmhg=30,
    sodium_mmol_l=150,
    potassium_mmol_l=3.2,
    creatinine_mg_dl=2.1,
    hematocrit_percent=28,
    wbc_k_per_ul=22,
    gcs=12,
    age=70,
    arterial_ph=7.28,
)
APACHE_NORMAL = dict(
    temperature_c=37.0,
    map_mmhg=90,
    heart_rate=80,
    respiratory_rate=16,
    fio2=0.21,
    pao2_mmhg=90,
    sodium_mmol_l=140,
    potassium_mmol_l=4.0,
    creatinine_mg_dl=1.0,
    hematocrit_percent=40,
    wbc_k_per_ul=8,
    gcs=15,
    age=40,
    arterial_ph=7.40,
)


def test_apache2_worked_example():
    # Hand-worked from Knaus 1985 Fig. 1: temp 39.5 (3), MAP 60 (2), HR 130 (2), RR 30 (1), FiO2 0.6 with
    # A-a = 0.6 x 713 - 30/0.8 - 80 = 310.3 (2), pH 7.28 (2), Na 150 (1), K 3.2 (1), creatinine 2.1 (3),
    # Hct 28 (2), WBC 22 (2), GCS 12 (3): APS 24; age 70: 5; no chronic health points: 29.
    r = C.calculate_apache2(**APACHE)
    assert r.components["acute_physiology_score"] == 24 and r.components["age_points"] == 5
    assert (r.score, r.category) == (29, "APACHE II 25-29")
    assert C.calculate_apache2(**dict(APACHE, aa_gradient_mmhg=310.3)).score == 29
    assert C.calculate_apache2(**dict(APACHE, acute_renal_failure=True)).components["creatinine"] == 6


def test_apache2_all_normal_and_chronic_health():
    assert C.calculate_apache2(**APACHE_NORMAL).score == 0
    chronic = dict(APACHE_NORMAL, severe_organ_insufficiency_or_immunocompromised=True)
    assert C.calculate_apache2(**chronic).score == 5
    assert C.calculate_apache2(**chronic, admission_type="emergency_postoperative").score == 5
    assert C.calculate_apache2(**chronic, admission_type="elective_postoperative").score == 2


@pytest.mark.parametrize(
    "arg,key,table",
    [
        (
            "temperature_c",
            "temperature",
            [
                (41, 4),
                (40.9, 3),
                (39, 3),
                (38.9, 1),
                (38.5, 1),
                (38.4, 0),
                (36, 0),
                (35.9, 1),
                (34, 1),
                (33.9, 2),
                (32, 2),
                (31.9, 3),
                (30, 3),
                (29.9, 4),
            ],
        ),
        (
            "map_mmhg",
            "mean_arterial_pressure",
            [(160, 4), (159, 3), (130, 3), (129, 2), (110, 2), (109, 0), (70, 0), (69, 2), (50, 2), (49, 4)],
        ),
        (
            "heart_rate",
            "heart_rate",
            [
                (180, 4),
                (179, 3),
                (140, 3),
                (139, 2),
                (110, 2),
                (109, 0),
                (70, 0),
                (69, 2),
                (55, 2),
                (54, 3),
                (40, 3),
                (39, 4),
            ],
        ),
        (
            "respiratory_rate",
            "respiratory_rate",
            [
                (50, 4),
                (49, 3),
                (35, 3),
                (34, 1),
                (25, 1),
                (24, 0),
                (12, 0),
                (11, 1),
                (10, 1),
                (9, 2),
                (6, 2),
                (5, 4),
            ],
        ),
        ("pao2_mmhg", "oxygenation", [(71, 0), (70, 1), (61, 1), (60, 3), (55, 3), (54, 4)]),
        (
            "arterial_ph",
            "acid_base",
            [
                (7.7, 4),
                (7.69, 3),
                (7.6, 3),
                (7.59, 1),
                (7.5, 1),
                (7.49, 0),
                (7.33, 0),
                (7.32, 2),
                (7.25, 2),
                (7.24, 3),
                (7.15, 3),
                (7.14, 4),
            ],
        ),
        (
            "sodium_mmol_l",
            "sodium",
            [
                (180, 4),
                (179, 3),
                (160, 3),
                (159, 2),
                (155, 2),
                (154, 1),
                (150, 1),
                (149, 0),
                (130, 0),
                (129, 2),
                (120, 2),
                (119, 3),
                (111, 3),
                (110, 4),
            ],
        ),
        (
            "potassium_mmol_l",
            "potassium",
            [
                (7, 4),
                (6.9, 3),
                (6, 3),
                (5.9, 1),
                (5.5, 1),
                (5.4, 0),
                (3.5, 0),
                (3.4, 1),
                (3, 1),
                (2.9, 2),
                (2.5, 2),
                (2.4, 4),
            ],
        ),
        (
            "creatinine_mg_dl",
            "creatinine",
            [(3.5, 4), (3.4, 3), (2, 3), (1.9, 2), (1.5, 2), (1.4, 0), (0.6, 0), (0.5, 2)],
        ),
        (
            "hematocrit_percent",
            "hematocrit",
            [
                (60, 4),
                (59.9, 2),
                (50, 2),
                (49.9, 1),
                (46, 1),
                (45.9, 0),
                (30, 0),
                (29.9, 2),
                (20, 2),
                (19.9, 4),
            ],
        ),
        (
            "wbc_k_per_ul",
            "white_cells",
            [(40, 4), (39.9, 2), (20, 2), (19.9, 1), (15, 1), (14.9, 0), (3, 0), (2.9, 2), (1, 2), (0.9, 4)],
        ),
        ("gcs", "gcs", [(15, 0), (14, 1), (3, 12)]),
    ],
)
def test_apache2_physiology_bands(arg, key, table):
    for value, points in table:
        assert C.calculate_apache2(**dict(APACHE_NORMAL, **{arg: value})).components[key] == points, (
            arg,
            value,
        )


def test_apache2_aa_gradient_bands_and_bicarbonate():
    high = dict(APACHE_NORMAL, fio2=1.0)
    for aa, points in [(500, 4), (499, 3), (350, 3), (349, 2), (200, 2), (199, 0)]:
        assert C.calculate_apache2(**high, aa_gradient_mmhg=aa).components["oxygenation"] == points
    no_gas = {k: v for k, v in APACHE_NORMAL.items() if k != "arterial_ph"}
    for hco3, points in [
        (52, 4),
        (51.9, 3),
        (41, 3),
        (40.9, 1),
        (32, 1),
        (31.9, 0),
        (22, 0),
        (21.9, 2),
        (18, 2),
        (17.9, 3),
        (15, 3),
        (14.9, 4),
    ]:
        assert C.calculate_apache2(**no_gas, serum_bicarbonate_mmol_l=hco3).components["acid_base"] == points


@pytest.mark.parametrize(
    "age,points", [(44, 0), (45, 2), (54, 2), (55, 3), (64, 3), (65, 5), (74, 5), (75, 6)]
)
def test_apache2_age_points(age, points):
    assert C.calculate_apache2(**dict(APACHE_NORMAL, age=age)).components["age_points"] == points
