"""`rollout.text_turn_ends_episode` and the env-pool batching keys of the run config reach the
episodes: the config validates them, the Ray env pool built from the config carries them, and a
text turn ends an episode with the same record through the env actors as in the plain loop.
The evaluation's agent condition reports such an end as
"text_answer"."""

from __future__ import annotations

import asyncio
import json

import pytest

from actors.agent_loop import AgentLoop, EpisodeSpec, GoldReplayPolicy, LocalEnv, RolloutLimits
from actors.env_actor import EnvPool, EpisodeLedger, run_episode
from learner.config import ConfigError, RunConfig, load_config
from learner.metrics import episode_index_fields
from tests.training.conftest import NO_EMBEDDINGS

WARD = {"ward": "tests.fixtures.ward_domain.environment"}


def write_config(tmp_path, rollout: dict) -> str:
    import yaml

    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump({"rollout": rollout}))
    return str(path)


def test_the_rollout_keys_validate_and_default_to_todays_behaviour(tmp_path):
    cfg = RunConfig()
    assert (cfg.rollout.text_turn_ends_episode, cfg.rollout.env_batch_calls, cfg.rollout.env_stream_after_s) == \
           (False, True, None)
    assert cfg.rollout.env_kwargs() == {}
    cfg = load_config(write_config(tmp_path, {"text_turn_ends_episode": True, "env_stream_after_s": 0.002}),
                      overrides=["rollout.num_env_actors=3"])
    options = cfg.rollout.env_pool_options()
    assert options["env_kwargs"] == {"text_turn_ends_episode": True}
    assert (options["batch_calls"], options["stream_after_s"], options["num_actors"]) == (True, 0.002, 3)
    for bad, message in (({"text_turn_ends_episode": "maybe"}, "rollout.text_turn_ends_episode"),
                         ({"text_turn_ends_episode": 1}, "rollout.text_turn_ends_episode"),
                         ({"env_batch_calls": "no"}, "rollout.env_batch_calls"),
                         ({"env_stream_after_s": -0.001}, "rollout.env_stream_after_s"),
                         ({"env_batch_calls": False, "env_stream_after_s": 0.002}, "needs env_batch_calls: true"),
                         ({"text_turns_end_episode": True}, "unknown key")):
        with pytest.raises(ConfigError, match=message):
            load_config(write_config(tmp_path, bad))


def text_answer_actions(tasks) -> dict[str, list[str]]:
    """Per task: one lookup, then the answer as plain text (no submit call)."""
    out = {}
    for task in tasks:
        lookup = '<tool_call>{"name": "get_patient", "arguments": {"patient_id": "P1"}}</tool_call>'
        out[task.id] = [lookup, f"The answer is {task.correct_answer}."]
    return out


def ward_specs(tasks, n: int) -> list[EpisodeSpec]:
    return [EpisodeSpec(sample_id=f"{tasks[i % len(tasks)].id}:{i}:{100 + i}", task_id=tasks[i % len(tasks)].id,
                        domain="ward", group_id=f"g{i}", seed=100 + i) for i in range(n)]


@pytest.mark.ray
@pytest.mark.parametrize("batch_calls", [True, False], ids=["batched", "unbatched"])
def test_the_pool_from_the_config_ends_text_turns_as_the_plain_loop_does(ray_cluster, ward_policy_dir, monkeypatch,
                                                                          tmp_path, batch_calls):
    from envs import registry
    from modeling.model import load_tokenizer

    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    cfg = load_config(write_config(tmp_path, {"text_turn_ends_episode": True, "env_batch_calls": batch_calls,
                                              "num_env_actors": 2, "slots_per_env_actor": 3, "max_turns": 4,
                                              "env_vars": NO_EMBEDDINGS}))
    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=4)
    tasks = registry.get_tasks("ward", None)
    specs = ward_specs(tasks, 6)
    loop, policy = AgentLoop(tokenizer, limits), GoldReplayPolicy(tokenizer, text_answer_actions(tasks))

    async def plain(env_kwargs):
        env = LocalEnv(limits.max_turns, env_kwargs)
        return [await loop.run(s, env, policy) for s in specs]

    async def pooled():
        pool = EnvPool(**cfg.rollout.env_pool_options(), domain_modules=WARD)
        assert (pool.batch_calls, pool.stream_after_s, len(pool.actors), pool.slots) == (batch_calls, None, 2, 3)
        await pool.ready()
        ledger = EpisodeLedger()
        for s in specs:
            ledger.admit(s.sample_id)
        samples = await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in specs])
        pings = await pool.ready()
        for actor in pool.actors:
            ray_cluster.kill(actor)
        return samples, pings

    reference = asyncio.run(plain(cfg.rollout.env_kwargs()))
    samples, pings = asyncio.run(pooled())
    assert sum(p["batches"] > 0 for p in pings) == (2 if batch_calls else 0)
    for got, want in zip(samples, reference):
        assert got.sample_id == want.sample_id
        assert (got.input_ids, got.loss_mask, got.reward, got.correct, got.episode) == \
               (want.input_ids, want.loss_mask, want.reward, want.correct, want.episode)
        assert got.metadata["num_turns"] == 2 and not got.truncated
        assert got.episode.metadata["end_reason"] == "text_answer"
        assert got.episode.submitted_answer.startswith("The answer is ")
        assert episode_index_fields(got)["end_reason"] == "text_answer"
    # the gold answer given as text is graded right (the choice letter, the dose's number)
    assert all(s.correct for s in samples if s.task_id in ("ward_choice", "ward_dose"))

    # the default: the same policy's text turn is answered with a reminder, and the episode goes on
    # (the replay repeats its last action) to the turn limit
    default = asyncio.run(plain({}))
    assert all(s.metadata["num_turns"] == 4 and s.truncated for s in default)
    assert all(episode_index_fields(s)["end_reason"] == "turn_limit" for s in default)  # one vocabulary


def test_the_agent_condition_reports_a_text_answer():
    from envs import registry
    from evals.conditions import ConditionSettings, run_agent
    from evals.metrics import row_values
    from evals.types import END_REASONS

    task = {t.id: t for t in registry.get_tasks("ward", None)}["ward_choice"]

    class Chat:
        policy_id = "chat"

        async def reply(self, messages, tools, *, max_tokens, seed):
            from evals.types import PolicyReply

            if len(messages) == 2:
                return PolicyReply(text='<tool_call>{"name": "get_patient", "arguments": {"patient_id": "P1"}}'
                                        '</tool_call>', completion_tokens=5, prompt_tokens=5)
            return PolicyReply(text="Penicillin allergy: the answer is B.", completion_tokens=5, prompt_tokens=5)

    settings = ConditionSettings(max_turns=3, text_turn_ends_episode=True)
    out = asyncio.run(run_agent(Chat(), LocalEnv(3, settings.env_kwargs()), task, "ward", None, 0, settings))
    assert (out.end_reason, out.answer, out.correct, out.turns, out.tool_calls) == ("text_answer", "B", True, 2, 1)
    assert "text_answer" in END_REASONS
    assert row_values({"end_reason": "text_answer", "correct": None}, "accuracy") == {"accuracy": None}
    # without the option the same policy never answers: its text turns end at the turn limit
    out = asyncio.run(run_agent(Chat(), LocalEnv(3), task, "ward", None, 0, ConditionSettings(max_turns=3)))
    assert (out.end_reason, out.answer) == ("parse_failure", None)
    json.dumps(out.messages)  # the transcript stays serialisable


class _PoolBuilt(Exception):
    """Raised by the stand-in EnvPool: the trainer got as far as building its env pool."""


def test_the_trainer_builds_its_env_pool_from_the_rollout_section(tmp_path, monkeypatch, ward_policy_dir):
    """`Trainer._build` passes rollout.text_turn_ends_episode (as env arguments), env_batch_calls and
    env_stream_after_s to the `EnvPool` it creates (the policy, Ray and the other actors stubbed out:
    only the pool's arguments are checked)."""
    import learner.sft
    import learner.train as train

    seen: dict = {}

    def pool(**kwargs):
        seen.update(kwargs)
        raise _PoolBuilt

    monkeypatch.setattr(learner.sft, "prepare_policy", lambda cfg, run_dir, log=None: ward_policy_dir)
    for name, value in (("select_tasks", lambda *a, **k: []), ("init_ray", lambda cfg, log=None: None),
                        ("check_run_fits", lambda cfg: None), ("start_kb_service", lambda cfg: None),
                        ("start_generators", lambda *a: []), ("start_learner", lambda *a: None), ("EnvPool", pool)):
        monkeypatch.setattr(train, name, value)
    cfg = load_config(write_config(tmp_path, {"text_turn_ends_episode": True, "env_batch_calls": True,
                                              "env_stream_after_s": 0.004, "num_env_actors": 3}),
                      overrides=[f"output_dir={tmp_path / 'run'}", "data.domains=[ward]"])
    with pytest.raises(_PoolBuilt):
        train.Trainer(cfg, log=lambda line: None)._build()
    assert seen["env_kwargs"] == {"text_turn_ends_episode": True}
    assert (seen["batch_calls"], seen["stream_after_s"], seen["num_actors"]) == (True, 0.004, 3)
