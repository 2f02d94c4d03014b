"""The training driver: wires the actors from a `RunConfig` and runs GRPO / TT-OPD.

    python -m learner.train --config configs/tiny_cpu_ttopd.yaml [--max-steps N] [--output-dir DIR] [--resume]
    hcgym train --config ...                                        (the same)

Data flow (Algorithm 1, made asynchronous):

    admission --(EpisodeSpec x G)--> env pool + generators (TITO agent loop)
        --> group complete: reward (5D total or Eq. 4), correctness, dynamic-sampling verdict
        --> accepted: submitted to the teacher at once (it scores in the background)
        --> FIFO by admission order into the learner's next batch
    learner step --> weights --> generators (every step), teacher (EMA / hard copy steps)

Streaming: groups are admitted, rolled out, scored and sent to the teacher independently; there is
no barrier where a whole batch of rollouts must finish. `Trainer` is the loop over steps; each job
has its own module:

    learner/tasks.py            which tasks, in which order, with which seeds (TaskSampler)
    learner/batching.py         admission, staleness bound, dynamic sampling, FIFO batches (BatchScheduler)
    learner/rollouts.py         groups and validation passes over the env pool and generators (Rollouts)
    learner/teacher_client.py   teacher submit / fetch / update, retries and recovery (TeacherClient)
    learner/weight_publisher.py weights to the generators: object store or collective (WeightPublisher)
    learner/run_checkpoint.py   save / restore of a run checkpoint (learner, teacher, driver.json)
    learner/run_actors.py       Ray and the actors of a run
    learner/step_metrics.py     one step's metrics record and progress line
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

import envs._runtime  # noqa: F401  (CPU-path environment defaults before torch/ray load)
from actors.agent_loop import AgentLoop, RolloutLimits
from actors.env_actor import EnvPool, register_domains
from actors.generator import GeneratorClient
from actors.types import TeacherBatch, TeacherOutput
from learner.batching import BatchScheduler, Group, is_correct, mixed_outcomes, score_sample, shape_reward
from learner.config import RunConfig, dump_config, load_config
from learner.train_args import build_arg_parser, config_from_args
from learner.metrics import MetricsSink, write_samples
from learner.rollouts import Rollouts
from envs.core.files import DiskFullError
from learner.run_actors import (
    check_run_fits,
    init_ray,
    learner_node_lost,
    start_generators,
    start_kb_service,
    start_learner,
    start_teacher,
    stop_learner,
    wait_started,
)
from learner.faults import fault_point
from learner.run_checkpoint import commit_run_checkpoint, restore_run_checkpoint, save_run_checkpoint
from learner.step_metrics import StepTimes, progress_line, step_record
from learner.tasks import TaskRef, TaskSampler, episode_seed, load_task_refs, prompt_lengths, select_tasks
from learner.teacher_client import TeacherClient
from learner.weight_publisher import WeightPublisher

__all__ = ["Trainer", "train", "main", "replay_loss", "load_task_refs", "prompt_lengths", "TaskSampler", "TaskRef",
           "episode_seed", "Group", "is_correct", "shape_reward", "score_sample", "mixed_outcomes"]


class Trainer:
    """One training run: `run()` builds the actors, then loops over learner steps.

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
        self.counters: dict[str, int] = {}
        # Built by `_build` (actors, collaborators) and `_main` (the metrics sink); None until then.
        self.policy_dir: Path | None = None
        self.val_refs: list[TaskRef] = []
        self.kb_client = None
        self.generators: list = []
        self.learner = None
        self.teacher = None
        self.pool: EnvPool | None = None
        self.gen_client: GeneratorClient | None = None
        self.scheduler: BatchScheduler | None = None
        self.rollouts: Rollouts | None = None
        self.teacher_client: TeacherClient | None = None
        self.publisher: WeightPublisher | None = None
        self.sink: MetricsSink | None = None
        self.learner_nodes: dict[str, str] = {}  # Ray node id -> what of the learner runs there

    def _build(self) -> None:
        """Policy, tasks, actors and the collaborators of the loop."""
        from modeling.model import ENDOFTEXT, IM_END, load_tokenizer
        from learner.sft import prepare_policy

        cfg = self.cfg
        register_domains(cfg.data.domain_modules)
        for key, value in cfg.rollout.env_vars.items():  # the driver runs episodes too (gold replays)
            os.environ.setdefault(key, value)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        dump_config(cfg, self.run_dir / "config.yaml")
        self.policy_dir = prepare_policy(cfg, self.run_dir, log=self.log)
        tokenizer = load_tokenizer(self.policy_dir)
        limits = RolloutLimits(**{k: getattr(cfg.rollout, k) for k in RolloutLimits.model_fields})
        loop = AgentLoop(tokenizer, limits, cfg.rollout.system_prompt)
        max_prompt = cfg.rollout.max_prompt_tokens if cfg.data.filter_long_prompts else None
        d = cfg.data
        train_refs = select_tasks(d.domains, d.train_split, d.max_train_tasks, d.task_id_pattern, what="train",
                                  loop=loop, max_prompt_tokens=max_prompt, log=self.log)
        if cfg.trainer.val_interval or cfg.trainer.val_at_start:
            self.val_refs = select_tasks(d.domains, d.val_split, d.max_val_tasks, d.task_id_pattern,
                                         what="validation", loop=loop, max_prompt_tokens=max_prompt, log=self.log)
        init_ray(cfg, self.log)
        check_run_fits(cfg)  # before any actor exists: a run the cluster cannot hold fails naming what is missing
        self.log(f"[setup] {len(train_refs)} train / {len(self.val_refs)} validation tasks; policy {self.policy_dir}")
        self.kb_client = start_kb_service(cfg)
        if self.kb_client is not None:
            self.log(f"[setup] knowledge-base service {cfg.kb.name!r} with {cfg.kb.replicas} replica(s)")
        stop_ids = [tokenizer.convert_tokens_to_ids(t) for t in (IM_END, ENDOFTEXT)]
        self.generators = start_generators(cfg, str(self.policy_dir), stop_ids)
        self.learner = start_learner(cfg, str(self.policy_dir))
        r = cfg.rollout
        self.pool = EnvPool(**r.env_pool_options(cfg.reward.env_kwargs()), domain_modules=d.domain_modules,
                            kb_service=cfg.kb.name if self.kb_client is not None else None,
                            resources=dict(cfg.ray.env_resources) or None)
        self.gen_client = GeneratorClient(self.generators, cfg.generator.max_call_attempts,
                                          cfg.weight_sync.timeout_s,
                                          weights_provider=lambda: self.learner.get_weights.remote(),
                                          restart_wait_s=cfg.generator.restart_wait_s, log=self.log)
        self.scheduler = BatchScheduler(cfg.trainer, TaskSampler(train_refs, cfg.seed), self.log, self.counters)
        self.rollouts = Rollouts(cfg, loop, self.pool, self.gen_client, self.run_dir, self.log)
        if cfg.teacher.enabled:
            self.teacher = start_teacher(cfg, str(self.policy_dir))
            self.teacher_client = TeacherClient(self.teacher, self.learner, cfg, self.counters, self.log)
        # rendezvous clocks start after this
        report = wait_started(cfg, self.learner, self.generators, self.teacher, self.log)
        self.learner_nodes = {node: f"learner rank {rank}" for rank, node in enumerate(report["rank_nodes"])}
        self.learner_nodes.setdefault(report.get("learner_node", ""), "the learner actor")
        self.learner_nodes.pop("", None)
        member = self.teacher_client.group_member if self.teacher_client is not None else None
        self.publisher = WeightPublisher(cfg, self.learner, self.generators, self.gen_client, self.log, member)

    async def _produce_group(self, seq: int, task: TaskRef, version: int) -> Group:
        submit = self.teacher_client.submit if self.teacher_client is not None else None
        return await self.rollouts.group(seq, task, version, on_accepted=submit)

    async def _validate(self) -> dict[str, float]:
        metrics = await self.rollouts.validate(self.val_refs, self.step, self.scheduler.version)
        fault_point("validation_written", self.step)
        return metrics

    async def _save_checkpoint(self, *, mark: bool = True) -> None:
        await save_run_checkpoint(self.run_dir, self.step, self.learner, self.teacher_client, self.scheduler,
                                  self.counters, self.rollouts.ledger.balance(), self.cfg.trainer.keep_checkpoints,
                                  mark=mark)

    async def _restore(self) -> bool:
        restored = await restore_run_checkpoint(self.run_dir, self.learner, self.teacher_client, self.scheduler,
                                                self.counters, self.log)
        if restored is None:
            return False
        self.step, directory = restored
        await self.publisher.sync_object_store(self.step)
        self.log(f"[resume] restored step {self.step} from {directory}")
        return True

    async def _train_one_step(self) -> dict[str, Any]:
        cfg = self.cfg
        t_start = time.perf_counter()
        groups, batch_info = await self.scheduler.collect_batch()
        t_batch = time.perf_counter()
        samples = [s for g in groups for s in g.samples]
        if not samples:
            raise RuntimeError(
                f"step {self.step + 1}: no trainable groups among {batch_info['groups_inspected']:.0f} inspected "
                f"({batch_info['groups_failed']:.0f} failed, {batch_info['groups_stale_dropped']:.0f} stale, "
                f"the rest filtered by dynamic sampling with none recent enough to top up); see the log")
        teacher_out: dict[str, TeacherOutput] | None = None
        if self.teacher_client is not None:
            learner_metrics, teacher_out = await self.teacher_client.train_step(groups, samples, self.step + 1)
        else:
            learner_metrics = await self.learner.train_step.remote(samples, None, self.step + 1)
        learner_s = time.perf_counter() - t_batch
        self.step += 1

        t_sync = time.perf_counter()
        published = await self.publisher.publish(self.step)
        teacher_action = "none"
        if self.teacher_client is not None:
            # Awaited: work admitted afterwards is scored by the updated teacher.
            teacher_action = await self.teacher_client.update(self.step, published.weights_ref,
                                                              published.teacher_result)
        sync_s = time.perf_counter() - t_sync
        # The checkpoint captures the data position here (before `consumed` lets the next versions'
        # work start), but becomes `latest` only after the step's trajectories, validation and
        # metrics row are written: a crash in between resumes from the previous checkpoint and
        # redoes this step instead of skipping what it had not recorded yet.
        checkpoint_due = bool(cfg.trainer.checkpoint_interval) and self.step % cfg.trainer.checkpoint_interval == 0
        if checkpoint_due:
            await self._save_checkpoint(mark=False)
        val_metrics: dict[str, float] = {}
        val_due = bool(cfg.trainer.val_interval) and self.step % cfg.trainer.val_interval == 0 and bool(self.val_refs)
        if val_due and cfg.trainer.max_staleness == 0:
            # On-policy runs validate between steps, alone on the generators, so the run stays
            # deterministic (no training request shares a generation batch with a validation one).
            val_metrics = await self._validate()
        # Only now may work for the next versions start (staleness is counted against this version).
        await self.scheduler.consumed(groups, self.step)
        if val_due and cfg.trainer.max_staleness > 0:
            val_metrics = await self._validate()
        step_s = time.perf_counter() - t_start - val_metrics.get("val_time_s", 0.0)

        times = StepTimes(step=step_s, batch_wait=t_batch - t_start, learner=learner_s, weight_sync=sync_s)
        record = step_record(self.step, samples, learner_metrics, batch_info, times,
                             max_response_tokens=cfg.rollout.max_response_tokens, teacher_action=teacher_action,
                             teacher_version=self.teacher_client.version if self.teacher_client is not None else 0,
                             teacher_sync=self.teacher_client.sync_metrics() if self.teacher_client else {},
                             generator_failures=self.gen_client.failures, generator=self.gen_client.metrics(),
                             episode_reruns=len(self.rollouts.ledger.lost_attempts), batch_groups=len(groups))
        self.sink.observe("response_length", [s.response_tokens for s in samples])
        self.sink.observe("episode_turns", [len(s.turns) for s in samples])
        self.sink.observe("episode_tool_calls", [s.num_tool_calls for s in samples])
        if cfg.trainer.save_trajectories:
            write_samples(samples, self.run_dir / "trajectories" / f"step_{self.step:06d}.parquet",
                          step=self.step, teacher=teacher_out)
        fault_point("trajectories_written", self.step)
        record.update(val_metrics)
        self.sink.write(record)
        fault_point("metrics_written", self.step)
        if checkpoint_due:
            commit_run_checkpoint(self.run_dir, self.step, cfg.trainer.keep_checkpoints)
        if cfg.metrics.progress:
            self.log(progress_line(record, cfg.trainer.max_steps))
        return record

    async def _main(self) -> dict[str, Any]:
        cfg = self.cfg
        await self.pool.ready()
        await self.publisher.start()
        resumed = await self._restore() if self.resume else False
        self.sink = MetricsSink(self.run_dir, tensorboard=cfg.metrics.tensorboard, ray_metrics=cfg.metrics.ray_metrics,
                                run_name=cfg.name, resume=resumed)
        if resumed:
            self.sink.truncate_after(self.step, log=self.log)
        elif (self.run_dir / "validation.jsonl").exists():
            (self.run_dir / "validation.jsonl").unlink()
        started = time.perf_counter()
        if self.step == 0 and cfg.trainer.val_at_start and self.val_refs:
            await self._validate()
        admission = asyncio.ensure_future(self.scheduler.admission_loop(self._produce_group))
        finished = False
        try:
            while self.step < cfg.trainer.max_steps:
                await self._train_one_step()
                if admission.done():
                    admission.result()  # re-raise an admission error
            finished = True
        finally:
            await self.scheduler.stop()
            await asyncio.gather(admission, return_exceptions=True)
            await self.scheduler.drain(finished, cfg.trainer.drain_timeout_s)
        # The last validation comes before the last checkpoint becomes `latest`, so a crash during it
        # redoes it on resume; a run resumed after it (the folder has its row) does not repeat it.
        if (self.val_refs and cfg.trainer.val_interval and self.step % cfg.trainer.val_interval != 0
                and self.step not in self.sink.validated_steps()):
            await self._validate()
        if self.step and not (cfg.trainer.checkpoint_interval and self.step % cfg.trainer.checkpoint_interval == 0):
            await self._save_checkpoint()
        self.sink.close()
        from learner.plot import plot_runs

        plot_path = plot_runs([self.run_dir])
        self.log(f"[done] {self.step} steps; figure {plot_path}")
        summary = {"steps": self.step, "wall_s": time.perf_counter() - started, "run_dir": str(self.run_dir),
                   "policy_dir": str(self.policy_dir), "counters": dict(self.counters),
                   "ledger": self.rollouts.ledger.balance(), "generator_failures": self.gen_client.failures,
                   "generator": self.gen_client.metrics(),
                   "group_status": self.scheduler.status_counts(), "last_validation": self.rollouts.last_val}
        (self.run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
        return summary

    def run(self) -> dict[str, Any]:
        """Build everything, train `trainer.max_steps` steps, write the run directory; returns a summary."""
        try:
            self._build()
            return asyncio.run(self._main())
        except DiskFullError as exc:
            hint = f"The run stopped at learner step {self.step}; {self._kept()}. Free space on that disk, then " \
                   f"rerun with --resume (it continues from that checkpoint and redoes the steps after it)"
            raise exc.with_hint(f"{exc.hint}. {hint}" if exc.hint else hint) from exc
        except Exception as exc:
            lost = learner_node_lost(exc, self.learner_nodes, self._learner_needs, self._kept, self.step)
            if lost is None:
                raise
            raise lost from exc
        finally:
            self.shutdown()

    def _kept(self) -> str:
        """What a resume starts from, in words (for the error of a stopped run)."""
        from modeling.checkpoint import latest_checkpoint

        try:
            latest = latest_checkpoint(self.run_dir)
        except (OSError, ValueError):
            latest = None
        return f"the last complete checkpoint is {latest}" if latest is not None else \
            f"{self.run_dir} has no complete checkpoint yet (a resume starts from step 0)"

    def _learner_needs(self) -> str:
        from learner.placement import run_demands

        parts = [f"{d.count} x {d.name}: " + (", ".join(f"{k} {v:g}" for k, v in d.resources.items()) or "no resources")
                 for d in run_demands(self.cfg) if d.name.startswith("learner")]
        return "; ".join(parts)

    def shutdown(self) -> None:
        import ray

        # The TensorBoard writer runs a daemon thread; a run that fails must stop it too, or it is
        # still alive (and waking up) while the interpreter exits.
        if self.sink is not None:
            self.sink.close()
        if self.kb_client is not None:
            self.kb_client.shutdown()
        if self.learner is not None:
            stop_learner(self.learner)  # releases the ranks' placement group too
        actors = [self.teacher, *self.generators, *(self.pool.actors if self.pool is not None else [])]
        for handle in actors:
            if handle is not None:
                try:
                    ray.kill(handle)
                except Exception:  # already dead: nothing to release
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
        outputs = []
        for s in samples:
            extra = extras[s.sample_id]
            if extra["teacher_logprobs"] is None:
                raise ValueError(f"{parquet_path}: sample {s.sample_id} has no stored teacher log-probs, "
                                 "but the config enables distillation")
            outputs.append(TeacherOutput(sample_id=s.sample_id, teacher_version=int(extra["teacher_version"]),
                                         hint=extra["teacher_hint"] or "none", input_length=len(s.input_ids),
                                         logprobs=list(extra["teacher_logprobs"])))
        teacher = TeacherBatch(outputs=outputs)
    learner = Learner(cfg.learner.model_dump(), str(model_dir), cfg.seed)
    try:
        return learner.evaluate_loss(samples, teacher)
    finally:
        learner.shutdown()


def main(argv: list[str] | None = None) -> int:
    from learner.run_folder import run_undoing_failed_start

    args = build_arg_parser().parse_args(argv)
    cfg = config_from_args(args)
    summary = run_undoing_failed_start(
        Path(cfg.output_dir), lambda: train(cfg, resume=args.resume),
        lambda text: print(f"python -m learner.train: {text}", file=sys.stderr))
    print(json.dumps({k: summary[k] for k in ("steps", "wall_s", "run_dir")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
