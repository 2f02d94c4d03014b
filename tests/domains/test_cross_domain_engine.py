"""The pathway engine over the ward test domain (two phases, tools switching, scoring)."""

import json

import pytest

from envs.core.task import ExpectedAction
from envs.domains.cross_domain import environment as cross
from envs.domains.cross_domain.pathway import Pathway, PathwayEngine
from tests.fixtures.ward_domain import environment as ward

PATHWAY = Pathway.model_validate({
    "id": "ward_path", "title": "Ward admission", "presentation": "Zoe, 40, admitted with cellulitis.",
    "patient_id": "P7",
    "patients": {"ward": {"patient_id": "P7", "name": "Zoe", "age": 40, "weight_kg": 60.0}},
    "phases": [
        {"name": "history", "domain": "ward", "goal": "Review the chart.",
         "required_actions": [{"name": "get_patient", "arguments": {"patient_id": "P7"}, "compare_args": ["patient_id"]}],
         "nl_assertions": ["Reviews the chart"]},
        {"name": "dosing", "domain": "ward", "goal": "Dose cefazolin 20 mg/kg.", "time_pressure": True, "max_calls": 2,
         "required_actions": [{"name": "dose_for_weight", "arguments": {"patient_id": "P7", "mg_per_kg": 20}, "compare_args": ["patient_id", "mg_per_kg"]}]},
        {"name": "handover", "domain": "ward", "goal": "Declare handover.", "transition": "agent_declares"},
    ],
    "final_question": "What dose (mg) did you give?", "final_answer": "1200",
})


def engine():
    env = ward.get_environment()
    ward.add_patient(env, PATHWAY.patients["ward"])
    return PathwayEngine(PATHWAY, {"ward": env})


def test_phases_advance_when_required_actions_are_done():
    eng = engine()
    assert eng.status()["active_phase"] == "history" and eng.status()["still_required"] == ["get_patient"]
    out = eng.call("get_patient", {"patient_id": "P7"})
    assert out.ok and out.result["pathway"]["next_phase"] == "dosing" and out.result["result"]["name"] == "Zoe"
    assert eng.call("dose_for_weight", {"patient_id": "P7", "mg_per_kg": 20}).result["pathway"]["next_phase"] == "handover"
    assert eng.status()["active_phase"] == "handover"
    assert eng.call("complete_phase", {"summary": "done"}).result["next"] is None
    assert eng.finished and "submit_answer" in eng.definitions and "get_patient" not in eng.definitions
    assert [p["score"] for p in eng.phase_scores()] == [1.0, 1.0, 1.0]


def test_time_budget_and_missing_actions_lower_phase_scores():
    eng = engine()
    eng.call("get_patient", {"patient_id": "P7"})
    for _ in range(3):  # wrong dose three times: over the 2-call budget, action never matched
        eng.call("dose_for_weight", {"patient_id": "P7", "mg_per_kg": 10})
    eng.call("complete_phase", {"summary": "skipping"})
    scores = {p["phase"]: p for p in eng.phase_scores()}
    assert scores["dosing"]["coverage"] == 0.0 and scores["dosing"]["over_budget"]
    assert scores["handover"]["completed"] is False and scores["handover"]["score"] == 0.5


def test_unknown_domain_rejected_and_tools_switch():
    with pytest.raises(ValueError, match="no environment for domain"):
        PathwayEngine(PATHWAY, {})
    eng = engine()
    assert "get_pathway_status" in eng.definitions and "dose_for_weight" in eng.definitions


def test_pathway_episode_reward_is_the_pathway_score(monkeypatch):
    from envs import registry
    from envs.env import HealthcareGymEnv

    monkeypatch.setattr(cross, "load_pathways", lambda path=None: {PATHWAY.id: PATHWAY})
    monkeypatch.setitem(registry.DOMAINS, "cross_domain", "envs.domains.cross_domain.environment")
    registry.domain_module.cache_clear()
    env = HealthcareGymEnv(domain="cross_domain", task_id="pathway_ward_path", max_turns=10)
    obs, info = env.reset(seed=0)
    assert "get_pathway_status" in obs and "get_patient" in obs
    def call(name, **a):
        return "<tool_call>" + json.dumps({"name": name, "arguments": a}) + "</tool_call>"
    env.step(call("get_patient", patient_id="P7"))
    env.step(call("dose_for_weight", patient_id="P7", mg_per_kg=20))
    env.step(call("complete_phase", summary="handover done"))
    _, reward, terminated, _, info = env.step(call("submit_answer", answer="1200"))
    details = info["reward_breakdown"]["details"]
    assert terminated and [p["score"] for p in details["pathway_phases"]] == [1.0, 1.0, 1.0]
    assert reward == pytest.approx(min(1.0, details["pathway_overall"] - info["reward_breakdown"]["penalty"]))
    assert details["pathway_overall"] == pytest.approx(1.0)
