"""The reward inside the real environment: gold replays of a registered domain score cleanly, and
the env's terminal reward and info["reward_components"] come from score_episode."""

from __future__ import annotations

import json
import random

import pytest

from envs import registry
from envs.rewards import score_episode


def _domain_tasks(name: str):
    try:
        return registry.get_tasks(name)
    except Exception as exc:  # data not built on this machine: nothing to replay
        pytest.skip(f"domain {name!r} unavailable: {type(exc).__name__}: {exc}")


def _call(name: str, arguments: dict) -> str:
    return "<tool_call>" + json.dumps({"name": name, "arguments": arguments}) + "</tool_call>"


def test_gold_replays_of_the_drug_interaction_domain_score_cleanly():
    from envs.env import HealthcareGymEnv

    tasks = [t for t in _domain_tasks("drug_interaction") if t.has_gold_answer]
    sample = random.Random(7).sample(tasks, min(24, len(tasks)))
    env = HealthcareGymEnv(domain="drug_interaction", max_turns=40)
    for task in sample:
        env.reset(options={"task_id": task.id})
        for action in task.evaluation_criteria.actions:
            if action.name != "submit_answer":
                env.step(_call(action.name, action.arguments))
        _, reward, terminated, _, info = env.step(_call("submit_answer", {"answer": task.correct_answer}))
        assert terminated
        breakdown = info["reward_breakdown"]
        assert info["is_correct"], (task.id, breakdown["details"]["accuracy"])
        assert breakdown["violations"] == [], (task.id, breakdown["violations"])
        assert breakdown["grader_errors"] == [], (task.id, breakdown["grader_errors"])
        comps = info["reward_components"]
        assert reward == pytest.approx(comps["total"])
        # a gold replay is right, safe, well-formed and coherent; NL assertions graded by rules can
        # be partial because a replay writes no reasoning, so they are not asserted here
        assert (comps["accuracy"], comps["safety"], comps["format"], comps["coherence"]) == (1.0, 1.0, 1.0, 1.0), (task.id, comps)
        assert comps["process"] >= 0.9, (task.id, breakdown["details"]["process"])
        # the env's numbers are score_episode's numbers
        again = score_episode(info["trajectory"], task, context=env.domain_env.safety_context)
        assert again.components() == info["reward_components"]
