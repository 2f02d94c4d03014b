"""An episode the agent runner cuts (token limit) is scored by the env, with the domain's own scorer,
exactly as if the env had truncated it at its turn limit (the generic reward would give 0.40 where the
pathway scorer gives 0.0 on this task)."""

from __future__ import annotations

import pytest

from actors.agent_loop import finish_episode, make_env
from envs import registry
from envs.rewards import score_episode

ACTION = '{"name": "think", "arguments": {"thought": "assess the patient before any order"}}'


@pytest.fixture(autouse=True)
def _no_embeddings(monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")


def test_runner_truncation_equals_the_envs_own_truncation_with_the_domain_scorer():
    task = registry.get_tasks("cross_domain", "test")[0]
    at_turn_limit = make_env("cross_domain", "test", max_turns=1)
    at_turn_limit.reset(seed=0, options={"task_id": task.id})
    _, reward, terminated, truncated, info = at_turn_limit.step(ACTION)
    assert truncated and not terminated

    cut = make_env("cross_domain", "test", max_turns=10)
    cut.reset(seed=0, options={"task_id": task.id})
    cut.step(ACTION)
    end = finish_episode(cut)
    assert end.reward == pytest.approx(float(reward))
    assert end.reward_components == pytest.approx(info["reward_components"])
    assert end.is_correct is bool(info["is_correct"])

    # The pathway scorer is what decided: the generic reward scores the same record differently.
    record = cut.unwrapped.trajectory()
    generic = score_episode(record, cut.unwrapped.task, weights=cut.unwrapped.reward_weights,
                            context=cut.unwrapped.domain_env.safety_context)
    assert cut.unwrapped.domain_env.scorer is not None
    assert abs(generic.total - end.reward) > 0.05
    assert record.truncated and record.reward == pytest.approx(end.reward)


def test_truncate_refuses_an_episode_that_is_over_or_not_started():
    env = make_env("cross_domain", "test", max_turns=1)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.truncate("token_limit")
    task = registry.get_tasks("cross_domain", "test")[0]
    env.reset(seed=0, options={"task_id": task.id})
    with pytest.raises(ValueError, match="context_limit.*not one of"):  # one vocabulary of end reasons
        env.unwrapped.truncate("context_limit")
    reward, info = env.unwrapped.truncate("context_overflow")
    assert info["end_reason"] == "context_overflow" and "reward_components" in info
    with pytest.raises(RuntimeError, match=task.id):
        env.unwrapped.truncate("token_limit")
    # A step after the runner ended the episode changes nothing and says so.
    _, step_reward, terminated, _, step_info = env.step(ACTION)
    assert step_info.get("error") == "episode_over" and step_reward == 0.0 and terminated
