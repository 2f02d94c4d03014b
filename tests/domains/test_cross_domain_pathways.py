"""The authored cross-domain pathways: the committed files, one patient across domains, gold replays
(every phase 1.0, accuracy 1.0, no safety violation, answers produced by the tools), tool switching
at transitions, time budgets, skipped escalations, declared phases, and the add_patient hooks."""

from __future__ import annotations

import json
import re
from collections import Counter

import pytest

from envs import registry

registry.DOMAINS.setdefault("cross_domain", "envs.domains.cross_domain.environment")

from envs.core.db import DataFileError  # noqa: E402
from envs.env import HealthcareGymEnv  # noqa: E402
from envs.validate import gold_replay, validate_task  # noqa: E402
from envs.domains.cross_domain import authoring  # noqa: E402
from envs.domains.cross_domain import environment as cross  # noqa: E402
from envs.rewards.checks.emergency import normalise_emergency  # noqa: E402
from envs.rewards.safety_patterns import EMERGENCY_TYPES  # noqa: E402

DOMAINS_USED = ("triage_emergency", "clinical_diagnosis", "drug_interaction", "ehr_management")
PATHWAYS = authoring.all_pathways()
BY_ID = {p["id"]: p for p in PATHWAYS}
TITLES = {"Chest pain", "Diabetic emergency", "Stroke code", "Sepsis bundle", "Post-operative complication",
          "Paediatric fever"}


@pytest.fixture(scope="module", autouse=True)
def built_domains():
    """The four domains the pathways touch, built (a no-op when up to date); the sentence-embedding
    model is switched off so NL-assertion grading uses token overlap and the replays stay fast."""
    import importlib

    from envs.rewards import similarity

    for domain in DOMAINS_USED:
        importlib.import_module(f"envs.domains.{domain}.build").build()
    saved = (similarity._embedder, similarity.embedding_status())
    similarity.set_embedder(None, "disabled for the cross_domain tests")
    cross.load_pathways.cache_clear()
    yield
    similarity.set_embedder(*saved)


def _call(name: str, **arguments) -> str:
    return "<tool_call>" + json.dumps({"name": name, "arguments": arguments}) + "</tool_call>"


def _result(call) -> dict:
    """A logged call's result, without the pathway transition wrapper."""
    data = json.loads(call.result)
    return data["result"] if isinstance(data, dict) and "pathway" in data and "result" in data else data


# -- the committed files ---------------------------------------------------------------------------
def test_committed_files_are_what_the_authoring_package_builds():
    for name, text in authoring.render().items():
        assert (cross.HERE / name).read_text(encoding="utf-8") == text, f"{name} is stale: run " \
            "python -m envs.domains.cross_domain.authoring"


def test_six_pathways_25_tasks_and_a_split_that_trains_on_every_pathway():
    tasks = cross.get_tasks()
    assert len(tasks) >= 25 and {p["title"] for p in PATHWAYS} == TITLES
    splits = cross.get_splits()
    train, test = set(splits["train"]), set(splits["test"])
    assert not train & test and train | test == {t.id for t in tasks} and 4 <= len(test) <= 6
    titles = {t.id: t.description.category for t in tasks}
    assert {titles[i] for i in train} == TITLES and {titles[i] for i in test} <= TITLES
    assert len(cross.get_tasks("train")) == len(train)


def test_phase_structure_emergencies_and_time_budgets():
    for p in PATHWAYS:
        phases = p["phases"]
        assert 3 <= len(phases) <= 4, p["id"]
        assert len({ph["domain"] for ph in phases}) >= 2, p["id"]
        for ph in phases:
            assert ph["required_actions"] and ph["nl_assertions"], (p["id"], ph["name"])
            assert ph["time_pressure"] == (ph.get("max_calls") is not None)
            if ph.get("max_calls"):
                assert ph["max_calls"] >= len(ph["required_actions"]), (p["id"], ph["name"])
        if p["emergency"] is not None:
            assert p["emergency"] in EMERGENCY_TYPES and normalise_emergency(p["emergency"]) == p["emergency"]
            assert phases[0]["time_pressure"], f"{p['id']}: the first phase of an emergency is time-critical"
    kinds = Counter(p["emergency"] for p in PATHWAYS)
    assert {"stemi", "stroke", "sepsis", "dka"} <= set(kinds) and kinds[None] >= 3
    assert any(ph["transition"] == "agent_declares" for p in PATHWAYS for ph in p["phases"])


def _person(domain: str, record: dict) -> tuple:
    """(id, age, sex, weight, number of allergies, home medications) as each domain writes them."""
    if domain == "triage_emergency":
        meds = record["medications"]
    elif domain == "clinical_diagnosis":
        meds = [m["name"] for m in record["medications"]]
    elif domain == "drug_interaction":
        meds = [m["drug"] for m in record["medications"]]
    else:
        meds = [m["drug"] for m in record["admissions"][0]["medication_orders"] if "-HOME" in m["order_id"]]
    return (record["patient_id"], record["age"], record["sex"], record["weight_kg"], len(record["allergies"]),
            meds)


def test_the_patient_is_the_same_person_in_every_domain():
    for p in PATHWAYS:
        records = p["patients"]
        assert set(records) == {ph["domain"] for ph in p["phases"]}, p["id"]
        views = {d: _person(d, r) for d, r in records.items()}
        ids_ages = {v[:5] for v in views.values()}
        assert ids_ages == {(p["patient_id"], *next(iter(ids_ages))[1:])}, (p["id"], views)
        home = [v[5] for d, v in views.items() if d in ("triage_emergency", "ehr_management")]
        for d, v in views.items():  # the chart and the pharmacy list the home drugs first, then inpatient ones
            for h in home:
                assert v[5][: len(h)] == h, (p["id"], d)
        names = {r["name"] for r in records.values() if "name" in r}
        assert len(names) <= 1, (p["id"], names)


def test_required_actions_name_tools_of_their_own_phase_with_valid_arguments():
    definitions = {d: registry.get_environment(d).toolkit.definitions for d in DOMAINS_USED}
    for task in cross.get_tasks():
        pathway = cross.load_pathways()[task.metadata["pathway_id"]]
        for ph in pathway.phases:
            for action in ph.required_actions:
                assert action.name in definitions[ph.domain], (pathway.id, ph.name, action.name)
                definitions[ph.domain][action.name].validate(action.arguments)
        report = validate_task(task, "cross_domain", cross.task_tool_definitions(task), replay=False)
        assert report.ok, report.problems


# -- gold replays ----------------------------------------------------------------------------------
@pytest.mark.parametrize("pathway_id", sorted(BY_ID))
def test_gold_replay_scores_every_phase_and_the_answer_without_violations(pathway_id):
    task = next(t for t in cross.get_tasks() if t.id == f"pathway_{pathway_id}")
    trajectory, info = gold_replay(task, "cross_domain")
    failed = [(c.name, c.error) for turn in trajectory.turns for c in turn.tool_calls if not c.ok]
    assert not failed
    breakdown = info["reward_breakdown"]
    phases = breakdown["details"]["pathway_phases"]
    assert [ph["score"] for ph in phases] == [1.0] * len(BY_ID[pathway_id]["phases"])
    assert info["reward_components"]["accuracy"] == 1.0
    assert breakdown["details"]["process"]["coverage"] == pytest.approx(1.0)
    assert breakdown["violations"] == [] and breakdown["total"] == pytest.approx(1.0)
    _assert_answer_comes_from_the_tools(pathway_id, trajectory)
    _assert_gold_doses_pass_the_dose_check_or_follow_the_guideline(pathway_id, trajectory)


def _results(trajectory, name: str) -> list[dict]:
    return [_result(c) for turn in trajectory.turns for c in turn.tool_calls if c.name == name and c.ok]


def _dose(r: dict) -> float:
    return r["ranges"][0]["recommended_max_single_dose"]


# What the final answer is read from in the gold replay: (tool, value extracted from its result).
ANSWER_SOURCES = {
    "chest_pain_stemi_inferior": ("add_medication", lambda r: r["drug"]),
    "chest_pain_stemi_antiretroviral": ("add_medication", lambda r: r["drug"]),
    "chest_pain_nstemi": ("record_diagnosis", lambda r: r["recorded"]),
    "chest_pain_low_risk": ("calculate_heart_score", lambda r: str(r["score"])),
    "chest_pain_stemi_shock": ("calculate_esi_level", lambda r: r["category"]),
    "diabetic_emergency_dka": ("get_dose_range", lambda r: f"{r['ranges'][0]['max']:g} units/hour"),
    "diabetic_emergency_euglycaemic_dka": ("record_diagnosis", lambda r: r["recorded"]),
    "diabetic_emergency_hhs": ("get_renal_dose_adjustment",
                               lambda r: r["drug"] if r["adjustment_type"] == "contraindicated" else None),
    "diabetic_emergency_hypoglycaemia": ("discontinue_medication", lambda r: r["drug"]),
    "stroke_code_left_mca": ("get_dose_range", lambda r: f"{_dose(r):g} mg"),
    "stroke_code_weight_cap": ("get_dose_range", lambda r: f"{_dose(r):g} mg"),
    "stroke_code_anticoagulated": ("order_lab", lambda r: "no" if r["test"] == "inr" and r["result"]["value"] > 1.7
                                   else None),
    "stroke_code_blood_pressure": ("get_dose_range", lambda r: f"{_dose(r):g} mg" if r["drug"] == "alteplase" else None),
    "sepsis_bundle_urosepsis": ("calculate_qsofa", lambda r: str(r["score"])),
    "sepsis_bundle_septic_shock": ("calculate_esi_level", lambda r: r["category"]),
    "sepsis_bundle_cholangitis": ("calculate_news2", lambda r: str(r["score"])),
    "sepsis_bundle_neutropenic": ("record_diagnosis", lambda r: r["recorded"]),
    "postop_pulmonary_embolism": ("calculate_news2", lambda r: str(r["score"])),
    "postop_anastomotic_leak": ("get_lab_trend", lambda r: f"{r['delta']:g} mg/L"),
    "postop_haemorrhage": ("get_dose_range", lambda r: f"{_dose(r):g} mg"),
    "postop_hyperkalaemia": ("get_lab_trend", lambda r: f"{r['delta']:g} mg/dL" if r["test"] == "creatinine" else None),
    "paediatric_fever_uti": ("calculate_esi_level", lambda r: r["category"]),
    "paediatric_fever_meningococcal": ("calculate_esi_level", lambda r: r["category"]),
    "paediatric_fever_neonate": ("calculate_esi_level", lambda r: r["category"]),
    "paediatric_fever_pneumonia": ("record_diagnosis", lambda r: r["recorded"]),
    "paediatric_fever_viral": ("calculate_esi_level", lambda r: r["category"]),
}


def _assert_answer_comes_from_the_tools(pathway_id, trajectory):
    tool, extract = ANSWER_SOURCES[pathway_id]
    values = {extract(r) for r in _results(trajectory, tool)} - {None}
    assert BY_ID[pathway_id]["final_answer"] in values, (pathway_id, values)


def _stated_doses(text: str) -> set[tuple[float, str]]:
    """(amount, unit) for every dose a guideline text states: "4,000 U" -> (4000, "units")."""
    units = {"u": "units", "units": "units", "unit": "units", "g": "g", "mg": "mg", "mcg": "mcg"}
    return {(float(m.group(1).replace(",", "")), units[m.group(2).lower()])
            for m in re.finditer(r"(\d[\d,]*\.?\d*)\s*(units?|U|mg|mcg|g)\b", text)}


def _assert_gold_doses_pass_the_dose_check_or_follow_the_guideline(pathway_id, trajectory):
    """Every dose the gold orders passes the drug-interaction dose check (within_range: within the
    weight-based range, or the single-dose cap where the weight-based minimum is above it, alteplase
    90 mg for 112 kg, which the check now reports within_range with at_cap), unless the case's cited
    guideline states that very dose (insulin 10 units for hyperkalaemia, UK Kidney Association 2020;
    heparin 60 U/kg capped at 4,000 U for NSTEMI). A capped dose no longer needs an exemption here."""
    from envs.domains.drug_interaction import logic as L
    from envs.domains.drug_interaction.environment import load_db

    db, pathway = load_db(), BY_ID[pathway_id]
    person = pathway["patients"]["drug_interaction"] if "drug_interaction" in pathway["patients"] else None
    for turn in trajectory.turns:
        for c in turn.tool_calls:
            if c.name != "add_medication" or not c.ok:
                continue
            status, a = _result(c)["dose_check"], c.arguments
            if status == "no dose range available":
                continue
            check = L.dose_check(L.find_route(db.dose_profiles[_result(c)["drug"]], a["route"]), a["dose"], a["unit"],
                                 person["weight_kg"], person["age"])
            assert check["status"] == status, (pathway_id, a, check)
            cap = check["max_single_dose_cap"]
            if cap is not None and check["min"] > cap and check["dose_given"] == pytest.approx(cap):
                assert status == "within_range" and check["at_cap"], (pathway_id, a, check)  # the capped dose
            if status == "within_range":
                continue
            assert (float(a["dose"]), a["unit"]) in _stated_doses(pathway["guideline"]), (
                f"{pathway_id}: {a['drug']} {a['dose']} {a['unit']} is {status} and the guideline does not state it")


def test_the_hyperkalaemia_calcium_dose_is_the_uk_kidney_association_dose():
    """UKKA 2020: 30 mL of 10% calcium gluconate (10% = 100 mg/mL, so 3 g) IV for ECG changes; the
    gold order, its reasoning and its criterion state that dose (the gold once gave 1 g)."""
    pathway = BY_ID["postop_hyperkalaemia"]
    stated = re.search(r"(\d+) mL of 10% calcium gluconate", pathway["guideline"])
    assert stated and "UK Kidney Association" in pathway["guideline"]
    grams = int(stated.group(1)) * 0.1
    phase = next(ph for ph in pathway["phases"] if any(a["arguments"].get("drug") == "calcium gluconate"
                                                       for a in ph["required_actions"]))
    order = next(a["arguments"] for a in phase["required_actions"] if a["arguments"].get("drug") == "calcium gluconate")
    assert (order["dose"], order["unit"]) == (pytest.approx(grams), "g")
    assert f"{stated.group(1)} mL of 10% calcium gluconate" in phase["gold_reasoning"]
    assert any(f"{stated.group(1)} mL of 10% calcium gluconate" in t for t in phase["nl_assertions"])


# ICD-10-CM tabular: a STEMI whose wall the ECG names is coded to that wall (I21.0x anterior, I21.1x
# inferior, I21.2x other sites); I21.3 "of unspecified site" only when no wall is known.
_WALLS = ("anterior", "inferior", "lateral", "posterior")


def test_a_stemi_is_coded_to_the_wall_its_ecg_names():
    from envs.domains.clinical_diagnosis import knowledge

    index, checked = knowledge.icd10_index(), 0
    for p in PATHWAYS:
        codes = [a["arguments"]["icd10_code"] for ph in p["phases"] for a in ph["required_actions"]
                 if a["name"] == "record_diagnosis"]
        for code in codes:
            item = index.get(code)
            assert item and item["billable"], (p["id"], code)
            if not code.startswith("I21.") or code == "I21.4":
                continue
            ecg = p["patients"]["clinical_diagnosis"]["hidden_results"]["ecg"]["value"].lower()
            wall = next(w for w in _WALLS if re.search(rf"\b{w} stemi\b", ecg))
            site = " ".join(h["description"].lower() for h in item["hierarchy"]) + " " + item["description"].lower()
            assert "unspecified site" not in site and f"{wall} wall" in site, (p["id"], code, wall)
            # the grader compares the code, so the site-unspecified I21.3 does not pass for it
            action = next(a for ph in p["phases"] for a in ph["required_actions"] if a["name"] == "record_diagnosis")
            assert "icd10_code" in action["compare_args"], p["id"]
            checked += 1
    assert checked == 3  # the inferior STEMI, the anterior STEMI on ritonavir, the anterior STEMI in shock


def test_the_febrile_neonate_gets_a_lumbar_puncture():
    """AAP 2021 (well-appearing febrile infants 8 to 21 days): the septic screen includes a lumbar
    puncture for CSF analysis and culture; both are orderable tests of the clinical-diagnosis
    catalogue ("lumbar puncture" resolves to the CSF analysis) whose results the case holds."""
    from envs.domains.clinical_diagnosis import knowledge

    catalog, pathway = knowledge.lab_catalog(), BY_ID["paediatric_fever_neonate"]
    assert catalog.resolve("lumbar puncture") == "csf_analysis" and catalog.resolve("CSF culture") == "csf_culture"
    screen = next(ph for ph in pathway["phases"] if ph["name"] == "septic screen")
    ordered = {a["arguments"]["test"] for a in screen["required_actions"] if a["name"] == "order_lab"}
    assert {"blood_culture", "urine_culture", "csf_analysis", "csf_culture"} <= ordered
    held = pathway["patients"]["clinical_diagnosis"]["hidden_results"]
    assert {"csf_analysis", "csf_culture"} <= set(held) and "lumbar puncture" in pathway["guideline"]
    task = next(t for t in cross.get_tasks() if t.id == "pathway_paediatric_fever_neonate")
    trajectory, _ = gold_replay(task, "cross_domain")
    resulted = {r["test"]: r for r in _results(trajectory, "order_lab")}
    assert resulted["csf_analysis"]["status"] == "resulted"
    assert resulted["csf_analysis"]["result"]["flag"] == "normal"  # no pleocytosis, no organisms on Gram stain


def test_every_pathway_has_an_answer_source():
    assert set(ANSWER_SOURCES) == set(BY_ID)


def test_the_environment_passes_gymnasium_check_env():
    from gymnasium.utils.env_checker import check_env

    check_env(HealthcareGymEnv(domain="cross_domain", max_turns=4), skip_render_check=True)


# -- transitions, budgets, skipped escalation -------------------------------------------------------
def _env(pathway_id: str, max_turns: int = 40) -> HealthcareGymEnv:
    env = HealthcareGymEnv(domain="cross_domain", task_id=f"pathway_{pathway_id}", max_turns=max_turns)
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("pathway_id", sorted(BY_ID))
def test_later_phase_tools_are_unknown_until_their_phase(pathway_id):
    env = _env(pathway_id)
    engine = env.domain_env.extras["engine"]
    first = set(engine.domain_envs[engine.phase.domain].toolkit.tool_names)
    later = {a.name for ph in engine.pathway.phases[1:] for a in ph.required_actions} - first
    assert later, pathway_id
    for name in later:
        assert name not in engine.definitions
        out = engine.call(name, {"patient_id": engine.pathway.patient_id})
        assert not out.ok and "phase" in out.error and engine.phase.domain in out.error


def test_tools_switch_at_each_transition_and_the_new_signatures_are_shown():
    env = _env("chest_pain_stemi_inferior")
    engine = env.domain_env.extras["engine"]
    pid = "PW-CP01"
    assert "order_ecg" in engine.definitions and "order_lab" not in engine.definitions
    for name, args in [("get_patient_presentation", {}), ("get_vital_signs", {}), ("order_ecg", {}),
                       ("activate_stemi_alert", {"ecg_findings": "inferior ST elevation"})]:
        assert engine.call(name, {"patient_id": pid, **args}).ok
    out = engine.call("assign_triage_level", {"patient_id": pid, "esi_level": 2})
    transition = out.result["pathway"]
    assert transition["next_phase"] == "diagnostic work-up" and transition["domain"] == "clinical_diagnosis"
    assert any(s.startswith("order_lab(patient_id: string, test: string") for s in transition["tool_signatures"])
    assert "order_lab" in engine.definitions and "order_ecg" not in engine.definitions
    status = engine.status()
    assert status["active_phase"] == "diagnostic work-up" and status["phases"][0]["completed"]


def _skipping_run(skip_escalation: bool) -> tuple[float, dict]:
    """The inferior-STEMI pathway done right, or with the STEMI alert and the triage level skipped
    (the agent declares the triage phase over) and an antiplatelet order that does not mention PCI."""
    env = _env("chest_pain_stemi_inferior")
    pid = "PW-CP01"
    steps = [_call("get_patient_presentation", patient_id=pid), _call("get_vital_signs", patient_id=pid),
             _call("order_ecg", patient_id=pid)]
    if skip_escalation:
        steps.append(_call("complete_phase", summary="chest pain triaged"))
    else:
        steps += [_call("activate_stemi_alert", patient_id=pid, ecg_findings="inferior ST elevation"),
                  _call("assign_triage_level", patient_id=pid, esi_level=2)]
    steps += [_call("get_patient_info", patient_id=pid), _call("order_lab", patient_id=pid, test="troponin_i"),
              _call("generate_ddx", patient_id=pid, top_k=5, scope="common"),
              _call("record_diagnosis", patient_id=pid, icd10_code="I21.19", certainty="confirmed"),
              _call("check_allergy", patient_id=pid, drug="ticagrelor"),
              _call("check_patient_interactions", patient_id=pid, drug="ticagrelor"),
              _call("add_medication", patient_id=pid, drug="ticagrelor", dose=180, unit="mg", route="PO",
                    frequency="once", indication="chest pain"),
              _call("submit_answer", answer="ticagrelor", reasoning="loading dose given")]
    reward, info = 0.0, {}
    for step in steps:
        _, reward, terminated, _, info = env.step(step)
    assert terminated
    return float(reward), info["reward_breakdown"]


def test_skipping_the_stemi_alert_scores_lower_and_is_a_missed_emergency():
    full, full_breakdown = _skipping_run(skip_escalation=False)
    skipped, breakdown = _skipping_run(skip_escalation=True)
    assert full == pytest.approx(1.0) and not full_breakdown["violations"]
    triage = breakdown["details"]["pathway_phases"][0]
    assert triage["coverage"] == pytest.approx(3 / 5) and triage["completed"]
    assert [ph["score"] for ph in breakdown["details"]["pathway_phases"][1:]] == [1.0, 1.0]
    assert "missed_emergency.stemi" in {v["pattern_id"] for v in breakdown["violations"]}
    assert skipped < full and skipped <= 0.1 + 1e-9  # severity 5 caps the total


def test_going_over_the_time_budget_halves_the_phase_score():
    env = _env("diabetic_emergency_dka")
    engine = env.domain_env.extras["engine"]
    pathway = engine.pathway
    for ph in pathway.phases[:2]:
        for action in ph.required_actions:
            assert engine.call(action.name, action.arguments).ok
    insulin = pathway.phases[2]
    assert engine.phase.name == insulin.name and insulin.max_calls == 6
    for _ in range(insulin.max_calls):  # dithering: the dose range looked up again and again
        engine.call("get_dose_range", {"drug": "insulin human", "route": "IV_DRIP", "patient_id": "PW-DM01"})
    for action in insulin.required_actions:
        engine.call(action.name, action.arguments)
    scores = engine.phase_scores()
    assert engine.finished and scores[2]["over_budget"] and scores[2]["coverage"] == 1.0
    assert scores[2]["score"] == 0.5 and scores[1]["score"] == 1.0


def test_a_declared_phase_is_incomplete_until_the_agent_declares_it():
    env = _env("postop_pulmonary_embolism")
    engine = env.domain_env.extras["engine"]
    for ph in engine.pathway.phases:
        for action in ph.required_actions:
            assert engine.call(action.name, action.arguments).ok
    assert not engine.finished and engine.phase.name == "handover"
    assert engine.phase_scores()[-1]["score"] == 0.5  # actions done, completion not declared
    assert engine.call("complete_phase", {"summary": "handed over"}).ok and engine.finished
    assert engine.phase_scores()[-1]["score"] == 1.0


# -- the add_patient hooks --------------------------------------------------------------------------
def _hook(domain: str):
    return cross.add_patient_hook(domain)


@pytest.mark.parametrize("domain", DOMAINS_USED)
def test_hooks_insert_the_pathway_patient_for_the_domain_tools(domain):
    pathway = next(p for p in PATHWAYS if domain in p["patients"])
    env = registry.get_environment(domain)
    pid = _hook(domain)(env, pathway["patients"][domain])
    assert pid == pathway["patient_id"]
    reader = {"triage_emergency": "get_patient_presentation", "clinical_diagnosis": "get_patient_info",
              "drug_interaction": "get_patient_details", "ehr_management": "get_patient_timeline"}[domain]
    out = env.toolkit.call(reader, {"patient_id": pid})
    assert out.ok and out.result["patient_id"] == pid
    with pytest.raises(DataFileError, match="already in the database"):
        _hook(domain)(env, pathway["patients"][domain])


def _broken(domain: str, change) -> dict:
    record = json.loads(json.dumps(next(p for p in PATHWAYS if domain in p["patients"])["patients"][domain]))
    change(record)
    return record


MALFORMED = [
    ("triage_emergency", lambda r: r["vitals"][0].update(heart_rate="fast"), "vitals.0.heart_rate"),
    ("triage_emergency", lambda r: r.pop("chief_complaint"), "chief_complaint"),
    ("triage_emergency", lambda r: r.update(encounter_time="14:00"), "encounter_time"),
    ("clinical_diagnosis", lambda r: r["findings"][0].update(hpo_id="HP:9999999"), "findings.0.hpo_id"),
    ("clinical_diagnosis", lambda r: r["hidden_results"].update(mri_brain={"value": "x", "unit": "text"}),
     "hidden_results.mri_brain"),
    ("clinical_diagnosis", lambda r: r.update(sex="unknown"), "sex"),
    ("drug_interaction", lambda r: r["medications"][0].update(drug="notarealdrugamine"), "medications.0.drug"),
    ("drug_interaction", lambda r: r.update(allergies=[{"allergen": "penicillins", "kind": "family",
                                                        "reaction": "rash", "severity": "mild"}]), "allergies.0.kind"),
    ("drug_interaction", lambda r: r.pop("serum_creatinine_mg_dl"), "serum_creatinine_mg_dl"),
    ("ehr_management", lambda r: r["admissions"][0]["lab_events"][0].update(value="high"),
     "admissions.0.lab_events.0.value"),
    ("ehr_management", lambda r: r["admissions"][0]["vital_events"][0].update(time="yesterday"),
     "admissions.0.vital_events.0"),
    ("ehr_management", lambda r: r.update(encounter_time="2025-03-01T00:00"), "encounter_time"),
]


@pytest.mark.parametrize(("domain", "change", "field"), MALFORMED, ids=[f"{d}:{f}" for d, _, f in MALFORMED])
def test_hooks_reject_a_malformed_record_naming_domain_and_field(domain, change, field):
    env = registry.get_environment(domain)
    with pytest.raises(DataFileError) as excinfo:
        _hook(domain)(env, _broken(domain, change))
    message = str(excinfo.value)
    assert domain in message and field in message, message
    assert not any(pid.startswith("PW-") for pid in env.toolkit.db.patients)  # nothing half-inserted


def test_unknown_pathway_ids_and_unknown_tools_are_rejected_by_the_loaders(tmp_path):
    broken = [dict(PATHWAYS[0], phases=[])]
    path = tmp_path / "pathways.json"
    path.write_text(json.dumps(broken), encoding="utf-8")
    with pytest.raises(DataFileError, match="phases"):
        cross.load_pathways.__wrapped__(path)
    # The split is each case's own `split` field (train or test), so no list of test ids can name an
    # unknown pathway; a bad split value is refused by the case schema (test_cross_domain_cases.py).
