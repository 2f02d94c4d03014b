"""The training driver: wires the actors from a `RunConfig` and runs GRPO / TT-OPD.

    python -m learner.train --config configs/tiny_cpu_ttopd.yaml [--max-steps N] [--output-dir DIR] [--resume]
    hcgym train --config ...                                        (the same)

Data flow (Algorithm 1, made asynchronous):

    admission --(EpisodeSpec x G)--> env pool + generators (TITO agent loop)
        --> group complete: reward (5D total or Eq. 4), correctness, dynamic-sampling verdict
        --> accepted: submitted to the teacher at once (it scores in the background)
        --> FIFO by admission order into the learner's next batch
    learner step --> weights ref --> generators (every step), teacher (EMA / hard copy steps)

Streaming: groups are admitted, rolled out, scored and sent to the teacher independently; there is
no barrier where a whole batch of rollouts must finish. The learner takes groups in admission order
(FIFO), which makes the staleness bound exact and the batches deterministic at staleness 0.

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
"""

from __future__ import annotations

import argparse
import asyncio
import hashlib
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

import envs._runtime  # noqa: F401  (CPU-path environment defaults before torch/ray load)
from actors.agent_loop import AgentLoop, EpisodeSpec, PromptTooLongError, RolloutLimits
from actors.env_actor import EnvActorLost, EnvPool, EpisodeLedger, register_domains, run_episode
from actors.generator import GeneratorClient, generator_actor_class
from actors.types import RolloutSample, TeacherOutput
from learner.config import RunConfig, dump_config, load_config
from learner.metrics import MetricsSink, rollout_metrics, write_samples

# ---------------------------------------------------------------------------------------------
# Tasks
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TaskRef:
    domain: str
    task_id: str
    split: str | None


def load_task_refs(domains: list[str], split: str | None, limit: int | None = None,
                   pattern: str | None = None) -> list[TaskRef]:
    """Task references of a split over domains, in a stable order (domain, then file order).

    Args:
        domains: Registered domain names.
        split: The split ("train", "test", ...).
        limit: Keep the first `limit` references.
        pattern: Keep only task ids matching this regular expression.
    """
    import re

    from envs import registry

    refs: list[TaskRef] = []
    for domain in domains:
        if domain not in registry.list_domains():
            raise ValueError(f"data.domains: unknown domain {domain!r}; registered: {registry.list_domains()}")
        tasks = registry.get_tasks(domain, split)
        if not tasks:
            raise ValueError(f"data: domain {domain!r} has no tasks in split {split!r} (run `hcgym data build`?)")
        refs.extend(TaskRef(domain, t.id, split) for t in tasks if pattern is None or re.search(pattern, t.id))
    if not refs:
        raise ValueError(f"data: no task of {domains} in split {split!r} matches task_id_pattern {pattern!r}")
    return refs[:limit] if limit else refs


def prompt_lengths(refs: list[TaskRef], loop: AgentLoop) -> list[int]:
    """Token length of each task's rendered prompt (system prompt + ticket), as the agent loop renders it."""
    from envs import registry
    from envs.core.env import build_system_prompt, render_ticket

    systems: dict[str, tuple[str, list]] = {}
    tasks: dict[tuple[str, str | None], dict[str, Any]] = {}
    out = []
    for ref in refs:
        if ref.domain not in systems:
            domain_env = registry.get_environment(ref.domain)
            systems[ref.domain] = (build_system_prompt(domain_env), domain_env.toolkit.schemas())
        key = (ref.domain, ref.split)
        if key not in tasks:
            tasks[key] = {t.id: t for t in registry.get_tasks(ref.domain, ref.split)}
        info = {"system_prompt": systems[ref.domain][0], "tools": systems[ref.domain][1],
                "ticket": render_ticket(tasks[key][ref.task_id])}
        out.append(len(loop.render_prompt(info)))
    return out


class TaskSampler:
    """Epoch-wise shuffles of the training tasks, deterministic in (seed, epoch); resumable."""

    def __init__(self, refs: list[TaskRef], seed: int) -> None:
        if not refs:
            raise ValueError("no training tasks")
        self.refs = refs
        self.seed = seed
        self.epoch = 0
        self.position = 0
        self._order = self._permutation(0)

    def _permutation(self, epoch: int) -> list[int]:
        return np.random.default_rng([self.seed, epoch]).permutation(len(self.refs)).tolist()

    def next(self) -> TaskRef:
        if self.position >= len(self._order):
            self.epoch += 1
            self.position = 0
            self._order = self._permutation(self.epoch)
        ref = self.refs[self._order[self.position]]
        self.position += 1
        return ref

    def state_dict(self) -> dict[str, int]:
        return {"epoch": self.epoch, "position": self.position}

    def load_state_dict(self, state: dict[str, int]) -> None:
        self.epoch, self.position = int(state["epoch"]), int(state["position"])
        self._order = self._permutation(self.epoch)


def episode_seed(run_seed: int, *parts: Any) -> int:
    digest = hashlib.blake2b(":".join(str(p) for p in (run_seed, *parts)).encode(), digest_size=4).digest()
    return int.from_bytes(digest, "little") & 0x7FFF_FFFF


# ---------------------------------------------------------------------------------------------
# Rewards and dynamic sampling
# ---------------------------------------------------------------------------------------------


def is_correct(sample: RolloutSample, cfg: RunConfig) -> bool:
    rule = cfg.reward.correct_if
    if rule == "is_correct":
        return bool(sample.metadata.get("is_correct", sample.correct))
    if rule == "reward_positive":  # the reference implementation's rule
        return float(sample.metadata.get("env_reward", sample.reward)) > 0
    if rule == "total_at_least":
        return float(sample.metadata.get("env_reward", sample.reward)) >= cfg.reward.total_threshold
    accuracy = sample.reward_components.get("accuracy")
    return accuracy is not None and float(accuracy) >= cfg.reward.accuracy_threshold


def shape_reward(sample: RolloutSample, cfg: RunConfig) -> float:
    """The RL reward: the env's 5D total, or the cosine length reward of Eq. 4."""
    if cfg.reward.kind == "total":
        return float(sample.metadata.get("env_reward", sample.reward))
    from envs.rewards import cosine_length_reward

    return float(cosine_length_reward(
        sample.correct, sample.response_tokens, cfg.cosine_max_length,
        truncated=sample.metadata.get("truncation") in cfg.reward.penalize,
        r_max=cfg.reward.r_max, r_min=cfg.reward.r_min, r_penalty=cfg.reward.r_penalty,
    ))


def mixed_outcomes(samples: list[RolloutSample], cfg: RunConfig) -> bool:
    ds = cfg.trainer.dynamic_sampling
    if ds.criterion == "correct":
        return len({s.correct for s in samples}) > 1
    rewards = [s.reward for s in samples]
    return max(rewards) - min(rewards) > ds.reward_eps


# ---------------------------------------------------------------------------------------------
# The driver
# ---------------------------------------------------------------------------------------------


@dataclass
class Group:
    seq: int
    task: TaskRef
    admit_version: int
    samples: list[RolloutSample] = field(default_factory=list)
    accepted: bool = False
    failed: str | None = None
    error: BaseException | None = None
    teacher_submitted: bool = False
    teacher_submit_ref: Any = None  # the submit call; fetch waits for it (the teacher is a threaded actor)
    teacher_floor: int = 0      # teacher version confirmed when it was submitted: a valid score is >= it
    completed_at: float = 0.0


class Trainer:
    """One training run.

    Args:
        cfg: The run config.
        resume: Continue from the run directory's latest checkpoint.
        log: Where progress lines go.
    """

    def __init__(self, cfg: RunConfig, *, resume: bool = False, log: Callable[[str], None] = print) -> None:
        self.cfg = cfg
        self.run_dir = Path(cfg.output_dir)
        self.resume = resume
        self.log = log
        self.step = 0
        self.version = 0
        self.teacher_version = 0
        self.stopping = False
        self.completed: dict[int, Group] = {}
        self.in_flight: dict[int, asyncio.Task] = {}
        self.next_seq = 0            # next group sequence number to admit
        self.consume_seq = 0         # next sequence number the learner inspects (FIFO)
        self.unresolved = 0          # admitted groups not consumed, filtered, failed or dropped
        self.readmit: list[tuple[int, TaskRef]] = []
        self.filtered_recent: list[Group] = []
        # Every admitted group ends in exactly one state: consumed (trained on), filled (filtered, then
        # used to top up a short batch), filtered, failed, stale (dropped over the staleness bound),
        # leftover (done but never consumed when the run stopped) or cancelled.
        self.group_status: dict[int, str] = {}
        self.counters = {"groups_admitted": 0, "groups_filtered": 0, "groups_failed": 0, "groups_consumed": 0,
                         "groups_stale_dropped": 0, "groups_filled": 0, "short_batches": 0, "teacher_recoveries": 0}
        self.ledger = EpisodeLedger()
        self.val_ledger = EpisodeLedger()
        self.teacher = None
        # Teacher recovery state: a confirmed snapshot (None = the constructor's weights), the updates
        # applied after it, and the snapshot requested after the latest update.
        self.teacher_base_ref = None
        self.teacher_replay: list[tuple[Any, int]] = []
        self.teacher_snapshot_pending = None
        self.teacher_confirmed = 0
        self.teacher_outstanding: dict[int, Group] = {}
        self.last_val: dict[str, float] = {}

    # -- setup ---------------------------------------------------------------------------------
    def _init_ray(self) -> None:
        import ray

        if ray.is_initialized():
            return
        rc = self.cfg.ray
        kwargs: dict[str, Any] = {"namespace": rc.namespace, "include_dashboard": rc.include_dashboard,
                                  "log_to_driver": True}
        if rc.address:
            kwargs["address"] = rc.address
        else:
            kwargs["num_cpus"] = rc.num_cpus
        ray.init(**kwargs)

    def _build(self) -> None:
        """Policy, tasks, actors (everything that does not need the event loop)."""
        from learner.model import ENDOFTEXT, IM_END, load_tokenizer
        from learner.sft import prepare_policy

        cfg = self.cfg
        register_domains(cfg.data.domain_modules)
        for key, value in cfg.rollout.env_vars.items():  # the driver runs episodes too (gold replays)
            os.environ.setdefault(key, value)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        dump_config(cfg, self.run_dir / "config.yaml")
        self.policy_dir = prepare_policy(cfg, self.run_dir, log=self.log)
        self.tokenizer = load_tokenizer(self.policy_dir)
        limits = RolloutLimits(**{k: getattr(cfg.rollout, k) for k in RolloutLimits.model_fields})
        self.loop = AgentLoop(self.tokenizer, limits, cfg.rollout.system_prompt)

        self.train_refs = self._tasks(cfg.data.train_split, cfg.data.max_train_tasks, "train")
        self.val_refs = self._tasks(cfg.data.val_split, cfg.data.max_val_tasks, "validation") \
            if cfg.trainer.val_interval or cfg.trainer.val_at_start else []
        self.sampler = TaskSampler(self.train_refs, cfg.seed)

        self._init_ray()
        self.log(f"[setup] {len(self.train_refs)} train / {len(self.val_refs)} validation tasks; "
                 f"policy {self.policy_dir}")
        self.pool_args = dict(num_actors=cfg.rollout.num_env_actors, slots_per_actor=cfg.rollout.slots_per_env_actor,
                              max_turns=cfg.rollout.max_turns, max_restarts=cfg.rollout.env_actor_max_restarts,
                              domain_modules=cfg.data.domain_modules, env_vars=cfg.rollout.env_vars)
        self.kb_client = None
        if cfg.kb.service:
            from kb_service.service import start_kb_service

            self.kb_client = start_kb_service(cfg.kb.replicas, cfg.kb.path, cfg.kb.name, cfg.kb.num_cpus)
            self.pool_args["kb_service"] = cfg.kb.name
            self.log(f"[setup] knowledge-base service {cfg.kb.name!r} with {cfg.kb.replicas} replica(s)")
        stop_ids = [self.tokenizer.convert_tokens_to_ids(t) for t in (IM_END, ENDOFTEXT)]
        g = cfg.generator
        gen_cls = generator_actor_class().options(num_cpus=g.num_cpus, num_gpus=g.num_gpus, max_restarts=g.max_restarts,
                                                  max_task_retries=0, max_concurrency=1000)
        self.generators = [
            gen_cls.remote(g.backend, str(self.policy_dir), g.sampling.model_dump(), stop_ids, 0, g.options,
                           g.max_batch_size, g.batch_wait_s)
            for _ in range(g.num_generators)
        ]
        from learner.learner_actor import LearnerActor

        self.learner = LearnerActor.options(num_cpus=cfg.ray.learner_num_cpus, num_gpus=cfg.ray.learner_num_gpus) \
            .remote(cfg.learner.model_dump(), str(self.policy_dir), cfg.seed)
        if cfg.teacher.enabled:
            self.teacher = self._make_teacher()

    def _make_teacher(self):
        from actors.teacher import TeacherActor

        rc = self.cfg.ray
        return TeacherActor.options(num_cpus=rc.teacher_num_cpus, num_gpus=rc.teacher_num_gpus,
                                    max_restarts=rc.teacher_max_restarts, max_task_retries=0) \
            .remote(self.cfg.teacher.model_dump(), str(self.policy_dir), self.cfg.seed)

    def _tasks(self, split: str, limit: int | None, what: str) -> list[TaskRef]:
        refs = load_task_refs(self.cfg.data.domains, split, limit, self.cfg.data.task_id_pattern)
        if self.cfg.data.filter_long_prompts:
            lengths = prompt_lengths(refs, self.loop)
            kept = [r for r, n in zip(refs, lengths) if n <= self.cfg.rollout.max_prompt_tokens]
            if len(kept) < len(refs):
                self.log(f"[setup] dropped {len(refs) - len(kept)} {what} tasks whose prompt exceeds "
                         f"rollout.max_prompt_tokens={self.cfg.rollout.max_prompt_tokens}")
            refs = kept
        if not refs:
            raise ValueError(f"no {what} tasks left in split {split!r} of {self.cfg.data.domains}")
        return refs

    # -- checkpoints ---------------------------------------------------------------------------
    async def _save_checkpoint(self) -> Path:
        from learner.checkpoint import checkpoint_dir, mark_latest, prune_checkpoints, write_json_atomic

        directory = checkpoint_dir(self.run_dir, self.step)
        directory.mkdir(parents=True, exist_ok=True)
        await self.learner.save_checkpoint.remote(str(directory))
        if self.teacher is not None:
            await self.teacher.save.remote(str(directory))
        # Every admitted group the learner has not inspected yet (in flight, done, filtered or failed):
        # the FIFO consumer resumes at consume_seq and needs each of them again.
        pending = [(seq, self._group_tasks[seq]) for seq in range(self.consume_seq, self.next_seq)]
        write_json_atomic(directory / "driver.json", {
            "step": self.step, "version": self.version, "teacher_version": self.teacher_version,
            "sampler": self.sampler.state_dict(), "next_seq": self.next_seq, "consume_seq": self.consume_seq,
            # Admitted but not consumed: re-admitted first on resume, with the same sequence numbers
            # (so the same seeds), so no data is skipped or repeated.
            "readmit": [[seq, task.domain, task.task_id, task.split] for seq, task in sorted(pending)],
            "counters": self.counters, "ledger": self.ledger.balance(),
        })
        mark_latest(self.run_dir, self.step)
        prune_checkpoints(self.run_dir, self.cfg.trainer.keep_checkpoints)
        return directory

    async def _restore(self) -> bool:
        from learner.checkpoint import latest_checkpoint, read_json

        directory = latest_checkpoint(self.run_dir)
        if directory is None:
            self.log(f"[resume] {self.run_dir} has no checkpoint yet: starting from step 0")
            return False
        state = read_json(directory / "driver.json")
        learner_state = await self.learner.load_checkpoint.remote(str(directory))
        if int(learner_state["step"]) != int(state["step"]):
            raise RuntimeError(f"{directory}: learner step {learner_state['step']} != driver step {state['step']}")
        self.step = self.version = int(state["step"])
        self.teacher_version = int(state["teacher_version"])
        self.sampler.load_state_dict(state["sampler"])
        self.next_seq = int(state["next_seq"])
        self.consume_seq = int(state["consume_seq"])
        self.readmit = [(int(seq), TaskRef(d, t, s)) for seq, d, t, s in state["readmit"]]
        self._group_tasks.update(dict(self.readmit))
        self.counters.update(state["counters"])
        if self.teacher is not None:
            await self.teacher.load.remote(str(directory))
            self.teacher_confirmed = int(await self.teacher.teacher_version.remote())
            if self.teacher_confirmed != self.teacher_version:
                raise RuntimeError(f"{directory}: teacher version {self.teacher_confirmed} != driver's {self.teacher_version}")
            # A teacher restarted later must come back to the checkpoint's state, not the initial one.
            self.teacher_base_ref = self.teacher.get_state.remote()
        weights = self.learner.get_weights.remote()
        await self.gen_client.sync_all(weights, self.version)
        self.log(f"[resume] restored step {self.step} from {directory}")
        return True

    # -- admission -------------------------------------------------------------------------------
    def _capacity(self) -> int:
        return (self.cfg.trainer.max_staleness + 1) * self.cfg.trainer.batch_size

    async def _admission_loop(self) -> None:
        while True:
            async with self.cond:
                await self.cond.wait_for(lambda: self.stopping or self.unresolved < self._capacity())
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
                self._group_tasks[seq] = task
                self.in_flight[seq] = asyncio.ensure_future(self._run_group(seq, task, self.version))

    def _specs(self, seq: int, task: TaskRef, version: int, size: int, tag: str = "", greedy: bool = False):
        specs = []
        for i in range(size):
            seed = episode_seed(self.cfg.seed, tag, seq, i)
            specs.append(EpisodeSpec(
                sample_id=f"{task.task_id}:{tag}{i}:{seed}", task_id=task.task_id, domain=task.domain,
                split=task.split, group_id=f"{tag}g{seq:06d}:{task.task_id}", group_index=i, seed=seed,
                min_version=version, greedy=greedy,
            ))
        return specs

    async def _episodes(self, specs: list[EpisodeSpec], ledger: EpisodeLedger) -> list[RolloutSample]:
        for spec in specs:
            ledger.admit(spec.sample_id)
        return list(await asyncio.gather(*[
            run_episode(spec, self.loop, self.pool, self.gen_client, ledger, self.cfg.rollout.max_episode_attempts)
            for spec in specs
        ]))

    async def _run_group(self, seq: int, task: TaskRef, version: int) -> None:
        group = Group(seq=seq, task=task, admit_version=version)
        try:
            samples = await self._episodes(self._specs(seq, task, version, self.cfg.rollout.group_size), self.ledger)
            for s in samples:
                s.correct = is_correct(s, self.cfg)
                s.reward = shape_reward(s, self.cfg)
                s.metadata["group_seq"] = seq
                s.metadata["admit_version"] = version
            group.samples = samples
            group.accepted = (not self.cfg.trainer.dynamic_sampling.enabled) or mixed_outcomes(samples, self.cfg)
            if group.accepted and self.teacher is not None:
                self._submit_teacher(group)
        except (EnvActorLost, PromptTooLongError) as exc:
            group.failed = f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # a bug: surfaced by the consumer with its group
            group.failed = f"{type(exc).__name__}: {exc}"
            group.error = exc
        group.completed_at = time.perf_counter()
        async with self.cond:
            self.in_flight.pop(seq, None)
            self.completed[seq] = group
            self.group_status[seq] = "failed" if group.failed else ("done" if group.accepted else "filtered")
            if group.failed or not group.accepted:
                self.unresolved -= 1  # frees the slot now: dynamic sampling refills at once
                self.counters["groups_failed" if group.failed else "groups_filtered"] += 1
            self.cond.notify_all()

    # -- teacher -----------------------------------------------------------------------------------
    def _submit_teacher(self, group: Group) -> None:
        """Queue a finished group for teacher scoring; the teacher computes while rollouts go on."""
        group.teacher_submit_ref = self.teacher.submit.remote(group.samples)
        group.teacher_submitted = True
        group.teacher_floor = self.teacher_confirmed
        self.teacher_outstanding[group.seq] = group

    def _confirm_teacher_snapshot(self) -> None:
        """Promote the latest post-update teacher state to the recovery base once it exists."""
        import ray

        ref = self.teacher_snapshot_pending
        if ref is None or not ray.wait([ref], timeout=0)[0]:
            return
        try:
            ray.get(ref, timeout=0)
        except Exception:  # the teacher died before producing it: keep base + replay
            self.teacher_snapshot_pending = None
            return
        self.teacher_base_ref, self.teacher_replay, self.teacher_snapshot_pending = ref, [], None

    async def _recover_teacher(self, why: str) -> None:
        """Ray restarted the teacher with its initial weights: restore the EMA state it had (the last
        confirmed snapshot plus the updates since, replayed in order), then re-submit every group
        whose scores it may have lost."""
        self.counters["teacher_recoveries"] += 1
        self.log(f"[teacher] recovering ({why}): restoring teacher version {self.teacher_confirmed}")
        current = -1
        for _ in range(600):
            try:
                current = await asyncio.wait_for(self.teacher.teacher_version.remote(), 30)
                break
            except Exception:
                await asyncio.sleep(0.5)
        if current != self.teacher_confirmed:  # restarted: its weights are the constructor's
            if self.teacher_base_ref is not None:
                await self.teacher.set_state.remote(self.teacher_base_ref)
            for weights_ref, step in self.teacher_replay:
                await self.teacher.update.remote(weights_ref, step)
        restored = await self.teacher.teacher_version.remote()
        if restored != self.teacher_confirmed:
            raise RuntimeError(f"teacher recovery restored version {restored}, expected {self.teacher_confirmed}")
        for group in list(self.teacher_outstanding.values()):
            self._submit_teacher(group)

    async def _train_with_teacher(self, groups: list[Group], samples: list[RolloutSample]):
        """One learner step whose teacher log-probs are fetched while the learner already runs.

        The fetch's ref goes to the learner inside a list (T1's overlap): the learner does its
        reference and pi_old forwards first and blocks on the teacher only for what is not scored
        yet. A teacher that died (fetch fails, or the step's samples are unknown to it) is recovered
        and the step retried; nothing was updated, the learner resolves the teacher before its backward.

        Returns:
            (learner metrics, {sample id: TeacherOutput}).
        """
        from ray.exceptions import RayActorError

        for group in groups:
            if not group.teacher_submitted:
                self._submit_teacher(group)  # a fill group (filtered when it finished)
        ids = [s.sample_id for g in groups for s in g.samples]
        floors = {s.sample_id: g.teacher_floor for g in groups for s in g.samples}
        timeout = self.cfg.trainer.teacher_timeout_s
        for _ in range(5):
            try:
                # Threaded actor: a fetch may overtake a submit sent just before it; wait for those.
                await asyncio.gather(*[g.teacher_submit_ref for g in groups])
                # A teacher restarted since its last update scores with its initial weights: restore first.
                if await self.teacher.teacher_version.remote() != self.teacher_confirmed:
                    await self._recover_teacher("teacher version behind the driver's")
                    continue
            except RayActorError as exc:
                await self._recover_teacher(f"{type(exc).__name__} before fetch")
                continue
            fetch_ref = self.teacher.fetch.remote(ids, timeout)
            try:
                metrics = await self.learner.train_step.remote(samples, [fetch_ref], self.step + 1)
            except Exception as exc:
                try:
                    await fetch_ref
                except (RayActorError, KeyError) as teacher_exc:
                    await self._recover_teacher(f"{type(teacher_exc).__name__} during fetch")
                    continue
                raise exc
            fetched = await fetch_ref
            old = [o for o in fetched.outputs if o.teacher_version < floors[o.sample_id]]
            if old:
                # Scored by a restarted teacher in the instant before the version check: counted and
                # logged, the step has used them.
                self.counters["teacher_stale_outputs"] = self.counters.get("teacher_stale_outputs", 0) + len(old)
                self.log(f"[teacher] {len(old)} outputs of step {self.step + 1} came from teacher version "
                         f"{old[0].teacher_version} < {floors[old[0].sample_id]}")
            for group in groups:
                self.teacher_outstanding.pop(group.seq, None)
            return metrics, {o.sample_id: o for o in fetched.outputs}
        raise RuntimeError(f"teacher failed to serve step {self.step + 1} five times")

    async def _update_teacher(self, weights_ref) -> str:
        """EMA / hard copy after this step (Algorithm 1), awaited so that work admitted afterwards is
        scored by the updated teacher."""
        from learner.config_models import teacher_update_action

        action = teacher_update_action(self.step, self.cfg.teacher)
        if action == "none":
            return action
        if weights_ref is None:  # collective transport: the teacher still takes a full CPU state dict
            weights_ref = self.learner.get_weights.remote()
        self._confirm_teacher_snapshot()
        for attempt in range(3):
            try:
                result = await self.teacher.update.remote(weights_ref, self.step)
                break
            except Exception as exc:
                from ray.exceptions import RayActorError

                if not isinstance(exc, RayActorError) or attempt == 2:
                    raise
                await self._recover_teacher(f"{type(exc).__name__} during update")
        if result["action"] != action:
            raise RuntimeError(f"teacher applied {result['action']!r} at step {self.step}, driver expected {action!r}")
        self.teacher_replay.append((weights_ref, self.step))
        self.teacher_confirmed = int(result["teacher_version"])
        self.teacher_version = self.teacher_confirmed
        self.teacher_snapshot_pending = self.teacher.get_state.remote()
        return action

    # -- collective weight sync (GPU path; gloo on CPU) -------------------------------------------
    async def _form_weight_sync_group(self) -> None:
        """The learner's rank 0 and every generator join one private process group."""
        from learner.learner_actor import free_port

        config = self.cfg.weight_sync.model_dump()
        # Every (re-)formation needs a fresh rendezvous: the old store may still hold the port.
        config["master_port"] = free_port() if self._sync_formations or not config["master_port"] else config["master_port"]
        self._sync_formations += 1
        world = 1 + len(self.generators)
        names = ["learner-rank0"] + [f"generator-{i}" for i in range(len(self.generators))]
        await asyncio.wait_for(asyncio.gather(
            self.learner.join_weight_sync.remote(config, world, names),
            *[g.join_weight_sync.remote(config, i + 1, world, names) for i, g in enumerate(self.generators)],
        ), self.cfg.weight_sync.timeout_s + 30)

    async def _broadcast_to_generators(self) -> None:
        """One collective sync of the new weights; a broken group (a generator restarted) is re-formed
        once and the sync retried, and a generator that still fails catches up via the object store."""
        timeout = self.cfg.weight_sync.timeout_s + 30
        for attempt in range(2):
            try:
                await asyncio.wait_for(asyncio.gather(
                    self.learner.broadcast_weights.remote(),
                    *[g.receive_weights.remote(self.step) for g in self.generators],
                ), timeout)
                break
            except Exception as exc:
                if attempt == 1:
                    raise RuntimeError(f"collective weight sync of version {self.step} failed twice: {exc}") from exc
                self.log(f"[weight sync] {type(exc).__name__}: {exc}; re-forming the group")
                await self._form_weight_sync_group()
        self.gen_client.publish(None, self.step)

    # -- the learner's side ----------------------------------------------------------------------
    async def _collect_batch(self) -> tuple[list[Group], dict[str, float]]:
        """Take the next `batch_size` accepted groups in admission order (FIFO)."""
        cfg = self.cfg.trainer
        batch: list[Group] = []
        inspected = filtered = failed = stale = 0
        max_inspect = int(cfg.dynamic_sampling.max_admissions_factor * cfg.batch_size)
        while len(batch) < cfg.batch_size and inspected < max_inspect:
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
                self.log(f"[rollout] group {group.seq} dropped: {group.failed}")
                continue
            if not group.accepted:
                filtered += 1
                self.filtered_recent = (self.filtered_recent + [group])[-cfg.batch_size:]
                continue
            if self.version - group.admit_version > cfg.max_staleness:
                stale += 1
                self.counters["groups_stale_dropped"] += 1
                self.group_status[group.seq] = "stale"
                async with self.cond:
                    self.unresolved -= 1
                    self.cond.notify_all()
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

    async def _train_one_step(self) -> dict[str, Any]:
        cfg = self.cfg
        t_start = time.perf_counter()
        groups, batch_info = await self._collect_batch()
        t_batch = time.perf_counter()
        samples = [s for g in groups for s in g.samples]
        if not samples:
            raise RuntimeError(f"step {self.step + 1}: no trainable groups (all rollouts failed); see the log")
        teacher_out: dict[str, TeacherOutput] | None = None
        t_learn = time.perf_counter()
        if self.teacher is not None:
            learner_metrics, teacher_out = await self._train_with_teacher(groups, samples)
        else:
            learner_metrics = await self.learner.train_step.remote(samples, None, self.step + 1)
        learner_s = time.perf_counter() - t_learn
        wait_s = float(learner_metrics.get("teacher_wait_s", 0.0))
        self.step += 1

        t_sync = time.perf_counter()
        if self.collective:
            await self._broadcast_to_generators()
            weights_ref = None
        else:
            weights_ref = self.learner.get_weights.remote()
            await self.gen_client.sync_all(weights_ref, self.step)
        teacher_action = await self._update_teacher(weights_ref) if self.teacher is not None else "none"
        sync_s = time.perf_counter() - t_sync
        if cfg.trainer.checkpoint_interval and self.step % cfg.trainer.checkpoint_interval == 0:
            await self._save_checkpoint()
        val_metrics: dict[str, float] = {}
        val_due = bool(cfg.trainer.val_interval) and self.step % cfg.trainer.val_interval == 0 and bool(self.val_refs)
        if val_due and cfg.trainer.max_staleness == 0:
            # On-policy runs validate between steps, alone on the generators, so the run stays
            # deterministic (no training request shares a generation batch with a validation one).
            val_metrics = await self._validate()
        # Only now may work for the next versions start (staleness is counted against this version).
        async with self.cond:
            self.version = self.step
            self.unresolved -= len([g for g in groups if g.accepted])
            self.counters["groups_consumed"] += len(groups)
            for g in groups:
                if g.accepted:
                    self.group_status[g.seq] = "consumed"
            self.cond.notify_all()
        if val_due and cfg.trainer.max_staleness > 0:
            val_metrics = await self._validate()
        step_s = time.perf_counter() - t_start - val_metrics.get("val_time_s", 0.0)

        record: dict[str, Any] = {"step": self.step}
        record.update(rollout_metrics(samples, cfg.rollout.max_response_tokens))
        record.update({k: float(v) for k, v in learner_metrics.items()})
        lags = [self.step - 1 - v for s in samples for v, m in zip(s.policy_versions, s.loss_mask) if m]
        tokens = sum(len(s.input_ids) - s.prompt_length for s in samples)
        record.update(batch_info)
        record.update({
            "policy_lag_max": float(max(lags) if lags else 0), "policy_lag_mean": float(np.mean(lags) if lags else 0),
            # The share of the learner step spent blocked on the teacher (T1's overlap hides the rest).
            "teacher_wait_s": wait_s, "teacher_wait_frac": wait_s / max(learner_s, 1e-9),
            "time_step_s": step_s, "time_batch_wait_s": t_batch - t_start, "time_learner_s": learner_s,
            "time_weight_sync_s": sync_s,
            "time_generation_s": float(sum(s.metadata.get("generate_s", 0.0) for s in samples)),
            "time_env_s": float(sum(s.metadata.get("env_s", 0.0) for s in samples)),
            "trajectories_per_s": len(samples) / step_s, "tokens_per_s": tokens / step_s,
            "teacher_updates": float(self.teacher_version),
            "generator_failures": float(self.gen_client.failures), "episode_reruns": float(len(self.ledger.lost_attempts)),
            "batch_size_groups": float(len(groups)),
        })
        record["teacher_action"] = {"none": 0.0, "ema": 1.0, "hard_copy": 2.0}[teacher_action]
        if "grad_norm" not in record:
            raise RuntimeError("learner.train_step returned no grad_norm")
        record.setdefault("kl_teacher", 0.0)
        self.sink.observe("response_length", [s.response_tokens for s in samples])
        self.sink.observe("episode_turns", [len(s.turns) for s in samples])
        self.sink.observe("episode_tool_calls", [s.num_tool_calls for s in samples])
        if cfg.trainer.save_trajectories:
            write_samples(samples, self.run_dir / "trajectories" / f"step_{self.step:06d}.parquet",
                          step=self.step, teacher=teacher_out)
        record.update(val_metrics)
        self.sink.write(record)
        if cfg.metrics.progress:
            self.log(self._progress_line(record))
        return record

    def _progress_line(self, r: dict[str, Any]) -> str:
        val = f" | val acc {r['val_accuracy']:.3f} reward {r['val_reward_mean']:.3f}" if "val_accuracy" in r else ""
        return (f"step {r['step']}/{self.cfg.trainer.max_steps} | reward {r['reward_mean']:.3f} "
                f"acc {r['accuracy']:.2f} | len {r['response_length_mean']:.0f} turns {r['turns_mean']:.2f} "
                f"tools {r['tool_calls_mean']:.2f} | kl_t {r.get('kl_teacher', 0):.4f} kl_ref {r.get('kl_ref', 0):.4f} "
                f"| filtered {r['filtered_groups_frac']:.2f} | {r['time_step_s']:.1f}s "
                f"(learner {r['time_learner_s']:.1f}s, teacher wait {r['teacher_wait_s']:.1f}s){val}")

    # -- validation ------------------------------------------------------------------------------
    async def _validate(self) -> dict[str, float]:
        cfg = self.cfg
        t0 = time.perf_counter()
        specs = []
        for index, task in enumerate(self.val_refs):
            # Same seeds at every validation, so steps differ only by the policy.
            specs.extend(self._specs(index, task, self.version, cfg.trainer.val_group_size,
                                     tag="val", greedy=cfg.trainer.val_greedy))
        samples = await self._episodes_unique(specs)
        for s in samples:
            s.correct = is_correct(s, cfg)
            s.reward = shape_reward(s, cfg)
        metrics = rollout_metrics(samples, cfg.rollout.max_response_tokens, prefix="val_")
        metrics["val_env_reward_mean"] = metrics.pop("val_env_reward_mean", 0.0)
        metrics["val_time_s"] = time.perf_counter() - t0
        with (self.run_dir / "validation.jsonl").open("a", encoding="utf-8") as handle:
            handle.write(json.dumps({"step": self.step, **metrics}) + "\n")
        if cfg.trainer.save_trajectories:
            write_samples(samples, self.run_dir / "validation" / f"step_{self.step:06d}.parquet", step=self.step)
        self.last_val = metrics
        self.log(f"[validation] step {self.step}: accuracy {metrics['val_accuracy']:.3f}, reward "
                 f"{metrics['val_reward_mean']:.3f} (env {metrics['val_env_reward_mean']:.3f}) over "
                 f"{len(samples)} episodes in {metrics['val_time_s']:.1f}s")
        return metrics

    async def _episodes_unique(self, specs: list[EpisodeSpec]) -> list[RolloutSample]:
        # Validation re-uses its seeds at every pass; a fresh ledger per pass keeps ids unique.
        self.val_ledger = EpisodeLedger()
        return await self._episodes(specs, self.val_ledger)

    # -- the run ---------------------------------------------------------------------------------
    async def _main(self) -> dict[str, Any]:
        cfg = self.cfg
        self.cond = asyncio.Condition()
        self._group_tasks: dict[int, TaskRef] = {}
        self.pool = EnvPool(**self.pool_args)
        self.gen_client = GeneratorClient(self.generators, cfg.generator.max_call_attempts,
                                          cfg.trainer.weight_sync_timeout_s,
                                          weights_provider=lambda: self.learner.get_weights.remote())
        self.collective = cfg.weight_sync.transport == "collective"
        self._sync_formations = 0
        await self.pool.ready()
        if self.collective:
            await self._form_weight_sync_group()
        resumed = await self._restore() if self.resume else False
        self.sink = MetricsSink(self.run_dir, tensorboard=cfg.metrics.tensorboard, ray_metrics=cfg.metrics.ray_metrics,
                                run_name=cfg.name, resume=resumed)
        if resumed:
            self.sink.truncate_after(self.step)
        elif (self.run_dir / "validation.jsonl").exists():
            (self.run_dir / "validation.jsonl").unlink()
        started = time.perf_counter()
        if self.step == 0 and cfg.trainer.val_at_start and self.val_refs:
            await self._validate()
        admission = asyncio.ensure_future(self._admission_loop())
        finished = False
        try:
            while self.step < cfg.trainer.max_steps:
                await self._train_one_step()
                if admission.done():
                    admission.result()  # re-raise an admission error
            finished = True
        finally:
            async with self.cond:
                self.stopping = True
                self.cond.notify_all()
            await asyncio.gather(admission, return_exceptions=True)
            if finished and self.in_flight:
                # Let admitted groups finish so every episode is accounted for (completed or failed).
                await asyncio.wait(list(self.in_flight.values()), timeout=cfg.trainer.drain_timeout_s)
            for seq, task in list(self.in_flight.items()):
                task.cancel()
                self.group_status[seq] = "cancelled"
            await asyncio.gather(*self.in_flight.values(), return_exceptions=True)
            for seq, status in self.group_status.items():
                if status == "done":
                    self.group_status[seq] = "leftover"
        if self.step and not (cfg.trainer.checkpoint_interval and self.step % cfg.trainer.checkpoint_interval == 0):
            await self._save_checkpoint()
        if self.val_refs and cfg.trainer.val_interval and self.step % cfg.trainer.val_interval != 0:
            await self._validate()
        self.sink.close()
        from learner.plot import plot_runs

        plot_path = plot_runs([self.run_dir])
        self.log(f"[done] {self.step} steps; figure {plot_path}")
        summary = {"steps": self.step, "wall_s": time.perf_counter() - started, "run_dir": str(self.run_dir),
                   "policy_dir": str(self.policy_dir), "counters": dict(self.counters),
                   "ledger": self.ledger.balance(), "generator_failures": self.gen_client.failures,
                   "group_status": {k: sum(1 for v in self.group_status.values() if v == k)
                                    for k in sorted(set(self.group_status.values()))},
                   "last_validation": self.last_val}
        (self.run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
        return summary

    def run(self) -> dict[str, Any]:
        """Build everything, train `trainer.max_steps` steps, write the run directory; returns a summary."""
        self._build()
        try:
            return asyncio.run(self._main())
        finally:
            self.shutdown()

    def shutdown(self) -> None:
        import ray

        if getattr(self, "kb_client", None) is not None:
            self.kb_client.shutdown()
        for handle in [getattr(self, "learner", None), self.teacher, *getattr(self, "generators", []),
                       *(self.pool.actors if hasattr(self, "pool") else [])]:
            if handle is not None:
                try:
                    ray.kill(handle)
                except Exception:
                    pass


def train(cfg: RunConfig, *, resume: bool = False, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Run training from a config (the `hcgym train` entry point)."""
    return Trainer(cfg, resume=resume, log=log).run()


def replay_loss(parquet_path: str | Path, model_dir: str | Path, cfg: RunConfig) -> dict[str, float]:
    """Debug path: recompute the loss of stored trajectories (and their stored teacher log-probs)
    with the learner's loss code, in this process, without updating anything."""
    from learner.learner_actor import Learner
    from learner.metrics import read_samples

    samples, extras = read_samples(parquet_path)
    teacher = None
    if cfg.learner.loss.distill.enabled:
        teacher = []
        for s in samples:
            extra = extras[s.sample_id]
            if extra["teacher_logprobs"] is None:
                raise ValueError(f"{parquet_path}: sample {s.sample_id} has no stored teacher log-probs, "
                                 "but the config enables distillation")
            teacher.append(TeacherOutput(sample_id=s.sample_id, teacher_version=int(extra["teacher_version"]),
                                         hint=extra["teacher_hint"] or "none", input_length=len(s.input_ids),
                                         logprobs=list(extra["teacher_logprobs"])))
    learner = Learner(cfg.learner.model_dump(), str(model_dir), cfg.seed)
    try:
        return learner.evaluate_loss(samples, teacher)
    finally:
        learner.shutdown()


def build_arg_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="python -m learner.train", description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="run config YAML (see configs/)")
    parser.add_argument("--max-steps", type=int, default=None, help="override trainer.max_steps")
    parser.add_argument("--output-dir", default=None, help="override output_dir (the run directory)")
    parser.add_argument("--resume", action="store_true", help="continue from the run directory's latest checkpoint")
    parser.add_argument("--seed", type=int, default=None, help="override seed")
    parser.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                        help="override any config key (repeatable)")
    return parser


def config_from_args(args: argparse.Namespace) -> RunConfig:
    overrides = list(args.set)
    if args.max_steps is not None:
        overrides.append(f"trainer.max_steps={args.max_steps}")
    if args.output_dir is not None:
        overrides.append(f"output_dir={args.output_dir}")
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    return load_config(args.config, overrides)


def main(argv: list[str] | None = None) -> int:
    args = build_arg_parser().parse_args(argv)
    summary = train(config_from_args(args), resume=args.resume)
    print(json.dumps({k: summary[k] for k in ("steps", "wall_s", "run_dir")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
