"""Clinical content of the authored pathways and workflows: the gold follows the guideline it cites,
and no assertion penalises a correct alternative.

- Severe community-acquired pneumonia (ATS/IDSA 2019, Metlay et al., AJRCCM 2019): a beta-lactam
  plus a macrolide or a respiratory fluoroquinolone; an antipseudomonal beta-lactam only with a
  documented risk factor (a prior respiratory isolate of P. aeruginosa, or a recent hospitalisation
  with parenteral antibiotics).
- Tranexamic acid attributed to CRASH-2 (Lancet 2010) is CRASH-2's fixed regimen: 1 g over 10 minutes
  then 1 g over 8 hours, never a weight-based dose.
- An ACE inhibitor or ARB is held when the patient is hypotensive (SBP < 90) with a rising creatinine
  (KDIGO 2012 acute kidney injury guideline; NICE NG148, 2019).
- Hyperkalaemia (UK Kidney Association 2020): calcium gluconate is a one-off dose and sodium zirconium
  cyclosilicate a course of at most 72 hours, so an assertion must not forbid stopping them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PATHWAYS = {p["id"]: p for p in json.loads((ROOT / "envs/domains/cross_domain/pathways.json").read_text(encoding="utf-8"))}
WORKFLOWS = json.loads((ROOT / "envs/domains/ehr_management/authored/workflows.json").read_text(encoding="utf-8"))["workflows"]

BETA_LACTAMS = {"ceftriaxone", "cefotaxime", "ampicillin and sulbactam", "ceftaroline", "piperacillin and tazobactam",
                "cefepime", "ceftazidime", "meropenem", "imipenem", "aztreonam"}
ANTIPSEUDOMONAL = {"piperacillin and tazobactam", "cefepime", "ceftazidime", "meropenem", "imipenem", "aztreonam"}
MACROLIDE_OR_FQ = {"azithromycin", "clarithromycin", "levofloxacin", "moxifloxacin"}
RAAS = {"ramipril", "lisinopril", "enalapril", "perindopril", "captopril", "losartan", "candesartan", "valsartan",
        "irbesartan"}


def _actions(pathway: dict, phase_index: int | None = None) -> list[dict]:
    phases = pathway["phases"] if phase_index is None else [pathway["phases"][phase_index]]
    return [a for p in phases for a in p["required_actions"]]


def _ordered(pathway: dict) -> set[str]:
    return {a["arguments"]["drug"] for a in _actions(pathway) if a["name"] == "add_medication"}


def _stopped(pathway: dict) -> set[str]:
    return {a["arguments"]["drug"] for a in _actions(pathway) if a["name"] == "discontinue_medication"}


def _text(pathway: dict) -> str:
    return json.dumps(pathway, ensure_ascii=False)


def _adult_cap_pathways() -> list[dict]:
    return [p for p in PATHWAYS.values()
            if "pneumonia" in _text(p).lower() and p["patients"]["drug_interaction"].get("age", 99) >= 18
            and _ordered(p) & BETA_LACTAMS]


def test_severe_adult_pneumonia_gets_a_macrolide_or_fluoroquinolone_with_the_beta_lactam():
    cases = _adult_cap_pathways()
    assert "sepsis_bundle_septic_shock" in {p["id"] for p in cases}
    for p in cases:
        ordered = _ordered(p)
        assert ordered & MACROLIDE_OR_FQ, f"{p['id']}: {sorted(ordered)} has no macrolide or respiratory fluoroquinolone"
        assert "ATS/IDSA 2019" in p["guideline"], p["id"]


def test_antipseudomonal_cover_for_pneumonia_only_with_a_documented_risk_factor():
    for p in _adult_cap_pathways():
        if _ordered(p) & ANTIPSEUDOMONAL:
            record = p["patients"]["clinical_diagnosis"]
            history = json.dumps([record.get("history_of_present_illness"), record.get("past_medical_history"),
                                  p["patients"].get("triage_emergency", {}).get("history")]).lower()
            assert "pseudomonas" in history or "parenteral antibiotics" in history, \
                f"{p['id']}: antipseudomonal beta-lactam without a documented P. aeruginosa risk factor"


def test_tranexamic_acid_attributed_to_crash2_is_its_fixed_regimen():
    sentences = [s for p in PATHWAYS.values() for s in re.split(r"(?<=[.;])\s", _text(p)) if "CRASH-2" in s]
    assert sentences
    for s in sentences:
        assert "mg/kg" not in s, f"weight-based tranexamic acid attributed to CRASH-2: {s!r}"
    p = PATHWAYS["postop_haemorrhage"]
    txa = [a["arguments"] for a in _actions(p) if a["name"] == "add_medication"
           and a["arguments"]["drug"] == "tranexamic acid"]
    assert txa and txa[0]["dose"] == 1000 and txa[0]["unit"] == "mg"
    assert "10 minutes" in txa[0]["frequency"] and "8 hours" in txa[0]["frequency"]


def test_raas_blockers_are_held_in_hypotension_with_a_rising_creatinine():
    checked = []
    for p in PATHWAYS.values():
        ehr = p["patients"].get("ehr_management")
        if not ehr:
            continue
        meds = {m["drug"] for m in p["patients"].get("drug_interaction", {}).get("medications", [])}
        admission = ehr["admissions"][0]
        sbp = [v["systolic_bp"] for v in admission.get("vital_events", [])]
        creat = [e["value"] for e in sorted(admission.get("lab_events", []), key=lambda e: e["time"])
                 if e["test"] == "creatinine"]
        if meds & RAAS and sbp and sbp[-1] < 90 and len(creat) >= 2 and creat[-1] > creat[0]:
            checked.append(p["id"])
            assert meds & RAAS <= _stopped(p), f"{p['id']}: {sorted(meds & RAAS)} left running at SBP {sbp[-1]}"
    assert "postop_haemorrhage" in checked


HYPERKALAEMIA = [w for w in WORKFLOWS if "hyperkal" in w["ticket"].lower()]


def test_hyperkalaemia_assertions_do_not_forbid_stopping_the_binder_or_calcium():
    assert {"ehr_wf_ehr_010", "ehr_wf_ehr_011", "ehr_wf_ehr_012"} <= {w["id"] for w in HYPERKALAEMIA}
    for w in HYPERKALAEMIA:
        for a in w["nl_assertions"]:
            low = a.lower()
            negated = re.search(r"\b(not|never|no|does not|doesn't|keeps|continues)\b", low)
            about = re.search(r"binder|calcium|zirconium|patiromer", low)
            assert not (negated and about), f"{w['id']}: {a!r} penalises stopping a one-off or time-limited treatment"


def test_stopping_the_binder_and_calcium_scores_as_the_gold_on_the_assertions(monkeypatch):
    """Graded: the gold replay that also closes the completed calcium dose and the binder meets the
    same assertions as the gold replay."""
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    from envs import registry
    from envs.rewards.assertions import RuleGrader, grade_assertions
    from envs.rewards.view import EpisodeView
    from envs.validate import gold_replay

    task = next(t for t in registry.get_tasks("ehr_management") if t.id.endswith("ehr_wf_ehr_010"))
    extra = [{"name": "discontinue_order", "arguments": {"patient_id": "EHR-010", "order_id": oid,
                                                          "reason": reason}}
             for oid, reason in (("EHR-010-MED-3", "sodium zirconium cyclosilicate course complete (72 hours)"),
                                 ("EHR-010-MED-4", "calcium gluconate one-off dose given"))]
    stopping = task.model_copy(deep=True)
    stopping.evaluation_criteria.actions = list(stopping.evaluation_criteria.actions) + [
        type(stopping.evaluation_criteria.actions[0]).model_validate({"action_id": f"x{i}", **a, "compare_args": ["patient_id"]})
        for i, a in enumerate(extra)]
    grader = RuleGrader()
    scores = []
    for t in (task, stopping):
        trajectory, _ = gold_replay(t, "ehr_management")
        scores.append(grade_assertions(EpisodeView(trajectory, t), grader))
    gold, stopped = (s.score for s in scores)
    assert stopped >= gold >= 0.9, (gold, stopped)


def test_meningococcal_ceftriaxone_assertion_accepts_the_80_mg_per_kg_dose():
    """IDSA 2004 gives 80-100 mg/kg/day and the BNF for Children (NICE NG240) 80 mg/kg: an assertion that
    only 100 mg/kg is right would penalise the UK dose."""
    p = PATHWAYS["paediatric_fever_meningococcal"]
    dose = [a for ph in p["phases"] for a in ph["nl_assertions"] if "mg/kg" in a]
    assert dose and all("80-100 mg/kg" in a for a in dose), dose
