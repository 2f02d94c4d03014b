"""The driver's batch assembly (FIFO, dynamic sampling, staleness) and its reward / task helpers,
without Ray: groups of real `RolloutSample`s are handed to the consumer directly."""

from __future__ import annotations

import asyncio

import pytest

from actors.types import RolloutSample, TurnSpan
from learner.config import ConfigError, validate_config
from learner.batching import BatchScheduler
from learner.train import Group, TaskRef, TaskSampler, episode_seed, is_correct, mixed_outcomes, shape_reward


def sample(seq: int, i: int, *, correct: bool, reward: float = 0.5, truncation: str = "", length: int = 4):
    ids = list(range(10, 16)) + list(range(20, 20 + length))
    mask = [0] * 6 + [1] * length
    return RolloutSample(
        sample_id=f"t{seq}:{i}:{seq * 10 + i}", task_id=f"t{seq}", domain="ward", group_id=f"g{seq}",
        seed=seq * 10 + i, prompt_length=6, input_ids=ids, loss_mask=mask, sampling_logprobs=[0.0] * len(ids),
        policy_versions=[-1] * 6 + [0] * length, turns=[TurnSpan(start=6, end=6 + length)], reward=reward,
        env_reward=reward, env_correct=correct,
        reward_components={"accuracy": float(correct), "total": reward}, correct=correct,
        truncated=bool(truncation), response_tokens=length,
        metadata={"truncation": truncation},
    )


def group(seq: int, *, outcomes=(True, False), admit_version: int = 0, failed: str | None = None) -> Group:
    samples = [sample(seq, i, correct=c) for i, c in enumerate(outcomes)]
    return Group(seq=seq, task=TaskRef("ward", f"t{seq}", "train"), admit_version=admit_version, samples=samples,
                 accepted=failed is None and len(set(outcomes)) > 1, failed=failed)


def trainer(**trainer_cfg) -> BatchScheduler:
    cfg = validate_config({"trainer": {"batch_size": 3, **trainer_cfg}, "data": {"domains": ["ward"]}})
    return BatchScheduler(cfg.trainer, log=lambda line: None)


def collect(t: BatchScheduler, groups: list[Group], late: list[Group] = ()):
    async def go():
        for g in groups:
            t.completed[g.seq] = g
        task = asyncio.ensure_future(t.collect_batch())
        for g in late:  # completes after the consumer started waiting
            await asyncio.sleep(0.01)
            assert not task.done(), "the consumer must wait for the FIFO head"
            async with t.cond:
                t.completed[g.seq] = g
                t.cond.notify_all()
        return await task

    return asyncio.run(go())


def test_fifo_order_filtering_and_failures():
    t = trainer()
    groups = [group(0), group(1, outcomes=(True, True)), group(2), group(3, failed="EnvActorLost: x"), group(4)]
    batch, info = collect(t, groups)
    assert [g.seq for g in batch] == [0, 2, 4]
    assert info["filtered_groups_frac"] == pytest.approx(1 / 5) and info["groups_failed"] == 1
    assert t.consume_seq == 5 and info["groups_filled"] == 0


def test_consumer_waits_for_the_head_of_the_line():
    t = trainer()
    batch, _ = collect(t, [group(1), group(2)], late=[group(0)])
    assert [g.seq for g in batch] == [0, 1, 2]


def test_bounded_attempts_top_up_with_filtered_groups():
    t = trainer(dynamic_sampling={"max_admissions_factor": 1.0})  # inspect at most 3 groups
    groups = [group(0, outcomes=(False, False)), group(1), group(2, outcomes=(True, True)), group(3)]
    batch, info = collect(t, groups)
    assert [g.seq for g in batch] == [0, 1, 2]  # 1 kept, then the 2 latest filtered ones
    assert info["groups_filled"] == 2 and t.counters["short_batches"] == 1
    assert t.group_status == {0: "filled", 2: "filled"}
    assert t.consume_seq == 3  # group 3 waits for the next step


def test_groups_failed_by_a_generator_outage_are_replaced_without_using_the_budget():
    # A budget of one batch (3 groups). Four groups failed waiting for a generator: the batch is still full.
    t = trainer(dynamic_sampling={"max_admissions_factor": 1.0})
    out = [group(seq, failed="GeneratorUnavailableError: x") for seq in range(4)]
    for g in out:
        g.outage = True
    batch, info = collect(t, out + [group(4), group(5), group(6)])
    assert [g.seq for g in batch] == [4, 5, 6] and info["groups_failed"] == 4 and info["groups_inspected"] == 7
    assert t.counters["short_batches"] == 0
    # Any other failure still uses it: the step ends short.
    t = trainer(dynamic_sampling={"max_admissions_factor": 1.0})
    batch, info = collect(t, [group(0, failed="EnvActorLost: x"), group(1), group(2), group(3)])
    assert [g.seq for g in batch] == [1, 2] and t.counters["short_batches"] == 1


def test_over_stale_groups_are_dropped():
    t = trainer(max_staleness=1)
    t.version = 3
    t.unresolved = 4
    batch, info = collect(t, [group(0, admit_version=1), group(1, admit_version=2), group(2, admit_version=3),
                              group(3, admit_version=2)])
    assert [g.seq for g in batch] == [1, 2, 3] and info["groups_stale_dropped"] == 1
    assert t.unresolved == 3 and t.group_status[0] == "stale"


def test_unexpected_group_errors_surface():
    t = trainer()
    bad = group(0, failed="ZeroDivisionError: boom")
    bad.error = ZeroDivisionError("boom")
    with pytest.raises(RuntimeError, match="group 0"):
        collect(t, [bad])


def test_rewards_and_correctness_rules():
    cfg = validate_config({"reward": {"kind": "cosine", "max_length": 100}})
    right, wrong = sample(0, 0, correct=True, length=10), sample(0, 1, correct=False, length=50)
    assert shape_reward(right, cfg) == pytest.approx(1.1 - 0.5 * 0.4 * (1 - 0.9510565163), rel=1e-6)
    assert shape_reward(wrong, cfg) == pytest.approx(-0.35, rel=1e-6)
    cut = sample(0, 2, correct=True, truncation="response_tokens")
    assert shape_reward(cut, cfg) == -0.5
    turns_out = sample(0, 3, correct=False, truncation="max_turns", length=0)
    assert shape_reward(turns_out, cfg) == 0.0
    strict = validate_config({"reward": {"kind": "cosine", "max_length": 100, "penalize": ["response_tokens", "max_turns"]}})
    assert shape_reward(turns_out, strict) == -0.5
    assert shape_reward(wrong, validate_config({})) == 0.5  # kind total: the env's 5D reward

    zero = sample(0, 4, correct=False, reward=0.0)
    assert is_correct(right, cfg) and not is_correct(zero, cfg)
    acc = validate_config({"reward": {"correct_if": "accuracy_at_least", "accuracy_threshold": 0.5}})
    assert is_correct(right, acc) and not is_correct(wrong, acc)

    by_reward = validate_config({"trainer": {"dynamic_sampling": {"criterion": "reward"}}})
    same = [sample(0, i, correct=False, reward=0.3) for i in range(3)]
    assert not mixed_outcomes(same, by_reward) and not mixed_outcomes(same, cfg)
    assert mixed_outcomes([same[0], sample(0, 5, correct=False, reward=0.4)], by_reward)
    assert mixed_outcomes([right, wrong], cfg)


@pytest.mark.parametrize("reward", [{"correct_if": "total_at_least"}, {"correct_if": "reward_positive"},
                                    {"correct_if": "is_correct", "total_threshold": 0.55}])
def test_a_correctness_rule_on_the_total_alone_is_refused_naming_the_key(reward):
    # "wrong" earns a 0.5 total with a wrong answer: a rule on the total would call it correct
    with pytest.raises(ConfigError) as err:
        validate_config({"reward": reward})
    key = "reward.total_threshold" if "total_threshold" in reward else "reward.correct_if"
    assert key in str(err.value) and "is_correct" in str(err.value) and "accuracy_at_least" in str(err.value)


def test_task_sampler_is_deterministic_and_resumable():
    refs = [TaskRef("ward", f"t{i}", "train") for i in range(5)]
    a = TaskSampler(refs, seed=1)
    first = [a.next().task_id for _ in range(7)]
    assert sorted(first[:5]) == sorted(r.task_id for r in refs)  # an epoch visits every task once
    b = TaskSampler(refs, seed=1)
    assert [b.next().task_id for _ in range(7)] == first
    c = TaskSampler(refs, seed=1)
    for _ in range(3):
        c.next()
    d = TaskSampler(refs, seed=1)
    d.load_state_dict(c.state_dict())
    assert [d.next().task_id for _ in range(4)] == first[3:]
    assert [TaskSampler(refs, seed=2).next().task_id for _ in range(5)] != first[:5]
    assert episode_seed(0, "", 3, 1) == episode_seed(0, "", 3, 1) != episode_seed(0, "", 3, 2)


@pytest.mark.parametrize("staleness", [0, 1])
def test_a_fast_generator_with_filtered_groups_never_goes_stale(staleness):
    """Half the groups are filtered and every group finishes at once (a generator much faster than the
    learner, as vLLM is on the demo): the scheduler must still hand the learner full batches of groups
    within the staleness bound. Filtered groups used to free their admission slot on completion, so the
    producer ran ahead of the FIFO consumer and 6-18 of 36 groups a step were dropped as stale."""
    # 6 groups inspected a step at most, half of them filtered: 3 accepted + 1 filtered top-up a step,
    # so accepted groups are produced faster than they are consumed (the demo: 36 inspected for 24)
    t = BatchScheduler(validate_config({"trainer": {"batch_size": 4, "max_staleness": staleness,
                                                    "dynamic_sampling": {"enabled": True, "max_admissions_factor": 1.5}},
                                        "data": {"domains": ["ward"]}}).trainer,
                       TaskSampler([TaskRef("ward", f"t{i}", "train") for i in range(7)], seed=0),
                       log=lambda line: None)

    async def produce(seq: int, task: TaskRef, version: int) -> Group:
        await asyncio.sleep(0)
        return group(seq, outcomes=(True, False) if seq % 2 else (True, True), admit_version=version)

    async def run() -> list[tuple[list[Group], dict]]:
        admission = asyncio.ensure_future(t.admission_loop(produce))
        steps = []
        for step in range(1, 9):
            batch, info = await t.collect_batch()
            await asyncio.sleep(0.01)  # the learner's step: the producer runs meanwhile
            steps.append((batch, info))
            await t.consumed(batch, step)
        await t.stop()
        await admission
        return steps

    steps = asyncio.run(run())
    for step, (batch, info) in enumerate(steps, start=1):
        assert info["groups_stale_dropped"] == 0, f"step {step}: {info}"
        assert len(batch) == 4 and sum(g.accepted for g in batch) == 3, f"step {step}: {info}"
        assert all(step - 1 - g.admit_version <= staleness for g in batch), [g.admit_version for g in batch]
    assert t.unresolved <= t.capacity
