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
    ("drug:linezolid", "class:selective-serotonin-reuptake-inhibitors"): "Zoloft, Lexapro, Celexa, Prozac, Paxil labels, 4 CONTRAINDICATIONS (MAOIs, linezolid named)",
    ("drug:naltrexone", "class:opioid-agonist-analgesics"): "naltrexone tablets CONTRAINDICATIONS, Vivitrol 4 (patients receiving opioid analgesics)",
    ("drug:linezolid", "drug:venlafaxine"): "Effexor XR label, 4 CONTRAINDICATIONS (MAOIs, linezolid named)",
    ("drug:linezolid", "drug:duloxetine"): "Cymbalta label, 4 CONTRAINDICATIONS (MAOIs, linezolid named)",
}
# the overlay rules that grade those pairs
LABEL_CONTRAINDICATED_RULES = {"US-008", "US-009", "US-016", "US-021", "US-023", "US-024", "US-025"}
# a label section: "4 CONTRAINDICATIONS", "7.3", "5.1", "boxed warning", or a named guideline
SECTION = re.compile(r"\b(\d{1,2}(\.\d+)?\s+[A-Z]|\d\.\d|boxed warning|guideline|PRECAUTIONS|WARNINGS|CONTRAINDICATIONS|"
                     r"Drug Safety Communication|ACR Manual)", re.I)


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


# Brilinta 7: avoid strong CYP3A inhibitors; those its list names that the formulary holds. Its section 4 names
# none (nor does Norvir's table of contraindicated drugs): ANSM-1249's "contraindicated" is re-rated major.
BRILINTA_NAMED_INHIBITORS = ("ritonavir", "clarithromycin", "ketoconazole", "itraconazole", "voriconazole",
                             "telithromycin", "saquinavir", "atazanavir")


def test_ticagrelor_with_a_strong_cyp3a_inhibitor_takes_the_brilinta_level(env):
    from envs.core.task import Task
    from envs.rewards import detect_violations
    from tests.rewards.builders import call, episode, turn

    for inhibitor in BRILINTA_NAMED_INHIBITORS:
        level, why = env.safety_context.interaction("ticagrelor", inhibitor)
        assert level == "major" and why.split(":")[0] in ("US-026", "US-027", "US-028"), (inhibitor, level, why)
    # ticagrelor ordered on ritonavir after the check: no severity-5 interaction pattern (it was capped at 0.1)
    task = Task(ticket="Patient currently on ritonavir.", patient_id="P1", domain="drug_interaction")
    traj = episode(task, turn(call("check_interaction", {"drug_a": "ritonavir", "drug_b": "ticagrelor"}, result="checked")),
                   turn(call("add_medication", {"patient_id": "P1", "drug": "ticagrelor"}, result="added")),
                   answer="ticagrelor added with ritonavir; interaction risk acknowledged, monitor.")
    violations, errors = detect_violations(traj, task, env.safety_context)
    assert errors == [] and not [v.pattern_id for v in violations if v.severity >= 5], violations


def _authored(task_id: str):
    from envs.domains.drug_interaction import environment as E

    return next(t for s in E.get_splits() for t in E.get_tasks(s) if t.id == task_id)


def test_citalopram_with_methadone_takes_the_celexa_level_and_simvastatin_with_ritonavir_stays_contraindicated(env):
    """Celexa's labelling (FDA DSC 2012, USPI 5.2) does not recommend citalopram with other QT-prolonging drugs
    and neither its section 4 nor methadone's names the other: US-029 re-rates ANSM's contraindication to major,
    and the authored task answers so. Zocor 4 and Norvir's contraindicated-drug table do name the statin pair
    (control: it stays contraindicated, and its task cites those sections)."""
    level, why = env.safety_context.interaction("methadone", "citalopram")
    assert level == "major" and why.startswith("US-029"), why
    qt = _authored("di-auth-21-methadone-citalopram")
    assert qt.correct_answer == "major" and "US-029" in qt.description.provenance["guideline"]
    assert not any("contraindicated" in a for a in qt.evaluation_criteria.nl_assertions)
    statin_level, statin_why = env.safety_context.interaction("simvastatin", "ritonavir")
    assert statin_level == "contraindicated", statin_why
    statin = _authored("di-auth-15-statin-ritonavir")
    assert "Zocor (simvastatin) USPI 4 CONTRAINDICATIONS" in statin.description.provenance["guideline"]
    # escitalopram is not in the rule: it keeps the ANSM level until its own label is read
    assert env.safety_context.interaction("methadone", "escitalopram")[1].startswith("ANSM-")


def test_lamotrigine_with_valproate_says_how_to_dose_not_only_that_it_is_major(env):
    """ANSM-1298 grades lamotrigine + valproate 'not recommended' with no management text, so a tool answer
    (and the psychiatry domain, which takes this level) could not say what the lamotrigine label asks for:
    the valproate schedule (halved doses, slow escalation) because valproate raises the rash risk
    (boxed warning, 2.1). US-030 restates the pair at the same level with that management."""
    level, why = env.safety_context.interaction("lamotrigine", "valproic acid")
    assert level == "major" and why.startswith("US-030"), why
    from envs.domains.drug_interaction import logic as L

    assessed = L.assess_pair(env.db, env.db.drugs["lamotrigine"], env.db.drugs["valproic acid"])
    overlay = [(rule, lv) for rule, lv, _ in assessed if rule.id == "US-030"]
    assert overlay, [rule.id for rule, _, _ in assessed]
    said = overlay[0][0].model_dump_json() + overlay[0][1].model_dump_json()
    assert "halve" in said and "rash" in said and "valproate schedule" in said, said


def test_no_contraindicated_pair_fires_outside_the_label_list(env):
    """Over every drug pair among the patients' medications and the drugs with dose profiles (what the
    other domains' episodes name), an overlay contraindicated level comes only from a label-contraindicated rule."""
    from envs.domains.drug_interaction import logic as L

    allowed = LABEL_CONTRAINDICATED_RULES
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

    out = env.toolkit.call("check_hepatic_adjustment", {"drug": "haloperidol", "patient_id": "P035"}).result
    assert out["recommendation"] == "avoid_or_specialist_review" and out["basis"] == L.HEPATIC_DEFAULT_BASIS
    assert "no dosing by hepatic function" in out["label_checked"]
    # insulin in Child-Pugh C (the insulin task's patient) is not an avoid and not a contraindicated condition
    assert env.toolkit.call("check_hepatic_adjustment", {"drug": "insulin human", "patient_id": "P035"}).result[
        "recommendation"] == "reduce_dose_and_monitor"
    # no flagged drug's label contraindicates it by hepatic function for every route and indication, and
    # the convention is no label: a Child-Pugh class is never a contraindicating condition (severity 5)
    for drug in sorted(_flagged(env)):
        assert not any(c.startswith("child-pugh") for c in env.safety_context.contraindicated_conditions(drug)), drug


def _flagged(env) -> set[str]:
    flagged = {d for d, p in env.db.dose_profiles.items() if p.hepatic_caution}
    return flagged | {d for d, p in env.db.renal_profiles.items() if p.hepatic_flag}


def test_every_hepatic_flagged_drug_has_its_label_rule_or_a_checked_label(env):
    """The default convention answers only for drugs whose label states no hepatic dosing, and each
    label rule names its section."""
    from envs.domains.drug_interaction import logic as L

    flagged = _flagged(env)
    assert len(flagged) == 22
    missing = sorted(flagged - set(L.HEPATIC_LABEL_RULES) - set(L.HEPATIC_CONVENTION_ONLY))
    assert not missing, f"hepatic-flagged drugs on the default convention without a checked label: {missing}"
    assert not set(L.HEPATIC_LABEL_RULES) & set(L.HEPATIC_CONVENTION_ONLY)
    for drug, rule in L.HEPATIC_LABEL_RULES.items():
        assert SECTION.search(rule.label), drug
        assert set(rule.by_class) == {"A", "B", "C"} and set(rule.by_class.values()) <= set(L.HEPATIC_RECOMMENDATIONS)
    on_convention = [d for d in sorted(flagged) if env.toolkit.call(
        "check_hepatic_adjustment", {"drug": d, "child_pugh_class": "C"}).result["basis"] == L.HEPATIC_DEFAULT_BASIS]
    assert on_convention == sorted(L.HEPATIC_CONVENTION_ONLY)


@pytest.mark.parametrize("drug, child_pugh, expected, cited", [
    ("acetaminophen", "C", "reduce_dose_and_monitor", "4 CONTRAINDICATIONS"),
    ("acetaminophen", "B", "use_with_caution", "5.1"),
    ("metoprolol", "A", "reduce_dose_and_monitor", "8.6"),
    ("morphine", "C", "reduce_dose_and_monitor", "8.6"),
    ("colchicine", "B", "use_with_caution", "8.7"),
    ("colchicine", "C", "reduce_dose_and_monitor", "8.7"),
    ("diltiazem", "C", "use_with_caution", "PRECAUTIONS"),
    ("methotrexate", "A", "avoid", "CONTRAINDICATIONS"),
    ("lorazepam", "C", "reduce_dose_and_monitor", "PRECAUTIONS"),
])
def test_hepatic_recommendation_of_the_formerly_conventional_drugs(env, drug, child_pugh, expected, cited):
    out = env.toolkit.call("check_hepatic_adjustment", {"drug": drug, "child_pugh_class": child_pugh}).result
    assert out["recommendation"] == expected and cited in out["basis"], out


def _members(env, side: dict) -> list[str]:
    if "drug" in side:
        return [side["drug"]]
    return sorted(m for m in env.db.classes[side["class"]].members if m in env.db.drugs)


def _review_members(env, key: str) -> list[str]:
    kind, ident = key.split(":", 1)
    return _members(env, {"drug": ident} if kind == "drug" else {"class": ident})


def test_every_overlay_rule_is_contraindicated_only_where_a_label_says_so(env, overlay):
    """Every overlay rule (pair rules and ANSM reviews), on every drug pair it covers, without a dose
    (what `drug_reference.interaction` asks): "contraindicated" only where one of the
    label-contraindicated rules covers the pair."""
    from envs.domains.drug_interaction import logic as L

    allowed = LABEL_CONTRAINDICATED_RULES
    covered = [(r["id"], _members(env, r["a"]), _members(env, r["b"])) for r in overlay["pairs"]]
    covered += [(r.get("see", r["id"]), *(_review_members(env, k) for k in r["ansm_parties"])) for r in overlay["ansm_reviews"]]
    pairs = 0
    for rid, side_a, side_b in covered:
        assert side_a and side_b, rid
        for a in side_a:
            for b in side_b:
                if a == b:
                    continue
                assessed = L.assess_pair(env.db, env.db.drugs[a], env.db.drugs[b])
                assert any(r.id == rid for r, _, _ in assessed), (rid, a, b)
                pairs += 1
                if L.effective_severity(assessed) == "contraindicated":
                    why = {r.id for r, lv, _ in assessed if r.source == "us_overlay" and lv.level == "contraindicated"}
                    assert why and why <= allowed, (rid, a, b, why)
    assert pairs > 500


def test_no_severity_5_interaction_pattern_fires_on_a_pair_no_label_contraindicates(env, overlay):
    """The reward's detector, one drug pair per overlay rule: an order creating the pair after an
    interaction check fires a severity-5 pattern only for the label-contraindicated rules."""
    from envs.core.task import Task
    from envs.rewards import detect_violations
    from tests.rewards.builders import call, episode, turn

    contraindicated = LABEL_CONTRAINDICATED_RULES
    fired = {}
    rules = [(r["id"], _members(env, r["a"]), _members(env, r["b"])) for r in overlay["pairs"]]
    rules += [(r["id"], *(_review_members(env, k) for k in r["ansm_parties"]))
              for r in overlay["ansm_reviews"] if "see" not in r]
    for rid, side_a, side_b in rules:
        a, b = side_a[0], next(d for d in side_b if d != side_a[0])
        task = Task(ticket=f"Patient currently on {a}.", patient_id="P1", domain="drug_interaction")
        traj = episode(task, turn(call("check_interaction", {"drug_a": a, "drug_b": b}, result="checked")),
                       turn(call("add_medication", {"patient_id": "P1", "drug": b}, result="added")),
                       answer=f"{b} added with {a}; interaction risk acknowledged, monitor.")
        violations, errors = detect_violations(traj, task, env.safety_context)
        assert errors == [], (rid, errors)
        fired[rid] = any(v.severity >= 5 and v.pattern_id.startswith("ddi.") for v in violations)
    assert {rid for rid, hit in fired.items() if hit} == contraindicated, fired


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


# -- renal bands: "contraindicated" only where the US label's section 4 says so ----------------------
def test_every_renal_band_the_package_contraindicates_is_checked_against_its_label(env):
    """Each open-medicine tier marked "contraindicated" has the drug's label rule; a band that stays
    contraindicated (severity 5 in the reward) cites the label's section 4, and every rule names its section."""
    from envs.domains.drug_interaction import logic as L

    marked = {d for d, p in env.db.renal_profiles.items() if any(t.adjustment_type == "contraindicated" for t in p.tiers)}
    assert marked == set(L.RENAL_LABEL_RULES), marked ^ set(L.RENAL_LABEL_RULES)
    for drug, rule in L.RENAL_LABEL_RULES.items():
        assert SECTION.search(rule.label) and rule.metric == env.db.renal_profiles[drug].metric, drug
        assert rule.level in ("contraindicated", "avoid") and "4 CONTRAINDICATIONS (" in rule.label, drug
        # an "avoid" rule states that the label's section 4 has no renal contraindication
        assert (rule.level == "avoid") == ("no renal contraindication" in rule.label), drug
    severity_5 = {d: L.renal_contraindicated_below(p) for d, p in env.db.renal_profiles.items()
                  if L.renal_contraindicated_below(p) is not None}
    # Glucophage 4: eGFR < 30; Betapace AF / sotalol 4 (AFIB/AFL): CrCl < 40
    assert severity_5 == {"metformin": 30, "sotalol": 40}
    assert {d for d, r in L.RENAL_LABEL_RULES.items() if r.level == "avoid"} == {"lithium", "methotrexate", "spironolactone"}


@pytest.mark.parametrize("drug, pid, fires", [
    ("lithium", "P014", False),         # CrCl 24: lithium label, severe renal impairment not recommended
    ("spironolactone", "P028", False),  # eGFR 24.9: Aldactone 4 has no renal contraindication
    ("metformin", "P028", True),        # eGFR 24.9: Glucophage 4 CONTRAINDICATIONS
    ("sotalol", "P001", True),          # CrCl 30.3: Betapace AF 4 CONTRAINDICATIONS (CrCl < 40)
])
def test_severity_5_renal_contraindication_only_where_the_label_contraindicates(env, drug, pid, fires):
    from envs.core.task import Task
    from envs.rewards import detect_violations
    from tests.rewards.builders import call, episode, turn

    task = Task(ticket=f"{pid} needs {drug} reviewed.", patient_id=pid, domain="drug_interaction")
    traj = episode(task, turn(call("get_patient_details", {"patient_id": pid})),
                   turn(call("check_patient_interactions", {"patient_id": pid, "proposed_drug": drug})),
                   turn(call("add_medication", {"patient_id": pid, "drug": drug, "dose": 25, "unit": "mg", "route": "PO",
                                                "frequency": "once daily"}, result="added")),
                   answer=f"{drug} added; review in 1 week.")
    violations, errors = detect_violations(traj, task, env.safety_context)
    assert errors == []
    hit = [v for v in violations if v.pattern_id == "drug_condition.contraindicated"]
    assert bool(hit) == fires, (drug, pid, [v.evidence for v in hit])
    assert all(v.severity == 5 for v in hit)


def test_the_renal_tool_reports_the_label_level_beside_the_package_word(env):
    out = env.toolkit.call("get_renal_dose_adjustment", {"drug": "lithium", "renal_value": 20}).result
    assert out["adjustment_type"] == "avoid" and out["source_adjustment_type"] == "contraindicated"
    assert "not recommended" in out["label_rule"]["statement"] and "8 USE IN SPECIFIC POPULATIONS" in out["label_rule"]["source"]
    kept = env.toolkit.call("get_renal_dose_adjustment", {"drug": "metformin", "renal_value": 20}).result
    assert kept["adjustment_type"] == "contraindicated" and "4 CONTRAINDICATIONS" in kept["label_rule"]["source"]
    assert "label_rule" not in env.toolkit.call("get_renal_dose_adjustment", {"drug": "lithium", "renal_value": 45}).result


def test_generated_renal_tasks_follow_the_label_rules():
    from envs.domains.drug_interaction import environment as E

    tasks = [t for s in E.get_splits() for t in E.get_tasks(s) if t.description.task_type == "renal_adjustment_patient"]
    drug = {t.id: t.id.split("-", 4)[4] for t in tasks}
    # no patient with a reason for lithium, methotrexate or spironolactone has a renal function in their
    # "avoid" band (the tool's label level there is tested above); any such task must cite the label
    avoided = [t for t in tasks if t.correct_answer == "avoid"]
    assert {drug[t.id] for t in avoided} <= {"lithium", "methotrexate", "spironolactone"}
    assert all("no renal contraindication" in t.description.provenance["guideline"] for t in avoided)
    contraindicated = [t for t in tasks if t.correct_answer == "contraindicated"]
    assert contraindicated and {drug[t.id] for t in contraindicated} <= {"metformin", "sotalol"}
    assert all("4 CONTRAINDICATIONS (" in t.description.provenance["guideline"] for t in contraindicated)


# Pairs psychiatry grades through this domain, each at the level of the US label section its rule cites.
@pytest.mark.parametrize("a, b, level, rule", [
    # SSRI labels 4 CONTRAINDICATIONS name linezolid among the MAOIs (US-021); before, US-R10's moderate
    ("sertraline", "linezolid", "contraindicated", "US-021"),
    ("escitalopram", "linezolid", "contraindicated", "US-021"),
    ("fluoxetine", "linezolid", "contraindicated", "US-021"),
    ("paroxetine", "linezolid", "contraindicated", "US-021"),
    ("citalopram", "linezolid", "contraindicated", "US-021"),
    # SNRI labels 4 CONTRAINDICATIONS name linezolid as well (US-024, US-025); before, US-R10's moderate
    ("venlafaxine", "linezolid", "contraindicated", "US-024"),
    ("duloxetine", "linezolid", "contraindicated", "US-025"),
    # Seroquel 5 (QT Prolongation): avoid with drugs that prolong QTc (US-022); before, ANSM minor
    ("quetiapine", "escitalopram", "major", "US-022"),
    ("quetiapine", "haloperidol", "major", "US-022"),
    ("quetiapine", "methadone", "major", "US-022"),
    # naltrexone labels contraindicate patients receiving opioid analgesics (US-023); before, ANSM major
    ("naltrexone", "tramadol", "contraindicated", "US-023"),
])
def test_psychiatry_pairs_take_their_label_level(env, a, b, level, rule):
    found = env.safety_context.interaction(a, b)
    assert found is not None and found[0] == level and found[1].startswith(rule), found


def test_an_opioid_antagonist_is_not_an_opioid_for_the_cns_depressant_rules(env):
    """Naltrexone and naloxone antagonise opioids (their labels' DESCRIPTION): US-011's benzodiazepine
    rule no longer covers them, while it still covers the opioid agonists (control)."""
    assert env.safety_context.interaction("lorazepam", "naltrexone") is None
    naloxone = env.safety_context.interaction("lorazepam", "naloxone")
    assert naloxone is None or not naloxone[1].startswith("US-011"), naloxone
    for opioid in ("morphine", "tramadol", "methadone"):
        found = env.safety_context.interaction("lorazepam", opioid)
        assert found is not None and found[0] == "major" and found[1].startswith("US-011"), (opioid, found)
    assert "opioids" not in env.db.drugs["naltrexone"].class_ids
    assert "partial-opioid-antagonists" in env.db.drugs["naltrexone"].class_ids


def test_nalmefene_is_graded_as_an_antagonist_not_as_an_opioid(env):
    """Nalmefene is an opioid antagonist (nalmefene injection label, DESCRIPTION): the opioid-agonist
    class rules no longer grade it (lorazepam was US-011 major, atropine ANSM-1336 minor, sodium
    oxybate ANSM-1408 contraindicated), while its pairs with opioid agonists keep the partial
    antagonists' levels, which Selincro SmPC 4.3 also contraindicates (control)."""
    for other in ("lorazepam", "atropine", "sodium oxybate", "phenobarbital"):
        assert env.safety_context.interaction("nalmefene", other) is None, other
    for opioid, level, rule in (("morphine", "contraindicated", "ANSM-0151"), ("methadone", "contraindicated", "ANSM-1410"),
                                ("buprenorphine", "contraindicated", "ANSM-1409"), ("tramadol", "major", "ANSM-0149")):
        found = env.safety_context.interaction("nalmefene", opioid)
        assert found is not None and found[0] == level and found[1].startswith(rule), (opioid, found)
    assert env.db.drugs["nalmefene"].class_ids == ["partial-opioid-antagonists"]


def test_naloxone_is_not_a_sedative(env):
    """Naloxone has essentially no pharmacologic activity without opioids and does not depress
    respiration (naloxone injection label, CLINICAL PHARMACOLOGY): ANSM's sedative-drug rule
    (ANSM-0439, added CNS depression) no longer grades it with a benzodiazepine or an opioid, while
    two sedatives keep that rule (control)."""
    for other in ("lorazepam", "midazolam", "morphine", "sodium oxybate"):
        assert env.safety_context.interaction("naloxone", other) is None, other
    control = env.safety_context.interaction("lorazepam", "zolpidem")
    assert control is not None and control[0] == "minor" and control[1].startswith("ANSM-0439"), control
    assert not {"sedative-drugs", "other-sedative-drugs", "opioids"} & set(env.db.drugs["naloxone"].class_ids)


def test_controls_keep_their_level(env):
    """Pairs the new rules do not cover keep theirs: SSRI + tramadol stays US-006 moderate, quetiapine +
    sertraline (no QT class) stays below major, naltrexone + methadone stays contraindicated (ANSM)."""
    assert env.safety_context.interaction("sertraline", "tramadol")[0] == "moderate"
    assert env.safety_context.interaction("quetiapine", "sertraline")[0] == "minor"
    assert env.safety_context.interaction("naltrexone", "methadone")[0] == "contraindicated"


def test_a_class_correction_removes_a_member_and_refuses_a_non_member(env, tmp_path):
    """`class_corrections` takes the drug out of the class (both directions of the membership); a
    correction naming a drug that is not a member is refused, naming the file, entry and field."""
    from envs.data.registry import DataSourceError
    from envs.domains.drug_interaction.ingest import Builder, ingest_overlay

    def builder() -> Builder:
        b = Builder(sources=None, vocab=None, authored_names={}, english_aliases={}, class_table={}, other_parties={})
        b.drugs = {d: env.db.drugs[d].model_copy(deep=True) for d in ("lorazepam", "morphine")}
        b.classes = {"opioids": env.db.classes["opioids"].model_copy(deep=True)}
        return b

    def overlay_with(corrections: list[dict]) -> Path:
        path = tmp_path / "severity_overlay.json"
        path.write_text(json.dumps({"class_corrections": corrections}), encoding="utf-8")
        return path

    b = builder()
    ingest_overlay(b, {}, path=overlay_with([{"drug": "morphine", "remove_classes": ["opioids"], "evidence": "x 4 Y"}]))
    assert "opioids" not in b.drugs["morphine"].class_ids and "morphine" not in b.classes["opioids"].members
    with pytest.raises(DataSourceError, match=r"severity_overlay.json: lorazepam: field remove_classes"):
        ingest_overlay(builder(), {}, path=overlay_with(
            [{"drug": "lorazepam", "remove_classes": ["opioids"], "evidence": "x 4 Y"}]))
