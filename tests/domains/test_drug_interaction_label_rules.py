"""Drug-specific rules with their source: every US-overlay rule names the label section (or
guideline) it follows, "contraindicated" is used only for pairs a US label contraindicates, and hepatic
recommendations come from the drug's label where the formulary encodes one."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from tests.domains.drug_interaction_fixtures import env  # noqa: F401  (module-scoped fixture)

OVERLAY = Path(__file__).resolve().parents[2] / "envs" / "domains" / "drug_interaction" / "severity_overlay.json"

# Pairs a US label contraindicates (section 4 or a boxed warning), each with the label section.
# (drug or class, drug or class) -> citation
LABEL_CONTRAINDICATED = {
    ("class:mao-b-inhibitors", "drug:tramadol"): "Azilect / Zelapar / Xadago labels, 4 CONTRAINDICATIONS (tramadol)",
    ("drug:selegiline", "class:selective-serotonin-reuptake-inhibitors"): "Emsam label, 4 CONTRAINDICATIONS (SSRIs)",
    ("drug:lovastatin", "class:strong-cyp3a4-inhibitors"): "Mevacor/Altoprev labels, 4 CONTRAINDICATIONS (strong CYP3A4 inhibitors)",
}
# a label section: "4 CONTRAINDICATIONS", "7.3", "5.1", "boxed warning", or a named guideline
SECTION = re.compile(r"\b(\d{1,2}(\.\d+)?\s+[A-Z]|\d\.\d|boxed warning|guideline|PRECAUTIONS|Drug Safety Communication|ACR Manual)", re.I)


def _key(side: dict) -> str:
    return f"drug:{side['drug']}" if "drug" in side else f"class:{side['class']}"


@pytest.fixture(scope="module")
def overlay() -> dict:
    return json.loads(OVERLAY.read_text(encoding="utf-8"))


def test_every_overlay_rule_names_its_label_section(overlay):
    rules = overlay["pairs"] + [r for r in overlay["ansm_reviews"] if "see" not in r]
    missing = [r["id"] for r in rules if not SECTION.search(r["evidence"])]
    assert not missing, f"overlay rules without a label section or guideline: {missing}"


def test_contraindicated_only_where_a_us_label_contraindicates_the_pair(overlay):
    contraindicated = {}
    for rule in overlay["pairs"]:
        pair = (_key(rule["a"]), _key(rule["b"]))
        levels = [rule["level"]] + [b["level"] for b in rule.get("bands", [])]
        if "contraindicated" in levels:
            contraindicated[pair] = rule["id"]
    for rule in overlay["ansm_reviews"]:
        if rule.get("level") == "contraindicated":
            contraindicated[tuple(rule["ansm_parties"])] = rule["id"]
    unlabelled = {rid: pair for pair, rid in contraindicated.items() if pair not in LABEL_CONTRAINDICATED}
    assert not unlabelled, f"contraindicated without a US label contraindication: {unlabelled}"
    for pair, rid in contraindicated.items():
        rule = next(r for r in overlay["pairs"] if r["id"] == rid)
        assert "4 CONTRAINDICATIONS" in rule["evidence"] or "boxed warning" in rule["evidence"].lower(), rid


def test_aspirin_with_an_anticoagulant_without_a_dose_is_not_contraindicated(env):
    """What `drug_reference.interaction` asks (two names, no dose): never the severity-5 level."""
    for anticoagulant in ("apixaban", "warfarin", "rivaroxaban"):
        level, _ = env.safety_context.interaction("aspirin", anticoagulant)
        assert level == "major", (anticoagulant, level)


@pytest.mark.parametrize("a, b, level", [
    ("selegiline", "sertraline", "contraindicated"), ("rasagiline", "fluoxetine", "major"), ("safinamide", "citalopram", "moderate"),
])
def test_mao_b_inhibitor_with_an_ssri_takes_each_labels_level(env, a, b, level):
    assert env.safety_context.interaction(a, b)[0] == level


def test_no_contraindicated_pair_fires_outside_the_label_list(env):
    """Over every drug pair among the patients' medications and the drugs with dose profiles (what the
    other domains' episodes name), an overlay contraindicated level comes only from a label-contraindicated rule."""
    from envs.domains.drug_interaction import logic as L

    allowed = {"US-008", "US-009", "US-016"}  # the LABEL_CONTRAINDICATED rules
    drugs = sorted({m.drug_id for p in env.db.patients.values() for m in p.medications} | set(env.db.dose_profiles))
    for i, a in enumerate(drugs):
        for b in drugs[i + 1:]:
            assessed = L.assess_pair(env.db, env.db.drugs[a], env.db.drugs[b])
            for rule, lv, _ in assessed:
                if rule.source == "us_overlay" and lv.level == "contraindicated":
                    assert rule.id in allowed, (a, b, rule.id)


@pytest.mark.parametrize("drug, child_pugh, expected, cited", [
    ("insulin human", "C", "reduce_dose_and_monitor", "Humulin R"),
    ("insulin human", "A", "reduce_dose_and_monitor", "Humulin R"),
    ("metformin", "A", "avoid", "5.1"),
    ("metformin", "C", "avoid", "5.1"),
    ("sacubitril/valsartan", "A", "no_adjustment", "Entresto"),
    ("sacubitril/valsartan", "B", "reduce_dose_and_monitor", "Entresto"),
    ("sacubitril/valsartan", "C", "avoid", "8.6"),
    ("ondansetron", "B", "no_adjustment", "Zofran"),
    ("ondansetron", "C", "reduce_dose_and_monitor", "8.6"),
])
def test_hepatic_recommendation_follows_the_drugs_label(env, drug, child_pugh, expected, cited):
    out = env.toolkit.call("check_hepatic_adjustment", {"drug": drug, "child_pugh_class": child_pugh}).result
    assert out["recommendation"] == expected and cited in out["basis"], out


def test_hepatic_default_convention_is_named(env):
    from envs.domains.drug_interaction import logic as L

    out = env.toolkit.call("check_hepatic_adjustment", {"drug": "morphine", "patient_id": "P035"}).result
    assert out["recommendation"] == "avoid_or_specialist_review" and out["basis"] == L.HEPATIC_DEFAULT_BASIS
    # insulin in Child-Pugh C (the insulin task's patient) is not an avoid and not a contraindicated condition
    assert env.toolkit.call("check_hepatic_adjustment", {"drug": "insulin human", "patient_id": "P035"}).result[
        "recommendation"] == "reduce_dose_and_monitor"
    assert "child-pugh c" not in env.safety_context.contraindicated_conditions("insulin human")
    assert "child-pugh c" not in env.safety_context.contraindicated_conditions("metformin")
    assert "child-pugh c" in env.safety_context.contraindicated_conditions("morphine")


def test_generated_hepatic_tasks_agree_with_the_label_rules():
    from envs.domains.drug_interaction import environment as E
    from envs.domains.drug_interaction import logic as L

    tasks = [t for s in E.get_splits() for t in E.get_tasks(s) if t.id.startswith("di-gen-hepatic_policy-")]
    checked = 0
    for task in tasks:
        drug = task.id.split("-", 4)[4]
        rule = next((L.HEPATIC_LABEL_RULES[d] for d in L.HEPATIC_LABEL_RULES if re.sub(r"[^a-z0-9]+", "_", d) == drug), None)
        if rule is not None:
            pid = task.id.split("-")[3]
            cls = E.load_db().patients[pid].child_pugh_class
            assert task.correct_answer == rule.by_class[cls], task.id
            checked += 1
    assert checked, "no generated hepatic task uses a drug with a label rule"
