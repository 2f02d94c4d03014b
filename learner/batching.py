"""Batch scheduling: admission under the staleness bound, dynamic sampling, FIFO batch assembly and
the accounting of every admitted group.

Staleness: a group is admitted only while fewer than (max_staleness + 1) * batch_size groups are
admitted and not yet consumed, so every consumed group was sampled by a policy at most
`max_staleness` versions older than the one being updated. Admission stamps the current version
as the episode's `min_version`; every token records the version that actually sampled it (with
staleness > 0 an episode can straddle a weight update). A group whose lag would still exceed the
bound (possible only after a short batch, see dynamic sampling) is dropped and counted.

Dynamic sampling: a group is kept only if its outcomes are mixed; filtered groups free their
admission slot at once, so the batch refills. After `max_admissions_factor * batch_size` inspected
groups the step tops up with the latest filtered groups (zero advantage, but still KL / distillation
signal) and logs it.

FIFO: the learner takes groups in admission order, which makes the staleness bound exact and the
batches deterministic at staleness 0.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any, Awaitable, Callable

from actors.types import RolloutSample
from learner.config import RunConfig, TrainerConfig
from learner.tasks import TaskRef, TaskSampler

# Every admitted group ends in exactly one of these states (see `BatchScheduler.group_status`).
FINAL_STATES = ("consumed", "filled", "filtered", "failed", "stale", "leftover", "cancelled")


def is_correct(sample: RolloutSample, cfg: RunConfig) -> bool:
    """Whether an episode counts as correct (dynamic sampling, teacher hints, the accuracy metric).

    Always the task's accuracy criterion, never the total alone (cheap strategies reach any total
    threshold; bench/reward_gaming.py): `is_correct` is the env's grader, `accuracy_at_least` the accuracy
    component against `reward.accuracy_threshold`.
    """
    rule = cfg.reward.correct_if
    if rule == "is_correct":
        return bool(sample.env_correct)
    accuracy = sample.reward_components.get("accuracy")
    return accuracy is not None and float(accuracy) >= cfg.reward.accuracy_threshold


def shape_reward(sample: RolloutSample, cfg: RunConfig) -> float:
    """The RL reward: the env's 5D total, or the cosine length reward of Eq. 4."""
    if cfg.reward.kind == "total":
        return float(sample.env_reward)
    from envs.rewards import cosine_length_reward

    return float(cosine_length_reward(
        is_correct(sample, cfg), sample.response_tokens, cfg.cosine_max_length,
        truncated=sample.metadata.get("truncation") in cfg.reward.penalize,
        r_max=cfg.reward.r_max, r_min=cfg.reward.r_min, r_penalty=cfg.reward.r_penalty,
    ))


def score_sample(sample: RolloutSample, cfg: RunConfig) -> RolloutSample:
    """Set the sample's training outcome and RL reward from the env's verdict and the run's reward
    config: the one place `sample.correct` and `sample.reward` are decided for training."""
    sample.correct = is_correct(sample, cfg)
    sample.reward = shape_reward(sample, cfg)
    return sample


def mixed_outcomes(samples: list[RolloutSample], cfg: RunConfig) -> bool:
    ds = cfg.trainer.dynamic_sampling
    if ds.criterion == "correct":
        return len({s.correct for s in samples}) > 1
    rewards = [s.reward for s in samples]
    return max(rewards) - min(rewards) > ds.reward_eps


@dataclass
class Group:
    seq: int
    task: TaskRef
    admit_version: int
    samples: list[RolloutSample] = field(default_factory=list)
    accepted: bool = False
    failed: str | None = None
    # Failed because no generator came back within `generator.restart_wait_s`: replaced without
    # using the step's inspection budget (the wait bounds such failures in time; see collect_batch).
    outage: bool = False
    error: BaseException | None = None
    teacher_submitted: bool = False
    teacher_submit_ref: Any = None  # the submit call; fetch waits for it (the teacher is a threaded actor)
    teacher_floor: int = 0      # teacher version confirmed when it was submitted: a valid score is >= it
    completed_at: float = 0.0


GroupProducer = Callable[[int, TaskRef, int], Awaitable[Group]]


class BatchScheduler:
    """Admits groups, collects finished ones, and hands the learner FIFO batches.

    Args:
        trainer: The `trainer` section of the run config (batch size, staleness, dynamic sampling).
        sampler: Where new tasks come from (None: only `collect_batch` is used, as in unit tests).
        log: Where notices go.
        counters: The run's counter dict to add to (created when None).
    """

    def __init__(self, trainer: TrainerConfig, sampler: TaskSampler | None = None,
                 log: Callable[[str], None] = print, counters: dict[str, int] | None = None) -> None:
        self.cfg = trainer
        self.sampler = sampler
        self.log = log
        self.cond = asyncio.Condition()
        self.version = 0             # the policy version new admissions are stamped with
        self.stopping = False
        self.completed: dict[int, Group] = {}
        self.in_flight: dict[int, asyncio.Task] = {}
        self.group_tasks: dict[int, TaskRef] = {}
        self.next_seq = 0            # next group sequence number to admit
        self.consume_seq = 0         # next sequence number the learner inspects (FIFO)
        self.unresolved = 0          # admitted groups not inspected yet, plus accepted ones not consumed yet
        self.readmit: list[tuple[int, TaskRef]] = []
        self.filtered_recent: list[Group] = []
        # seq -> "in_flight", "done" or one of FINAL_STATES.
        self.group_status: dict[int, str] = {}
        self.counters = counters if counters is not None else {}
        for key in ("groups_admitted", "groups_filtered", "groups_failed", "groups_consumed",
                    "groups_stale_dropped", "groups_filled", "short_batches"):
            self.counters.setdefault(key, 0)

    @property
    def capacity(self) -> int:
        return (self.cfg.max_staleness + 1) * self.cfg.batch_size

    # -- admission -------------------------------------------------------------------------------
    async def admission_loop(self, produce: GroupProducer) -> None:
        """Admit groups while the staleness bound allows, until `stop()`; `produce(seq, task, version)`
        rolls one group out and returns it (errors recorded in the group, never raised)."""
        while True:
            async with self.cond:
                await self.cond.wait_for(lambda: self.stopping or self.unresolved < self.capacity)
                if self.stopping:
                    return
                if self.readmit:
                    seq, task = self.readmit.pop(0)
                else:
                    seq, task = self.next_seq, self.sampler.next()
                    self.next_seq += 1
                self.unresolved += 1
                self.counters["groups_admitted"] += 1
                self.group_status[seq] = "in_flight"
                self.group_tasks[seq] = task
                self.in_flight[seq] = asyncio.ensure_future(self._produce_and_complete(produce, seq, task))

    async def _produce_and_complete(self, produce: GroupProducer, seq: int, task: TaskRef) -> None:
        await self.complete(await produce(seq, task, self.version))

    async def complete(self, group: Group) -> None:
        """Record a finished group. Its admission slot stays taken until the learner inspects it, even
        when it is filtered or failed: a slot freed at completion let a fast generator admit groups
        behind a backlog of finished ones that the FIFO consumer had not reached, and they went stale
        before it did (the demo with vLLM dropped 6-18 of 36 inspected groups a step as stale and
        ended a run with an empty batch). Held slots bound the backlog by `capacity`, so a group is
        inspected within `max_staleness` versions of its admission."""
        async with self.cond:
            self.in_flight.pop(group.seq, None)
            self.completed[group.seq] = group
            self.group_status[group.seq] = "failed" if group.failed else ("done" if group.accepted else "filtered")
            if group.failed or not group.accepted:
                self.counters["groups_failed" if group.failed else "groups_filtered"] += 1
            self.cond.notify_all()

    async def _release(self) -> None:
        """An inspected group that will not be trained on (filtered, failed, stale) frees its slot:
        dynamic sampling admits a replacement."""
        async with self.cond:
            self.unresolved -= 1
            self.cond.notify_all()

    # -- the learner's side ----------------------------------------------------------------------
    async def collect_batch(self) -> tuple[list[Group], dict[str, float]]:
        """Take the next `batch_size` accepted groups in admission order (FIFO).

        At most `max_admissions_factor * batch_size` groups are inspected, except those failed by a
        generator outage (`Group.outage`): each of them waited `generator.restart_wait_s` for a
        generator Ray is restarting and is replaced like the rest, but an outage longer than the
        budget's worth of waits would otherwise end the step short, or stop the run with no
        trainable group, while the generator was on its way back. A generator that will not come
        back stops the run (`GeneratorDeadError`), so these do not loop for ever."""
        cfg = self.cfg
        batch: list[Group] = []
        inspected = filtered = failed = stale = outages = 0
        max_inspect = int(cfg.dynamic_sampling.max_admissions_factor * cfg.batch_size)
        while len(batch) < cfg.batch_size and inspected - outages < max_inspect:
            async with self.cond:
                await self.cond.wait_for(lambda: self.consume_seq in self.completed)
                group = self.completed.pop(self.consume_seq)
                self.consume_seq += 1
            inspected += 1
            if group.error is not None:
                raise RuntimeError(f"group {group.seq} (task {group.task.task_id}) failed: {group.failed}") \
                    from group.error
            if group.failed:
                failed += 1
                outages += group.outage
                self.log(f"[rollout] group {group.seq} dropped: {group.failed}")
                await self._release()
                continue
            if not group.accepted:
                filtered += 1
                self.filtered_recent = (self.filtered_recent + [group])[-cfg.batch_size:]
                await self._release()
                continue
            if self.version - group.admit_version > cfg.max_staleness:
                stale += 1
                self.counters["groups_stale_dropped"] += 1
                self.group_status[group.seq] = "stale"
                await self._release()
                continue
            batch.append(group)
        filled = 0
        if len(batch) < cfg.batch_size:
            self.counters["short_batches"] += 1
            fill = [g for g in reversed(self.filtered_recent)
                    if self.version - g.admit_version <= cfg.max_staleness][: cfg.batch_size - len(batch)]
            filled = len(fill)
            self.counters["groups_filled"] += filled
            self.log(f"[dynamic sampling] only {len(batch)} mixed-outcome groups after {inspected} inspected; "
                     f"topping up with {filled} filtered groups")
            batch.extend(fill)
            for g in fill:
                self.group_status[g.seq] = "filled"
            self.filtered_recent = [g for g in self.filtered_recent if g not in fill]
        batch.sort(key=lambda g: g.seq)
        info = {"filtered_groups_frac": filtered / max(inspected, 1), "groups_inspected": float(inspected),
                "groups_failed": float(failed), "groups_stale_dropped": float(stale), "groups_filled": float(filled)}
        return batch, info

    async def consumed(self, groups: list[Group], version: int) -> None:
        """The learner trained on `groups` and published `version`: free their slots, so work for the
        next versions may start (staleness is counted against the new version)."""
        async with self.cond:
            self.version = version
            self.unresolved -= len([g for g in groups if g.accepted])
            self.counters["groups_consumed"] += len(groups)
            for g in groups:
                if g.accepted:
                    self.group_status[g.seq] = "consumed"
            self.cond.notify_all()

    # -- the end of a run ------------------------------------------------------------------------
    async def stop(self) -> None:
        async with self.cond:
            self.stopping = True
            self.cond.notify_all()

    async def drain(self, finished: bool, timeout_s: float) -> None:
        """Let admitted groups finish (when the run finished) so every episode is accounted for, cancel
        the rest, and mark done-but-unconsumed groups as leftovers."""
        if finished and self.in_flight:
            await asyncio.wait(list(self.in_flight.values()), timeout=timeout_s)
        for seq, task in list(self.in_flight.items()):
            task.cancel()
            self.group_status[seq] = "cancelled"
        await asyncio.gather(*self.in_flight.values(), return_exceptions=True)
        for seq, status in self.group_status.items():
            if status == "done":
                self.group_status[seq] = "leftover"

    def status_counts(self) -> dict[str, int]:
        states = self.group_status.values()
        return {k: sum(1 for v in states if v == k) for k in sorted(set(states))}

    # -- checkpoints -----------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        # Every admitted group the learner has not inspected yet (in flight, done, filtered or failed):
        # the FIFO consumer resumes at consume_seq and needs each of them again, re-admitted first with
        # the same sequence numbers (so the same seeds): no data is skipped or repeated.
        pending = [(seq, self.group_tasks[seq]) for seq in range(self.consume_seq, self.next_seq)]
        return {"version": self.version, "sampler": self.sampler.state_dict(), "next_seq": self.next_seq,
                "consume_seq": self.consume_seq,
                "readmit": [[seq, task.domain, task.task_id, task.split] for seq, task in sorted(pending)]}

    def load_state_dict(self, state: dict[str, Any], version: int) -> None:
        self.version = version
        self.sampler.load_state_dict(state["sampler"])
        self.next_seq = int(state["next_seq"])
        self.consume_seq = int(state["consume_seq"])
        self.readmit = [(int(seq), TaskRef(d, t, s)) for seq, d, t, s in state["readmit"]]
        self.group_tasks.update(dict(self.readmit))
