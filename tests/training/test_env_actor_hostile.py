"""Hostile actions and failing env methods inside the Ray env actors: neither
kills the actor nor loses the batch.

Hostile actions (every reproducer class of tests/core/test_hostile_actions.py, oversized and
non-string actions) go through a live `EnvActor`: every call returns, the episodes end scored, and
the actor is the same process afterwards. A failing env method (a toolkit bug that raises out of
`env.step`) ends only its own episode, as `env_error`, while the rest of the batch completes on the
same actor.

This module is also the "ward_faulty" test domain the actors import (`get_environment`,
`get_tasks`, `get_splits` below): the ward domain with a toolkit that raises on one patient id.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from actors.agent_loop import AgentLoop, EpisodeSpec, GoldReplayPolicy, RolloutLimits, gold_turn_actions
from actors.env_actor import EnvActor, EnvPool, EpisodeLedger, run_episode
from envs.core.domain import DomainEnvironment, read_policy
from envs.core.tools import CompositeToolkit, ToolOutcome
from tests.fixtures.ward_domain import environment as ward
from tests.training.conftest import NO_EMBEDDINGS

pytestmark = pytest.mark.ray
DOMAINS = {"ward": "tests.fixtures.ward_domain.environment", "ward_faulty": __name__}
CRASH = 'get_patient(patient_id="EXPLODE")'


# -- the faulty test domain ---------------------------------------------------------------------
class ExplodingToolkit(CompositeToolkit):
    """The ward's tools, with a dispatch bug: a lookup of patient "EXPLODE" raises out of `call`
    (which real toolkits never do: it is the kind of failure only a bug produces)."""

    def call(self, name: str, arguments: Any) -> ToolOutcome:
        if isinstance(arguments, dict) and arguments.get("patient_id") == "EXPLODE":
            raise RuntimeError("toolkit bug: dispatch failed")
        return super().call(name, arguments)


def get_environment() -> DomainEnvironment:
    db = ward.WardDB.model_validate_json(ward._DB_JSON)
    return DomainEnvironment(name="ward_faulty", policy=read_policy(ward.HERE),
                             toolkit=ExplodingToolkit(ward.WardTools(db), ward.SharedNotes()))


def get_tasks(split: str | None = None):
    return ward.get_tasks(split)


def get_splits() -> dict[str, list[str]]:
    return ward.get_splits()


# -- helpers -------------------------------------------------------------------------------------
def spec_for(task_id: str, index: int, domain: str = "ward") -> EpisodeSpec:
    return EpisodeSpec(sample_id=f"{task_id}:{index}:{100 + index}", task_id=task_id, domain=domain,
                       group_id=f"g{index}", group_index=0, seed=100 + index)


def new_actor(ray, max_turns: int = 3):
    cls = ray.remote(EnvActor).options(max_restarts=0, num_cpus=0, runtime_env={"env_vars": NO_EMBEDDINGS})
    return cls.remote(0, max_turns, 4, None, DOMAINS)


def hostile_actions() -> list[Any]:
    from tests.core.test_hostile_actions import NON_TERMINAL, deep, hermes

    actions: list[Any] = [action for action, _ in NON_TERMINAL.values()]
    actions += [
        "\n".join(f'get_patient(patient_id="zq{i:04d}xkv")' for i in range(3300)),  # over the call cap
        "x" * 100_001,  # over the action size limit
        hermes("submit_answer", '{"answer": "\\ud800 lone surrogate \\udfff"}'),  # terminal, NL grader
        hermes("submit_answer", '{"answer": "x", "n": %s}' % ("9" * 400)),
        hermes("submit_answer", '{"answer": %s}' % deep(900)),
        None, 12, b"bytes", ["a", "list"],  # not even a string (a broken generator client)
    ]
    return actions


# -- tests ---------------------------------------------------------------------------------------
def test_hostile_actions_never_raise_inside_the_actor(ray_cluster):
    ray = ray_cluster
    actor = new_actor(ray)
    before = ray.get(actor.ping.remote())
    episode, ended = 0, 0
    key = f"e{episode}"
    ray.get(actor.reset.remote(key, spec_for("ward_choice", episode).model_dump()))
    try:
        for action in hostile_actions():
            observation, reward, terminated, truncated, info = ray.get(actor.step.remote(key, action))
            assert isinstance(observation, str) and observation, repr(action)[:80]
            assert "env_error" not in info, info["env_error"]
            if terminated or truncated:
                ended += 1
                end = info["end"]
                assert end.reward == reward and set(end.reward_components) >= {"accuracy", "total"}
                ray.get(actor.release.remote(key))
                episode += 1
                key = f"e{episode}"
                ray.get(actor.reset.remote(key, spec_for("ward_choice", episode).model_dump()))
        after = ray.get(actor.ping.remote())
    finally:
        ray.kill(actor)
    assert ended >= 5
    assert (after["pid"], after["incarnation"]) == (before["pid"], before["incarnation"])  # never restarted
    assert after["env_errors"] == 0 and after["episodes_started"] == episode + 1


def test_failing_env_method_ends_only_its_episode_and_the_batch_completes(ray_cluster, ward_policy_dir):
    from modeling.model import load_tokenizer

    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=5)
    tasks = ward.get_tasks(None)
    # ward_choice episodes hit the toolkit bug on their first turn; the others replay the gold answer
    actions = {t.id: gold_turn_actions(t, limits.max_turns) for t in tasks}
    actions["ward_choice"] = [CRASH]
    specs = [spec_for(tasks[i % len(tasks)].id, i, domain="ward_faulty") for i in range(6)]

    async def go():
        pool = EnvPool(1, 4, limits.max_turns, domain_modules=DOMAINS, max_restarts=0, env_vars=NO_EMBEDDINGS)
        before = await pool.ready()
        ledger = EpisodeLedger()
        for spec in specs:
            ledger.admit(spec.sample_id)
        samples = await asyncio.gather(*[run_episode(spec, AgentLoop(tokenizer, limits), pool,
                                                     GoldReplayPolicy(tokenizer, actions), ledger) for spec in specs])
        after = await pool.ready()
        for actor in pool.actors:
            ray_cluster.kill(actor)
        return samples, ledger, before, after

    samples, ledger, before, after = asyncio.run(go())
    assert ledger.balance() == {"admitted": 6, "completed": 6, "failed": 0, "in_flight": 0, "reruns": 0, "attempts": 6}
    assert after[0]["incarnation"] == before[0]["incarnation"] and after[0]["env_errors"] == 2
    for sample in samples:
        if sample.task_id == "ward_choice":
            assert sample.reward == 0.0 and not sample.correct and sample.metadata["truncation"] == "env_error"
            error = sample.metadata["env_error"]
            assert "RuntimeError: toolkit bug: dispatch failed" in error and "ward_faulty/ward_choice" in error
        else:
            assert sample.correct and "env_error" not in sample.metadata, sample.metadata


def test_finish_after_the_episode_ended_returns_the_same_end(ray_cluster):
    ray = ray_cluster
    actor = new_actor(ray)
    try:
        ray.get(actor.reset.remote("k", spec_for("ward_dose", 0).model_dump()))
        first = ray.get(actor.finish.remote("k", "token_limit"))
        assert first.env_error is None and set(first.reward_components) >= {"accuracy", "total"}
        again = ray.get(actor.finish.remote("k", "turn_limit"))  # the env's finish is idempotent
        assert again == first and again.reason == "token_limit"
        ray.get(actor.release.remote("k"))  # a healthy env goes back to the idle pool
        ray.get(actor.reset.remote("k2", spec_for("ward_dose", 1).model_dump()))
        pong = ray.get(actor.ping.remote())
    finally:
        ray.kill(actor)
    assert pong["env_errors"] == 0 and pong["active"] == 1


def test_a_group_with_an_env_error_is_dropped_not_trained_on(ray_cluster, ward_policy_dir, tmp_path):
    """Training side: a group in which an env error ended an episode is marked failed (the batching
    consumer drops and logs it) instead of training on its unscored reward 0 or stopping the run."""
    from learner.config import RunConfig
    from modeling.model import load_tokenizer
    from learner.rollouts import Rollouts
    from learner.tasks import TaskRef

    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=5)
    actions = {t.id: gold_turn_actions(t, limits.max_turns) for t in ward.get_tasks(None)}
    actions["ward_choice"] = [CRASH]
    cfg = RunConfig.model_validate({"rollout": {"group_size": 2}})

    async def go():
        pool = EnvPool(1, 4, limits.max_turns, domain_modules=DOMAINS, max_restarts=0, env_vars=NO_EMBEDDINGS)
        await pool.ready()
        rollouts = Rollouts(cfg, AgentLoop(tokenizer, limits), pool, GoldReplayPolicy(tokenizer, actions), tmp_path,
                            log=lambda _: None)
        broken = await rollouts.group(0, TaskRef("ward_faulty", "ward_choice", None), 0)
        healthy = await rollouts.group(1, TaskRef("ward_faulty", "ward_dose", None), 0)
        for actor in pool.actors:
            ray_cluster.kill(actor)
        return broken, healthy, rollouts.ledger.balance()

    broken, healthy, balance = asyncio.run(go())
    assert broken.failed.startswith("env_error in 2 of 2 episodes: env actor 0: step of episode")
    assert broken.error is None and not broken.samples
    assert not healthy.failed and len(healthy.samples) == 2 and all(s.correct for s in healthy.samples)
    assert balance["completed"] == 4 and balance["failed"] == 0


def test_an_eval_episode_ended_by_an_env_error_says_so():
    from envs.episode import EpisodeEnd
    from evals.conditions import EpisodeOutcome, _apply_end

    outcome = EpisodeOutcome(end_reason="env_error")
    _apply_end(outcome, EpisodeEnd.failed("env actor 0: step of episode 'k' (ward_faulty/ward_choice) failed: RuntimeError: x"))
    assert outcome.error_kind == "env_error" and "RuntimeError: x" in outcome.extra["env_error"]
    assert outcome.reward == 0.0 and outcome.correct is False
    plain = EpisodeOutcome(end_reason="answer")
    _apply_end(plain, EpisodeEnd(reason="answer", terminated=True, truncated=False, reward=1.0, is_correct=True))
    assert plain.error_kind is None and "env_error" not in plain.extra
