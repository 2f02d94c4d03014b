"""Pregnancy from labels, not letters: the formulary's pregnancy entries come from the US labels'
section 8.1 risk summary, section 4 or the FDA communication that changed the label; a letter only
where the FDA assigned one, with its date; drugdose's undated letters are reported as package data."""

from __future__ import annotations

import re

import pytest

from envs.domains.drug_interaction import logic as L
from tests.domains.drug_interaction_fixtures import env  # noqa: F401  (module-scoped fixture)

# a label section: "8.1", "4 CONTRAINDICATIONS", "WARNINGS", "boxed warning", or an FDA communication
SECTION = re.compile(r"\b(8\.1|4 CONTRAINDICATIONS|WARNINGS|boxed warning|Drug Safety Communication)\b", re.I)


@pytest.fixture(scope="module")
def tasks():
    from envs.domains.drug_interaction import environment as E

    return [t for s in E.get_splits() for t in E.get_tasks(s)]


def check(env, drug: str) -> dict:
    out = env.toolkit.call("check_pregnancy_safety", {"drug": drug})
    assert out.ok, out.error
    return out.result


def test_every_pregnancy_entry_names_its_source_section():
    for drug, rule in L.PREGNANCY_LABEL_RULES.items():
        assert SECTION.search(rule.section), f"{drug}: no label section in {rule.section!r}"
        assert rule.recommendation in L.PREGNANCY_RECOMMENDATIONS, drug
        assert rule.statement, drug
        # a letter only with the date the FDA assigned it
        assert (rule.letter is None) == (rule.letter_date is None), drug
        if rule.letter:
            assert rule.letter in L.PREGNANCY_CATEGORIES and re.fullmatch(r"\d{4}-\d{2}-\d{2}", rule.letter_date), drug


def test_every_reported_pregnancy_conclusion_names_its_source(env):
    for drug in sorted(set(env.db.dose_profiles) | set(L.PREGNANCY_LABEL_RULES)):
        out = check(env, drug)
        if drug in L.PREGNANCY_LABEL_RULES:
            assert SECTION.search(out["label_section"]) and out["risk_summary"], drug
        else:  # drugdose's undated letter, named as package data
            assert out["label_section"] is None and out["fda_category_date"] is None, drug
            assert out["basis"] == L.PACKAGE_LETTER_BASIS, drug


def test_magnesium_sulfate_is_category_d_since_2013_not_a(env, tasks):
    # FDA Drug Safety Communication, 30 May 2013: category A -> D (fetal hypocalcaemia and bone
    # abnormalities with continuous use beyond 5 to 7 days); drugdose 0.1.2 still says "A"
    assert env.db.dose_profiles["magnesium sulfate"].pregnancy_category == "A"
    out = check(env, "magnesium sulfate")
    assert out["fda_category"] == "D" and out["fda_category_date"] == "2013-05-30"
    assert "5 to 7 days" in out["risk_summary"] and out["recommendation"] != "acceptable"
    auth = next(t for t in tasks if t.id == "di-auth-05-pregnancy-magnesium")
    assert auth.correct_answer == "D" and "category A" not in " ".join(auth.evaluation_criteria.nl_assertions)
    for t in tasks:
        if "magnesium" in t.id and "pregnancy" in t.id:
            assert t.correct_answer != "A", t.id


def test_glucose_and_calcium_gluconate_carry_no_letter(env):
    # both labels are in PLLR format (8.1 risk summary, no letter): drugdose's "A" is not reported
    for drug in ("glucose", "calcium gluconate"):
        assert env.db.dose_profiles[drug].pregnancy_category == "A"
        out = check(env, drug)
        assert out["fda_category"] is None and "8.1" in out["label_section"], drug
    assert check(env, "glucose")["recommendation"] == "not_expected_to_cause_harm"
    assert check(env, "calcium gluconate")["recommendation"] == "risk_not_established"


def test_valproate_contraindication_is_limited_to_migraine_prophylaxis(env):
    # Depakote label 4: contraindicated in pregnant women for migraine prophylaxis; boxed warning otherwise
    out = check(env, "valproic acid")
    assert out["recommendation"] == "contraindicated_for_migraine_prophylaxis"
    assert out["contraindicated_for"] == "migraine prophylaxis" and "4 CONTRAINDICATIONS" in out["label_section"]
    ctx = env.safety_context
    assert "pregnancy" not in ctx.contraindicated_conditions("valproic acid")
    assert ctx.label_pregnancy_contraindication("valproic acid") is None
    # controls: labels that contraindicate the drug in every pregnancy still do
    for drug in ("lisinopril", "warfarin", "isotretinoin"):
        assert "pregnancy" in ctx.contraindicated_conditions(drug), drug


def test_generated_pregnancy_tasks_answer_from_the_table(env, tasks):
    letters = [t for t in tasks if t.id.startswith("di-gen-pregnancy_category-")]
    risks = {t.id: t for t in tasks if t.id.startswith("di-gen-pregnancy_label_risk-")}
    assert letters and len(risks) == len(L.PREGNANCY_LABEL_RULES)
    for t in letters:
        drug = t.evaluation_criteria.actions[0].arguments["drug"]
        rule = L.PREGNANCY_LABEL_RULES.get(drug)
        assert rule is None or rule.letter is not None, f"{t.id}: a letter asked for a drug whose label has none"
        assert t.correct_answer == check(env, drug)["fda_category"], t.id
    for t in risks.values():
        drug = t.evaluation_criteria.actions[0].arguments["drug"]
        assert t.correct_answer == L.PREGNANCY_LABEL_RULES[drug].recommendation == check(env, drug)["recommendation"]
