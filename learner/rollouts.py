"""Rolling out groups for training and passes for validation over the env pool and the generators.

A training group is `rollout.group_size` episodes of one task with seeds fixed by its sequence
number; each finished sample gets its correctness and RL reward (`batching.is_correct`,
`batching.shape_reward`), and the group its dynamic-sampling verdict. Validation runs every
validation task with the same seeds at every pass, so passes differ only by the policy.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path

from actors.agent_loop import AgentLoop, EpisodeSpec, PromptTooLongError
from actors.env_actor import EnvActorLost, EnvPool, EpisodeLedger, run_episode
from actors.generator import GeneratorClient, GeneratorUnavailableError
from actors.types import RolloutSample
from learner.batching import Group, mixed_outcomes, score_sample
from learner.config import RunConfig
from envs.core.files import append_durable
from learner.metrics import json_record, rollout_metrics, write_samples
from learner.tasks import TaskRef, episode_specs


class Rollouts:
    """Runs episodes for the driver and keeps their ledgers (every episode accounted for once).

    Args:
        cfg: The run config.
        loop: The agent loop (tokenizer, limits, prompt rendering).
        pool: The env actors.
        gen_client: The generators.
        run_dir: Where validation results go.
        log: Where notices go.
    """

    def __init__(self, cfg: RunConfig, loop: AgentLoop, pool: EnvPool, gen_client: GeneratorClient, run_dir: Path,
                 log: Callable[[str], None] = print) -> None:
        self.cfg = cfg
        self.loop = loop
        self.pool = pool
        self.gen_client = gen_client
        self.run_dir = run_dir
        self.log = log
        self.ledger = EpisodeLedger()
        self.val_ledger = EpisodeLedger()
        self.last_val: dict[str, float] = {}

    async def episodes(self, specs: list[EpisodeSpec], ledger: EpisodeLedger) -> list[RolloutSample]:
        for spec in specs:
            ledger.admit(spec.sample_id)
        # Every episode runs to its end before an error is raised: a plain gather would raise the
        # first and leave the others running unowned, in the ledger's flight and on the env actors
        # and generators after their group was replaced, and cancelled mid-episode (neither
        # completed nor failed) if the run ended first.
        outcomes = await asyncio.gather(*[
            run_episode(spec, self.loop, self.pool, self.gen_client, ledger, self.cfg.rollout.max_episode_attempts)
            for spec in specs
        ], return_exceptions=True)
        errors = [o for o in outcomes if isinstance(o, BaseException)]
        if errors:
            # A bug anywhere in the group outranks an expected failure next to it.
            expected = (EnvActorLost, PromptTooLongError, GeneratorUnavailableError)
            raise next((e for e in errors if not isinstance(e, expected)), errors[0])
        return list(outcomes)

    async def group(self, seq: int, task: TaskRef, version: int,
                    on_accepted: Callable[[Group], None] | None = None) -> Group:
        """Roll out group `seq`, score it, and call `on_accepted` (teacher submission) if it is kept.

        Never raises: a lost env actor, an over-long prompt, a generator that did not come back
        within `generator.restart_wait_s` or an episode ended by an env error (`metadata["env_error"]`,
        see actors/env_actor.py) marks the group failed (dropped, logged, and replaced by a new
        group); any other error is kept in `group.error` and surfaced by the consumer with its group.
        """
        cfg = self.cfg
        group = Group(seq=seq, task=task, admit_version=version)
        try:
            samples = await self.episodes(episode_specs(cfg.seed, seq, task, version, cfg.rollout.group_size),
                                          self.ledger)
            broken = [s.metadata["env_error"] for s in samples if s.metadata.get("env_error")]
            if broken:  # an env bug ended these episodes unscored: drop the group, do not train on it
                group.failed = f"env_error in {len(broken)} of {len(samples)} episodes: {broken[0]}"
                group.completed_at = time.perf_counter()
                return group
            for s in samples:
                score_sample(s, cfg)
                s.metadata["group_seq"] = seq
                s.metadata["admit_version"] = version
            group.samples = samples
            group.accepted = (not cfg.trainer.dynamic_sampling.enabled) or mixed_outcomes(samples, cfg)
            if group.accepted and on_accepted is not None:
                on_accepted(group)
        except (EnvActorLost, PromptTooLongError, GeneratorUnavailableError) as exc:
            group.failed = f"{type(exc).__name__}: {exc}"
            group.outage = isinstance(exc, GeneratorUnavailableError)
        except Exception as exc:  # a bug: surfaced by the consumer with its group
            group.failed = f"{type(exc).__name__}: {exc}"
            group.error = exc
        group.completed_at = time.perf_counter()
        return group

    async def validate(self, refs: list[TaskRef], step: int, version: int) -> dict[str, float]:
        """One validation pass; appends to `validation.jsonl` and returns the `val_*` metrics."""
        cfg = self.cfg
        t0 = time.perf_counter()
        specs = []
        for index, task in enumerate(refs):
            # Same seeds at every validation, so steps differ only by the policy.
            specs.extend(episode_specs(cfg.seed, index, task, version, cfg.trainer.val_group_size,
                                       tag="val", greedy=cfg.trainer.val_greedy))
        # Validation re-uses its seeds at every pass; a fresh ledger per pass keeps ids unique.
        self.val_ledger = EpisodeLedger()
        samples = await self.episodes(specs, self.val_ledger)
        for s in samples:
            score_sample(s, cfg)
        metrics = rollout_metrics(samples, cfg.rollout.max_response_tokens, prefix="val_")
        metrics["val_env_reward_mean"] = metrics.pop("val_env_reward_mean", 0.0)
        metrics["val_time_s"] = time.perf_counter() - t0
        row = json.dumps(json_record({"step": step, **metrics}), allow_nan=False) + "\n"
        append_durable(self.run_dir / "validation.jsonl", row.encode("utf-8"))  # a full disk: DiskFullError
        if cfg.trainer.save_trajectories:
            write_samples(samples, self.run_dir / "validation" / f"step_{step:06d}.parquet", step=step)
        self.last_val = metrics
        self.log(f"[validation] step {step}: accuracy {metrics['val_accuracy']:.3f}, reward "
                 f"{metrics['val_reward_mean']:.3f} (env {metrics['val_env_reward_mean']:.3f}) over "
                 f"{len(samples)} episodes in {metrics['val_time_s']:.1f}s")
        return metrics
