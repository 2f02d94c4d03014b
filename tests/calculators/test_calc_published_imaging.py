"""Published examples and boundaries: ACR TI-RADS (Tessler 2017), BI-RADS (ACR Atlas 5th ed.),
Fleischner 2017 (MacMahon 2017) and Lung-RADS v2022. No open-source peer implements these, so
the published charts are encoded case by case here.
"""

from __future__ import annotations

import pytest

from envs import calculators as C
from envs.calculators import CalculatorInputError


# ----------------------------------------------------------------------------- ACR TI-RADS


def tirads(
    comp="solid", echo="hypoechoic", shape="wider_than_tall", margin="smooth", foci=("none",), size=None
):
    return C.calculate_tirads(comp, echo, shape, margin, list(foci), max_diameter_cm=size)


def test_tirads_levels():
    assert (tirads().score, tirads().category) == (4, "TR4")  # solid 2 + hypoechoic 2
    worst = tirads(
        echo="very_hypoechoic",
        shape="taller_than_wide",
        margin="extrathyroidal_extension",
        foci=("punctate", "macrocalcifications", "peripheral_rim"),
    )
    assert (worst.score, worst.category) == (2 + 3 + 3 + 3 + 6, "TR5")
    assert tirads(comp="mixed", echo="isoechoic").category == "TR2"  # 2 points
    assert tirads(comp="mixed", echo="isoechoic", foci=("macrocalcifications",)).category == "TR3"  # 3
    assert tirads(comp="solid", echo="hyperechoic").category == "TR3"  # 3
    assert tirads(echo="very_hypoechoic", margin="lobulated_irregular").score == 7
    assert tirads(echo="very_hypoechoic", margin="lobulated_irregular").category == "TR5"
    assert tirads(echo="very_hypoechoic", foci=("macrocalcifications",)).category == "TR4"  # 6
    assert tirads(comp="cystic", echo="anechoic").category == "TR1"  # 0
    assert tirads(comp="cystic", echo="anechoic", foci=("large_comet_tail",)).category == "TR1"
    assert tirads(comp="cystic", echo="anechoic", foci=("macrocalcifications",)).category == "TR2"  # 1 point


def test_tirads_spongiform_scores_zero():
    r = tirads(comp="spongiform", echo="isoechoic", foci=("macrocalcifications",))
    assert (r.score, r.category) == (0, "TR1")


@pytest.mark.parametrize(
    "level_kwargs,fna,follow",
    [
        (dict(comp="solid", echo="hyperechoic"), 2.5, 1.5),  # TR3
        (dict(), 1.5, 1.0),  # TR4
        (dict(echo="very_hypoechoic", margin="lobulated_irregular"), 1.0, 0.5),  # TR5
    ],
)
def test_tirads_size_thresholds(level_kwargs, fna, follow):
    assert "FNA recommended" in tirads(**level_kwargs, size=fna).components["recommendation"]
    below_fna = tirads(**level_kwargs, size=round(fna - 0.1, 1)).components["recommendation"]
    assert below_fna.startswith("follow-up")
    assert tirads(**level_kwargs, size=follow).components["recommendation"].startswith("follow-up")
    assert (
        tirads(**level_kwargs, size=round(follow - 0.1, 1)).components["recommendation"].startswith("no FNA")
    )
    assert "give the size" in tirads(**level_kwargs).components["recommendation"]


def test_tirads_invalid_foci():
    for bad in (["none", "punctate"], [], ["punctate", "punctate"], ["microcalcifications"], "punctate"):
        with pytest.raises(CalculatorInputError, match="'echogenic_foci'"):
            tirads(foci=bad) if not isinstance(bad, str) else C.calculate_tirads(
                "solid", "hypoechoic", "wider_than_tall", "smooth", bad
            )


# ----------------------------------------------------------------------------- BI-RADS (ACR Atlas 5th ed.)


@pytest.mark.parametrize(
    "kwargs,category,score",
    [
        (dict(), "BI-RADS 1", 1),
        (dict(calcification_morphology="typically_benign"), "BI-RADS 2", 2),
        (dict(mass_shape="oval", mass_margin="circumscribed", mass_typically_benign=True), "BI-RADS 2", 2),
        (dict(mass_shape="oval", mass_margin="circumscribed"), "BI-RADS 3", 3),
        (dict(mass_shape="round", mass_margin="circumscribed", mass_stable_2_years=True), "BI-RADS 2", 2),
        (dict(mass_shape="oval", mass_margin="obscured"), "BI-RADS 0", 0),
        (dict(mass_shape="oval", mass_margin="indistinct"), "BI-RADS 4", 4),
        (dict(mass_shape="irregular", mass_margin="circumscribed"), "BI-RADS 4", 4),
        (dict(mass_shape="irregular", mass_margin="spiculated"), "BI-RADS 5", 5),
        (dict(calcification_morphology="coarse_heterogeneous"), "BI-RADS 4B", 4),  # PPV 13 %
        (dict(calcification_morphology="amorphous"), "BI-RADS 4B", 4),  # PPV 21 %
        (dict(calcification_morphology="fine_pleomorphic"), "BI-RADS 4B", 4),  # PPV 29 %
        (dict(calcification_morphology="fine_linear_branching"), "BI-RADS 4C", 4),  # PPV 70 %
        (dict(architectural_distortion=True), "BI-RADS 4", 4),
        (dict(exam_complete=False), "BI-RADS 0", 0),
        (
            dict(known_biopsy_proven_malignancy=True, mass_shape="irregular", mass_margin="spiculated"),
            "BI-RADS 6",
            6,
        ),
    ],
)
def test_birads_categories(kwargs, category, score):
    r = C.calculate_birads(**kwargs)
    assert (r.category, r.score) == (category, score)


def test_birads_most_suspicious_finding_wins():
    r = C.calculate_birads(
        mass_shape="oval", mass_margin="circumscribed", calcification_morphology="amorphous"
    )
    assert r.category == "BI-RADS 4B" and r.components["mass"] == "3"
    r = C.calculate_birads(
        mass_shape="oval", mass_margin="obscured", calcification_morphology="fine_linear_branching"
    )
    assert r.category == "BI-RADS 4C"
    with pytest.raises(CalculatorInputError, match="'mass_margin' must be 'none' exactly when mass_shape"):
        C.calculate_birads(mass_shape="oval")


# ----------------------------------------------------------------------------- Fleischner 2017


@pytest.mark.parametrize(
    "kind,size,multiple,risk,cat",
    [
        ("solid", 5, False, "low", "no routine follow-up"),
        ("solid", 5, False, "high", "optional CT at 12 months"),
        ("solid", 5.4, False, "low", "no routine follow-up"),  # rounds to 5
        ("solid", 5.5, False, "low", "CT at 6-12 months"),  # rounds to 6
        ("solid", 8, False, "high", "CT at 6-12 months"),
        ("solid", 8.4, False, "low", "CT at 6-12 months"),  # rounds to 8
        ("solid", 8.5, False, "low", "CT at 3 months, PET/CT or tissue sampling"),  # rounds to 9
        ("solid", 5, True, "high", "optional CT at 12 months"),
        ("solid", 7, True, "low", "CT at 3-6 months"),
        ("solid", 12, True, "high", "CT at 3-6 months"),
        ("ground_glass", 5, False, "high", "no routine follow-up"),
        ("ground_glass", 6, False, "low", "CT at 6-12 months"),
        ("part_solid", 5, False, "low", "no routine follow-up"),
        ("part_solid", 6, False, "low", "CT at 3-6 months"),
        ("ground_glass", 4, True, "low", "CT at 3-6 months"),
        ("part_solid", 10, True, "low", "CT at 3-6 months"),
    ],
)
def test_fleischner_table(kind, size, multiple, risk, cat):
    r = C.fleischner_recommendation(kind, size, multiple, risk)
    assert r.category == cat


def test_fleischner_texts():
    low = C.fleischner_recommendation("solid", 7, False, "low")
    high = C.fleischner_recommendation("solid", 7, False, "high")
    assert "then consider CT at 18-24 months" in low.interpretation
    assert "then CT at 18-24 months" in high.interpretation and "consider" not in high.interpretation
    gg = C.fleischner_recommendation("ground_glass", 10, False, "low")
    assert "every 2 years until 5 years" in gg.interpretation and gg.components["risk_applied"] is None
    assert (
        "annual CT for 5 years" in C.fleischner_recommendation("part_solid", 10, False, "low").interpretation
    )
    assert "2 and 4 years" in C.fleischner_recommendation("ground_glass", 5, True, "low").interpretation
    with pytest.raises(CalculatorInputError, match="'size_mm' must be a number in 1..30"):
        C.fleischner_recommendation("solid", 35, False, "low")


# ----------------------------------------------------------------------------- Lung-RADS v2022


@pytest.mark.parametrize(
    "kind,size,solid,context,cat",
    [
        ("solid", 5.9, 0, "baseline", "2"),
        ("solid", 6.0, 0, "baseline", "3"),
        ("solid", 7.9, 0, "baseline", "3"),
        ("solid", 8.0, 0, "baseline", "4A"),
        ("solid", 14.9, 0, "baseline", "4A"),
        ("solid", 15.0, 0, "baseline", "4B"),
        ("solid", 3.9, 0, "new", "2"),
        ("solid", 4.0, 0, "new", "3"),
        ("solid", 5.9, 0, "new", "3"),
        ("solid", 6.0, 0, "new", "4A"),
        ("solid", 7.9, 0, "new", "4A"),
        ("solid", 8.0, 0, "new", "4B"),
        ("solid", 7.9, 0, "growing", "4A"),
        ("solid", 8.0, 0, "growing", "4B"),
        ("part_solid", 5.9, 3, "baseline", "2"),
        ("part_solid", 8.0, 5.9, "baseline", "3"),
        ("part_solid", 8.0, 6.0, "baseline", "4A"),
        ("part_solid", 9.0, 7.9, "baseline", "4A"),
        ("part_solid", 9.0, 8.0, "baseline", "4B"),
        ("part_solid", 5.9, 2, "new", "3"),
        ("part_solid", 8.0, 3.9, "new", "4A"),
        ("part_solid", 8.0, 4.0, "new", "4B"),
        ("part_solid", 8.0, 3.0, "growing", "4A"),
        ("part_solid", 8.0, 4.0, "growing", "4B"),
        ("ground_glass", 29.9, 0, "baseline", "2"),
        ("ground_glass", 30.0, 0, "baseline", "3"),
        ("ground_glass", 30.0, 0, "new", "3"),
        ("ground_glass", 20.0, 0, "growing", "2"),
        ("perifissural", 9.9, 0, "baseline", "2"),
        ("perifissural", 10.0, 0, "baseline", "4A"),
    ],
)
def test_lung_rads_nodules(kind, size, solid, context, cat):
    r = C.calculate_lung_rads(kind, size_mm=size, solid_component_mm=solid, context=context)
    assert r.category == cat
    assert r.score == int(cat[0])


def test_lung_rads_other_categories():
    assert C.calculate_lung_rads("none").category == "1"
    assert C.calculate_lung_rads("benign_calcified_or_fat").category == "1"
    assert C.calculate_lung_rads("solid", size_mm=12, incomplete=True).category == "0"
    assert C.calculate_lung_rads("airway_subsegmental").category == "2"
    assert C.calculate_lung_rads("airway_segmental_or_proximal").category == "4A"
    assert C.calculate_lung_rads("airway_segmental_or_proximal", context="stable").category == "4B"
    assert C.calculate_lung_rads("solid", size_mm=7, context="stable", prior_category="3").category == "2"
    assert C.calculate_lung_rads("solid", size_mm=9, context="stable", prior_category="4A").category == "3"
    assert C.calculate_lung_rads("solid", size_mm=9, suspicious_features=True).category == "4X"
    assert (
        C.calculate_lung_rads("solid", size_mm=5, suspicious_features=True).category == "2"
    )  # 4X only from 3/4
    s = C.calculate_lung_rads("solid", size_mm=5, significant_other_finding=True)
    assert s.category == "2S" and "significant other finding" in s.interpretation
    assert "6 months" in C.calculate_lung_rads("solid", size_mm=7).interpretation
    assert "3 months" in C.calculate_lung_rads("solid", size_mm=9).interpretation


def test_lung_rads_invalid():
    with pytest.raises(CalculatorInputError, match="'prior_category' must be given"):
        C.calculate_lung_rads("solid", size_mm=7, context="stable")
    with pytest.raises(CalculatorInputError, match="'size_mm' must be > 0 mm"):
        C.calculate_lung_rads("solid")
    with pytest.raises(CalculatorInputError, match="'solid_component_mm' must be > 0 and <= size_mm"):
        C.calculate_lung_rads("part_solid", size_mm=8, solid_component_mm=9)
