"""Batched env-actor calls: `EnvActor.batch` / `batch_stream` answer every call
on its own (one bad episode never fails the batch), `_ActorBatcher` coalesces concurrent episodes'
calls, and the batched and streamed pools give the same trajectories as the unbatched pool and the
in-process loop.

The first tests run `EnvActor` in this process (no Ray): a batch is a list of pickled calls.
"""

from __future__ import annotations

import asyncio
import pickle

import pytest

from actors.agent_loop import AgentLoop, EpisodeSpec, GoldReplayPolicy, LocalEnv, RolloutLimits, gold_turn_actions
from actors.env_actor import EnvActor, EnvActorLost, EnvPool, EpisodeLedger, EpisodeNotFoundError, run_episode
from tests.training.conftest import NO_EMBEDDINGS
from tests.training.test_env_actor_hostile import CRASH, DOMAINS

WARD = {"ward": DOMAINS["ward"]}


def call(method: str, key: str, *args) -> bytes:
    return pickle.dumps((method, key, args))


def spec(task_id: str, index: int, domain: str = "ward") -> dict:
    return EpisodeSpec(sample_id=f"{task_id}:{index}:{100 + index}", task_id=task_id, domain=domain,
                       group_id=f"g{index}", seed=100 + index).model_dump()


def answers(actor: EnvActor, calls: list[bytes]) -> list[tuple[bool, object]]:
    return [(ok, pickle.loads(data)) for ok, data in actor.batch(calls)]


@pytest.fixture
def actor(monkeypatch):
    from envs import registry

    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    monkeypatch.setitem(registry.DOMAINS, "ward_faulty", DOMAINS["ward_faulty"])
    return EnvActor(0, max_turns=5, slots=3)


def test_batch_runs_calls_in_order_and_isolates_each_failure(actor):
    """Every kind of bad call sits between good ones in one batch; each fails alone, named, and the
    good calls (including later calls of the same episodes) still run."""
    gold = gold_turn_actions(next(t for t in _ward_tasks() if t.id == "ward_dose"), 5)
    got = answers(actor, [
        call("reset", "a", spec("ward_dose", 0)),
        call("step", "ghost", "anything"),                        # no such episode
        b"not a pickle",                                           # a corrupt payload
        call("ping", "a"),                                         # not a batched method
        call("reset", "b", {"task_id": "ward_dose"}),              # an invalid spec
        call("reset", "c", spec("no_such_task", 1)),               # an unknown task
        call("reset", "x", spec("ward_choice", 2, domain="ward_faulty")),
        call("step", "x", CRASH),                                  # the env raises: env_error, not an exception
        call("step", "a", gold[0]),                                # episode "a" goes on after all of that
        call("reset", "a", spec("ward_dose", 3)),                  # already active
    ])
    ok = [flag for flag, _ in got]
    assert ok == [True, False, False, False, False, False, True, True, True, False]
    assert got[0][1][1]["task_id"] == "ward_dose"
    assert isinstance(got[1][1], EpisodeNotFoundError) and "'ghost'" in str(got[1][1])
    assert isinstance(got[2][1], pickle.UnpicklingError)
    assert isinstance(got[3][1], ValueError) and "'ping'" in str(got[3][1]) and "release" in str(got[3][1])
    assert "sample_id" in str(got[4][1])  # pydantic names the missing field
    assert "no_such_task" in str(got[5][1])
    observation, reward, terminated, truncated, info = got[7][1]
    assert truncated and reward == 0.0 and "toolkit bug" in info["env_error"]
    assert isinstance(got[8][1][0], str) and "env_error" not in got[8][1][4]
    assert isinstance(got[9][1], ValueError) and "already active" in str(got[9][1])
    pong = actor.ping()
    assert pong["batches"] == 1 and pong["batched_calls"] == 10 and pong["active"] == 2  # "a" and "x"
    assert pong["env_errors"] == 1


def test_batch_answers_an_unpicklable_result_as_that_calls_error(actor, monkeypatch):
    """A result that cannot cross the process boundary fails its own call, not its neighbours'."""
    real_step = EnvActor.step

    def step(self, key, action):
        out = real_step(self, key, action)
        return (*out[:4], {**out[4], "handle": (lambda: None)}) if key == "bad" else out

    monkeypatch.setattr(EnvActor, "step", step)
    action = '<tool_call>{"name": "list_patients", "arguments": {}}</tool_call>'
    got = answers(actor, [call("reset", "bad", spec("ward_dose", 0)), call("reset", "good", spec("ward_dose", 1)),
                          call("step", "bad", action), call("step", "good", action)])
    assert [flag for flag, _ in got] == [True, True, False, True]
    assert isinstance(got[2][1], Exception) and "pickle" in f"{type(got[2][1]).__name__}: {got[2][1]}".lower()


def test_batch_stream_yields_every_answer_once_in_order_in_chunks(actor):
    """The streamed batch answers the same calls the same way as `batch`, in order, each exactly
    once: a chunk per call when every call takes longer than the flush interval, one chunk when none does."""
    action = '<tool_call>{"name": "list_patients", "arguments": {}}</tool_call>'
    calls = [call("reset", "s1", spec("ward_dose", 0)), call("step", "nobody", action),
             call("reset", "s2", spec("ward_dose", 1)), call("step", "s1", action), call("step", "s2", action)]
    every = list(actor.batch_stream(calls, 0.0))
    assert [start for start, _ in every] == [0, 1, 2, 3, 4] and all(len(chunk) == 1 for _, chunk in every)
    assert [ok for _, chunk in every for ok, _ in chunk] == [True, False, True, True, True]
    for key in ("s1", "s2"):
        actor.release(key)
    whole = list(actor.batch_stream(calls, 3600.0))
    assert len(whole) == 1 and whole[0][0] == 0
    again = [(ok, pickle.loads(data)) for ok, data in whole[0][1]]
    first = [(ok, pickle.loads(data)) for _, chunk in every for ok, data in chunk]
    assert [ok for ok, _ in again] == [ok for ok, _ in first]
    assert again[3][1][0] == first[3][1][0]  # the same observation from the same seed
    assert actor.ping()["batches"] == 2 and actor.ping()["batched_calls"] == 10


def _ward_tasks():
    from envs import registry

    return registry.get_tasks("ward", None)


# -- through Ray ------------------------------------------------------------------------------------
def ward_setup(ward_policy_dir):
    from modeling.model import load_tokenizer

    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=5)
    actions = {t.id: gold_turn_actions(t, limits.max_turns) for t in _ward_tasks()}
    return tokenizer, limits, actions


def ward_specs(n: int) -> list[EpisodeSpec]:
    tasks = _ward_tasks()
    return [EpisodeSpec.model_validate(spec(tasks[i % len(tasks)].id, i)) for i in range(n)]


@pytest.mark.ray
def test_batched_and_streamed_pools_give_the_unbatched_pools_and_the_plain_loops_trajectories(ray_cluster, ward_policy_dir,
                                                                                  monkeypatch):
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    tokenizer, limits, actions = ward_setup(ward_policy_dir)
    specs = ward_specs(12)
    loop, policy = AgentLoop(tokenizer, limits), GoldReplayPolicy(tokenizer, actions)

    async def plain():
        env = LocalEnv(limits.max_turns)
        return [await loop.run(s, env, policy) for s in specs]

    async def pooled(batch_calls: bool, stream_after_s: float | None):
        pool = EnvPool(2, 4, limits.max_turns, domain_modules=WARD, env_vars=NO_EMBEDDINGS, batch_calls=batch_calls,
                       stream_after_s=stream_after_s)
        await pool.ready()
        ledger = EpisodeLedger()
        for s in specs:
            ledger.admit(s.sample_id)
        samples = await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in specs])
        pings = await pool.ready()
        for a in pool.actors:
            ray_cluster.kill(a)
        return samples, ledger.balance(), pings, pool.loads()

    reference = asyncio.run(plain())
    for batch_calls, stream_after_s in ((True, 0.002), (True, 0.0), (True, None), (False, None)):
        samples, balance, pings, loads = asyncio.run(pooled(batch_calls, stream_after_s))
        assert balance["completed"] == 12 and balance["reruns"] == 0 and loads == [0, 0]
        for got, want in zip(samples, reference):
            assert got.sample_id == want.sample_id
            assert (got.input_ids, got.loss_mask, got.reward, got.correct, got.episode) == \
                   (want.input_ids, want.loss_mask, want.reward, want.correct, want.episode)
        calls = sum(p["batched_calls"] for p in pings)
        batches = sum(p["batches"] for p in pings)
        if batch_calls:
            # 12 resets + the steps + 12 releases, and far fewer actor calls than that
            assert calls >= 12 * 3 and batches < calls / 2, (calls, batches)
        else:
            assert calls == 0 and batches == 0


@pytest.mark.ray
def test_an_unsendable_action_fails_only_its_episode(ray_cluster, ward_policy_dir, monkeypatch):
    """An action that cannot be pickled (a broken generator client) raises a TypeError naming the
    episode for that episode alone; the other episodes sharing the actor complete."""
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    tokenizer, limits, actions = ward_setup(ward_policy_dir)
    specs = ward_specs(4)

    async def go():
        pool = EnvPool(1, 4, limits.max_turns, domain_modules=WARD, env_vars=NO_EMBEDDINGS)
        await pool.ready()
        envs = [await pool.lease(s) for s in specs]
        await asyncio.gather(*[e.reset(s) for e, s in zip(envs, specs)])
        results = await asyncio.gather(
            envs[0].step(lambda: "not data"),
            *[e.step(actions[s.task_id][0]) for e, s in zip(envs[1:], specs[1:])], return_exceptions=True)
        for e in envs:
            await pool.give_back(e)
        pong = (await pool.ready())[0]
        for a in pool.actors:
            ray_cluster.kill(a)
        return results, pong

    results, pong = asyncio.run(go())
    assert isinstance(results[0], TypeError) and specs[0].sample_id in str(results[0]) and "step" in str(results[0])
    assert all(isinstance(r, tuple) and isinstance(r[0], str) for r in results[1:]), results
    assert pong["active"] == 0 and pong["batches"] >= 2


@pytest.mark.ray
@pytest.mark.parametrize("stream_after_s", [None, 0.0], ids=["whole", "streamed"])
def test_a_batch_lost_with_its_actor_fails_every_call_as_env_actor_lost(ray_cluster, ward_policy_dir, monkeypatch,
                                                                        stream_after_s):
    """Every episode whose call was in a batch when the actor died gets EnvActorLost (so run_episode
    re-runs it); killing the actor with `no_restart=True` makes the loss permanent."""
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    specs = ward_specs(3)

    async def go():
        pool = EnvPool(1, 3, 5, domain_modules=WARD, env_vars=NO_EMBEDDINGS, max_restarts=0,
                       stream_after_s=stream_after_s)
        await pool.ready()
        envs = [await pool.lease(s) for s in specs]
        await asyncio.gather(*[e.reset(s) for e, s in zip(envs, specs)])
        ray_cluster.kill(pool.actors[0], no_restart=True)
        # ray.kill returns before the actor is gone: a batch sent at once could still be served
        # (seen once in a full-suite run); wait until the actor no longer answers
        for _ in range(600):
            try:
                await pool.actors[0].ping.remote()
            except ray_cluster.exceptions.RayActorError:
                break
            await asyncio.sleep(0.05)
        else:
            raise AssertionError("the killed env actor still answers after 30 s")
        return await asyncio.gather(*[e.step("hello") for e in envs], return_exceptions=True)

    results = asyncio.run(go())
    assert all(isinstance(r, EnvActorLost) for r in results), results
    for r, s in zip(results, specs):  # each error names its own episode
        assert f"episode '{s.sample_id}#" in str(r) and "during step" in str(r)


@pytest.mark.ray
def test_switching_call_modes_between_passes_strands_no_release(ray_cluster, ward_policy_dir, monkeypatch):
    """Releases are not awaited; when the pool's call mode changes their batcher is replaced, and
    what it still holds is sent first: no slot stays busy in the actor ("all 2 slots are busy")."""
    monkeypatch.setenv("HCGYM_EMBEDDINGS", "0")
    tokenizer, limits, actions = ward_setup(ward_policy_dir)
    loop, policy = AgentLoop(tokenizer, limits), GoldReplayPolicy(tokenizer, actions)
    modes = [(True, 0.002), (True, None), (False, None), (True, 0.0), (True, None)]

    async def go():
        pool = EnvPool(1, 2, limits.max_turns, domain_modules=WARD, env_vars=NO_EMBEDDINGS, max_restarts=0)
        await pool.ready()
        passes = []
        for number, (batch_calls, stream_after_s) in enumerate(modes):
            pool.batch_calls, pool.stream_after_s = batch_calls, stream_after_s
            specs = [EpisodeSpec.model_validate({**spec(t.id, i), "sample_id": f"{t.id}:p{number}:{i}"})
                     for i, t in enumerate(_ward_tasks() * 2)]
            ledger = EpisodeLedger()
            for s in specs:
                ledger.admit(s.sample_id)
            passes.append(await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in specs]))
        pool.batch_calls = False  # sends what the last batcher holds
        pool.batcher(0)
        await asyncio.sleep(0.5)
        pong = (await pool.ready())[0]
        for a in pool.actors:
            ray_cluster.kill(a)
        return passes, pong

    passes, pong = asyncio.run(go())
    assert all(s.correct and s.metadata["attempts"] == 1 for samples in passes for s in samples)
    assert [[s.input_ids for s in samples] for samples in passes[1:]] == [[s.input_ids for s in passes[0]]] * 4
    assert pong["active"] == 0 and pong["episodes_started"] == 5 * 2 * len(_ward_tasks())
