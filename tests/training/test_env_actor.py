"""The env actor pool: scheduling over actors, and the accounting when an actor dies mid-rollout."""

from __future__ import annotations

import asyncio

import pytest

from actors.agent_loop import AgentLoop, EpisodeSpec, GoldReplayPolicy, RolloutLimits, gold_turn_actions
from actors.env_actor import EnvPool, EpisodeLedger, run_episode
from tests.training.conftest import NO_EMBEDDINGS

pytestmark = pytest.mark.ray
WARD = {"ward": "tests.fixtures.ward_domain.environment"}


@pytest.fixture(scope="module")
def setup(ward_policy_dir):
    from envs import registry
    from modeling.model import load_tokenizer

    tokenizer = load_tokenizer(ward_policy_dir)
    limits = RolloutLimits(max_turns=5)
    tasks = registry.get_tasks("ward", None)
    actions = {t.id: gold_turn_actions(t, limits.max_turns) for t in tasks}
    return tokenizer, limits, tasks, actions


def specs_for(tasks, n):
    out = []
    for i in range(n):
        task = tasks[i % len(tasks)]
        out.append(EpisodeSpec(sample_id=f"{task.id}:{i}:{100 + i}", task_id=task.id, domain="ward",
                               group_id=f"g{i}", group_index=0, seed=100 + i))
    return out


async def run_all(pool, loop, policy, specs, ledger):
    for s in specs:
        ledger.admit(s.sample_id)
    return await asyncio.gather(*[run_episode(s, loop, pool, policy, ledger) for s in specs])


def test_pool_spreads_episodes_and_balances(ray_cluster, setup):
    """Then (same pool) a training group whose first episode fails: the group's error comes only
    once its other episode has ended, so nothing of the dropped group is left running."""
    from actors.generator import GeneratorUnavailableError
    from learner.config import validate_config
    from learner.rollouts import Rollouts

    tokenizer, limits, tasks, actions = setup

    async def go():
        pool = EnvPool(2, 3, limits.max_turns, domain_modules=WARD, env_vars=NO_EMBEDDINGS)
        await pool.ready()
        ledger = EpisodeLedger()
        loop, policy = AgentLoop(tokenizer, limits), GoldReplayPolicy(tokenizer, actions)
        samples = await run_all(pool, loop, policy, specs_for(tasks, 8), ledger)
        pings = await pool.ready()

        failing, other = specs_for(tasks, 2)
        gate = asyncio.Event()

        async def one_generator_out(request):
            if request.request_id.startswith(failing.sample_id + ":"):
                raise GeneratorUnavailableError(f"generate {request.request_id}: no generator came back")
            await gate.wait()  # the other episode is mid-rollout when its sibling fails
            return await policy(request)

        rollouts = Rollouts(validate_config({"data": {"domains": ["ward"]}}), loop, pool, one_generator_out,
                            run_dir=None, log=lambda line: None)
        group_ledger = EpisodeLedger()
        group = asyncio.ensure_future(rollouts.episodes([failing, other], group_ledger))
        while not group_ledger.failed or sum(pool.loads()) > 1:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.1)
        raised_early = group.done()
        gate.set()
        with pytest.raises(GeneratorUnavailableError):
            await group
        group_balance, group_loads = group_ledger.balance(), pool.loads()
        for actor in pool.actors:
            ray_cluster.kill(actor)
        return samples, ledger, pings, group_loads, raised_early, group_balance

    samples, ledger, pings, loads, raised_early, group_balance = asyncio.run(go())
    assert len({s.sample_id for s in samples}) == 8
    assert all(s.correct for s in samples)
    assert all(p["episodes_started"] > 0 for p in pings), pings  # both actors did work
    assert ledger.balance() == {"admitted": 8, "completed": 8, "failed": 0, "in_flight": 0, "reruns": 0, "attempts": 8}
    assert not raised_early, "the group failed while its other episode was still running"
    assert loads == [0, 0]
    assert group_balance == {"admitted": 2, "completed": 1, "failed": 1, "in_flight": 0, "reruns": 0, "attempts": 2}


@pytest.mark.parametrize("batch_calls", [True, False], ids=["batched", "unbatched"])
def test_killed_actor_episodes_rerun_from_start_exactly_once(ray_cluster, setup, batch_calls):
    """Kill an env actor while every episode is mid-rollout: Ray restarts it, its episodes are
    re-run from the start with the same seed, and the ledger balances (nothing lost or doubled),
    with calls batched per actor and with one actor call each."""
    tokenizer, limits, tasks, actions = setup
    specs = specs_for(tasks, 8)

    async def go():
        pool = EnvPool(2, 4, limits.max_turns, domain_modules=WARD, max_restarts=2, env_vars=NO_EMBEDDINGS,
                       batch_calls=batch_calls)
        before = await pool.ready()
        loop = AgentLoop(tokenizer, limits)
        policy = GoldReplayPolicy(tokenizer, actions)
        gate = asyncio.Event()
        started: set[str] = set()

        async def gated(request):
            # Every episode blocks in its second turn until the actor is dead.
            if request.request_id.endswith(":t1") and request.request_id not in started:
                started.add(request.request_id)
                await gate.wait()
            return await policy(request)

        ledger = EpisodeLedger()
        task = asyncio.ensure_future(run_all(pool, loop, gated, specs, ledger))
        while len(started) < 8:
            await asyncio.sleep(0.05)
        on_actor0 = set(pool.in_flight[0])
        ray_cluster.kill(pool.actors[0], no_restart=False)
        await asyncio.sleep(0.5)
        gate.set()
        samples = await task
        after = await pool.ready()
        # Reference: the same specs with no failure.
        clean = EpisodeLedger()
        reference = await run_all(pool, loop, policy, specs, clean)
        for actor in pool.actors:
            ray_cluster.kill(actor)
        return samples, ledger, on_actor0, before, after, reference

    samples, ledger, on_actor0, before, after, reference = asyncio.run(go())
    assert len(on_actor0) == 4
    assert after[0]["incarnation"] != before[0]["incarnation"]  # Ray restarted actor 0
    assert after[1]["incarnation"] == before[1]["incarnation"]
    balance = ledger.balance()
    assert balance == {"admitted": 8, "completed": 8, "failed": 0, "in_flight": 0, "reruns": 4, "attempts": 12}
    rerun = {sid for sid, where in ledger.lost_attempts}
    assert all(where == "env actor 0" for _, where in ledger.lost_attempts)
    assert rerun == {key.split("#")[0] for key in on_actor0}
    assert sorted(s.sample_id for s in samples) == sorted(s.sample_id for s in specs)
    for got, want in zip(samples, reference):  # a re-run is the same episode (same seed, same policy)
        assert got.input_ids == want.input_ids and got.reward == want.reward
        assert got.metadata["attempts"] == (2 if got.sample_id in rerun else 1)
