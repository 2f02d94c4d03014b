"""Run an evaluation: a policy on suite items under a condition, results appended to a folder.

    run_eval(policy, items, condition, output_dir, seeds=[0], ...)

Episodes run concurrently: on a Ray env-actor pool (`actors.env_actor.EnvPool`, the training
pool) with a Ray generator pool for local models, or in-process (`LocalEnv`, one per episode in
flight) for `use_ray=False`; endpoints are throttled by `concurrency` (an asyncio semaphore).
Every episode is keyed by (policy_id, benchmark, task_id, condition, seed). Finished rows are
written to `results.parquet` (and their messages to `trajectories.parquet`) as they come in (the
file is rewritten atomically at most once per `flush_every_s`, and at the end or on an
interruption), so a re-run skips every key already present: an interrupted evaluation resumes
where it stopped and a finished one is never recomputed. Seeds are the episode seeds of the env
and of the policy's sampling (per turn: `actors.agent_loop.turn_seed`), so a re-run of a key
reproduces it.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from envs.core.files import DiskFullError, read_parquet, replace_atomic, write_text_atomic
from evals.conditions import CONDITION_RUNNERS, ConditionSettings, EpisodeOutcome, is_multiple_choice
from evals.types import (
    CONDITIONS,
    RESULTS_FILE,
    SPEC_FILE,
    TRAJECTORIES_FILE,
    EvalItem,
    EvalSpec,
    ResultRow,
    read_results,
    results_schema,
    row_to_record,
)
from learner.faults import fault_point


def trajectory_schema():
    import pyarrow as pa

    return pa.schema([("row_id", pa.string()), ("policy_id", pa.string()), ("benchmark", pa.string()),
                      ("task_id", pa.string()), ("condition", pa.string()), ("seed", pa.int64()),
                      ("messages", pa.string())])


def row_id(key: tuple) -> str:
    """A short stable id of a result key (the trajectory's id in trajectories.parquet)."""
    return hashlib.blake2b(json.dumps(list(key)).encode(), digest_size=8).hexdigest()


def task_type_of(task) -> str:
    if task.description.task_type:
        return task.description.task_type
    return "multiple_choice" if task.options else task.answer_type


def load_tasks_for(items: list[EvalItem]) -> dict[tuple[str, str | None], dict[str, Any]]:
    """(domain, split) -> {task id: Task} for every item; names the item whose task is missing."""
    from envs import registry

    tasks: dict[tuple[str, str | None], dict[str, Any]] = {}
    for item in items:
        where = (item.domain, item.split)
        if where not in tasks:
            tasks[where] = {t.id: t for t in registry.get_tasks(item.domain, item.split)}
        if item.task_id not in tasks[where]:
            raise LookupError(f"benchmark {item.benchmark!r}: task {item.task_id!r} is not in domain "
                              f"{item.domain!r} split {item.split!r}")
    return tasks


def is_retryable(row: ResultRow) -> bool:
    """An episode that ended because the endpoint failed (connection, timeout, 429/5xx after retries,
    malformed replies): not the policy's doing, so `--retry-errors` may run it again."""
    return row.end_reason == "endpoint_error"


class ResultsStore:
    """The rows of a results folder: the keys already done, and new rows written as they finish."""

    def __init__(self, output_dir: Path, flush_every_s: float = 2.0, *, retry_errors: bool = False) -> None:
        self.dir = output_dir
        self.dir.mkdir(parents=True, exist_ok=True)
        rows = read_results(self.dir)
        trajectories = self._read_trajectories()
        # --retry-errors: episodes an endpoint failed (after its own retries) are dropped with their
        # trajectories, so this run computes them again; every other row stays final.
        retried = {row_id(row.key()) for row in rows if retry_errors and is_retryable(row)}
        self.rows = [row for row in rows if row_id(row.key()) not in retried]
        # A flush renames trajectories.parquet before results.parquet: a crash or a full disk between
        # the two leaves trajectories of episodes without a result row. Those episodes run again, so
        # only the trajectories of kept rows stay, one per row id (the last written).
        kept_ids = {row_id(row.key()) for row in self.rows}
        by_id = {t.get("row_id"): t for t in trajectories if t.get("row_id") in kept_ids}
        self.trajectories = list(by_id.values())
        self.dropped_trajectories = len(trajectories) - len(self.trajectories)
        self.retried = len(retried)
        self.keys = {row.key() for row in self.rows}
        self.flush_every_s = flush_every_s
        self._dirty = bool(retried) or self.dropped_trajectories > 0
        self.saved_rows = len(self.rows)  # rows results.parquet holds now
        self._flushes = 0
        self._last_flush = time.monotonic()

    def _read_trajectories(self) -> list[dict[str, Any]]:
        path = self.dir / TRAJECTORIES_FILE
        return read_parquet(path).to_pylist() if path.exists() else []  # a damaged file: named

    def add(self, row: ResultRow, trajectory: dict[str, Any]) -> None:
        if row.key() in self.keys:
            raise RuntimeError(f"result {row.key()} is already in {self.dir / RESULTS_FILE}")
        self.keys.add(row.key())
        self.rows.append(row)
        self.trajectories.append(trajectory)
        self._dirty = True
        if time.monotonic() - self._last_flush >= self.flush_every_s:
            self.flush()

    def flush(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self._dirty:
            return
        self._flushes += 1
        for name, records, schema, point in (
                (TRAJECTORIES_FILE, self.trajectories, trajectory_schema(), "eval_trajectories_written"),
                (RESULTS_FILE, [row_to_record(r) for r in self.rows], results_schema(), "eval_results_written")):
            table = pa.Table.from_pylist(records, schema=schema)
            replace_atomic(self.dir / name, lambda tmp, table=table: pq.write_table(table, tmp))
            fault_point(point, self._flushes)
        self.saved_rows = len(self.rows)
        self._dirty = False
        self._last_flush = time.monotonic()


@dataclass
class EvalOptions:
    condition: str = "agent"
    seeds: tuple[int, ...] = (0,)
    settings: ConditionSettings = field(default_factory=ConditionSettings)
    concurrency: int = 8
    use_ray: bool = True
    num_env_actors: int = 2
    slots_per_env_actor: int = 8
    domain_modules: dict[str, str] | None = None
    env_vars: dict[str, str] | None = None
    max_episode_attempts: int = 3
    progress: bool = True
    flush_every_s: float = 2.0
    retry_errors: bool = False  # re-run episodes that ended with end_reason "endpoint_error"
    # An already started `EnvPool` to run on (kept open afterwards: several evaluations, or a
    # benchmark that excludes actor start-up); None creates one per run when use_ray.
    env_pool: Any = None


def make_row(policy_id: str, item: EvalItem, task, condition: str, seed: int, outcome: EpisodeOutcome,
             latency_s: float) -> tuple[ResultRow, dict[str, Any]]:
    key = (policy_id, item.benchmark, item.task_id, condition, seed)
    rid = row_id(key)
    row = ResultRow(
        policy_id=policy_id, benchmark=item.benchmark, domain=item.domain, task_id=item.task_id,
        task_type=task_type_of(task), condition=condition, seed=seed, end_reason=outcome.end_reason,
        error_kind=outcome.error_kind, answer=outcome.answer, gold=task.correct_answer, options=task.options,
        correct=outcome.correct, reward=outcome.reward, reward_components=outcome.reward_components,
        safety_violations=outcome.safety_violations, turns=outcome.turns, tool_calls=outcome.tool_calls,
        error_kinds=outcome.error_kinds, prompt_tokens=outcome.prompt_tokens,
        completion_tokens=outcome.completion_tokens, cost_usd=outcome.cost_usd, latency_s=max(latency_s, 0.0),
        trajectory_ref=f"{TRAJECTORIES_FILE}#{rid}", extra=outcome.extra,
    )
    trajectory = {"row_id": rid, "policy_id": policy_id, "benchmark": item.benchmark, "task_id": item.task_id,
                  "condition": condition, "seed": seed,
                  "messages": json.dumps(outcome.messages, ensure_ascii=False, default=str)}
    return row, trajectory


class _EnvSource:
    """Env handles for episodes: leased from a Ray `EnvPool`, or a fresh in-process `LocalEnv`."""

    def __init__(self, options: EvalOptions) -> None:
        self.options = options
        self.pool = options.env_pool
        self._owns_pool = False
        self._idle: list = []
        if options.use_ray and self.pool is None:
            self._owns_pool = True
            from actors.env_actor import EnvPool

            self.pool = EnvPool(options.num_env_actors, options.slots_per_env_actor, options.settings.max_turns,
                                env_kwargs=options.settings.env_kwargs(), domain_modules=options.domain_modules,
                                env_vars=options.env_vars)

    async def run(self, runner: Callable, item: EvalItem, seed: int):
        """Run `runner(env)`; with Ray, re-run from its start when the env actor is lost."""
        from actors.agent_loop import LocalEnv
        from actors.env_actor import EnvActorLost

        if not self.options.use_ray:
            # One LocalEnv per episode in flight, reused afterwards (it caches its envs per domain).
            env = self._idle.pop() if self._idle else LocalEnv(self.options.settings.max_turns,
                                                                  self.options.settings.env_kwargs())
            try:
                return await runner(env)
            finally:
                self._idle.append(env)
        from evals.conditions import episode_spec

        spec = episode_spec(item.task_id, item.domain, item.split, seed)
        last: Exception | None = None
        for _ in range(self.options.max_episode_attempts):
            env = await self.pool.lease(spec)
            try:
                outcome = await runner(env)
            except EnvActorLost as exc:
                await self.pool.give_back(env, lost=True)
                last = exc
                continue
            except BaseException:
                await self.pool.give_back(env)
                raise
            await self.pool.give_back(env)
            return outcome
        raise EnvActorLost(f"episode {item.task_id} seed {seed}: env actor lost "
                           f"{self.options.max_episode_attempts} times; last: {last}")

    def close(self) -> None:
        if self.pool is not None and self._owns_pool:
            import ray

            for actor in self.pool.actors:
                ray.kill(actor)


def pending_episodes(policy_id: str, items: list[EvalItem], output_dir: str | os.PathLike, condition: str,
                     seeds, *, retry_errors: bool = False) -> int:
    """How many (item, seed) episodes the folder lacks (the CLI starts no Ray cluster for none)."""
    done = {row.key() for row in read_results(Path(output_dir)) if not (retry_errors and is_retryable(row))}
    tasks = load_tasks_for(items) if condition == "logprob" else None
    count = 0
    for item in items:
        if tasks is not None and not is_multiple_choice(tasks[(item.domain, item.split)][item.task_id]):
            continue
        count += sum((policy_id, item.benchmark, item.task_id, condition, seed) not in done for seed in seeds)
    return count


async def run_episodes(policy, items: list[EvalItem], output_dir: str | os.PathLike,
                       options: EvalOptions) -> dict[str, Any]:
    """Run every (item, seed) not yet in `output_dir`; returns counts and timing."""
    if options.condition not in CONDITIONS:
        raise ValueError(f"--condition {options.condition!r}: choose one of {', '.join(CONDITIONS)}")
    if options.domain_modules:
        from actors.env_actor import register_domains

        register_domains(options.domain_modules)
    store = ResultsStore(Path(output_dir), options.flush_every_s, retry_errors=options.retry_errors)
    tasks = load_tasks_for(items)
    policy_id = policy.policy_id
    skipped_not_mc = 0
    todo: list[tuple[EvalItem, int]] = []
    for item in items:
        task = tasks[(item.domain, item.split)][item.task_id]
        if options.condition == "logprob" and not is_multiple_choice(task):
            skipped_not_mc += 1
            continue
        for seed in options.seeds:
            if (policy_id, item.benchmark, item.task_id, options.condition, seed) not in store.keys:
                todo.append((item, seed))
    total = len(todo) + sum(1 for r in store.rows if r.policy_id == policy_id and r.condition == options.condition)
    from evals.policies import ScriptedPolicy, majority_letters

    if isinstance(policy, ScriptedPolicy) and policy.kind == "majority":

        by_benchmark: dict[str, list] = {}
        for item in items:
            by_benchmark.setdefault(item.benchmark, []).append(tasks[(item.domain, item.split)][item.task_id])
        policy.majority = majority_letters(by_benchmark)

    runner = CONDITION_RUNNERS[options.condition]
    semaphore = asyncio.Semaphore(max(1, options.concurrency))
    source = _EnvSource(options) if todo else None
    bar = None
    if options.progress:
        from tqdm import tqdm

        bar = tqdm(total=total, initial=total - len(todo), desc=f"eval {options.condition}", unit="ep",
                   dynamic_ncols=True)
    started = time.perf_counter()

    async def one(item: EvalItem, seed: int) -> None:
        task = tasks[(item.domain, item.split)][item.task_id]
        episode_policy = policy
        if hasattr(policy, "for_episode"):
            episode_policy = policy.for_episode(task, seed, item.benchmark, options.settings.max_turns)
        async with semaphore:
            t0 = time.perf_counter()
            outcome = await source.run(
                lambda env: runner(episode_policy, env, task, item.domain, item.split, seed, options.settings),
                item, seed)
            latency = time.perf_counter() - t0
        row, trajectory = make_row(policy_id, item, task, options.condition, seed, outcome, latency)
        store.add(row, trajectory)
        if bar is not None:
            bar.update(1)

    try:
        await asyncio.gather(*[one(item, seed) for item, seed in todo])
    finally:
        if bar is not None:
            bar.close()  # first: an error below is printed on its own line, not after the bar
        try:
            store.flush()  # what finished is kept, even on an interruption or an error
        except DiskFullError as exc:
            raise exc.with_hint(
                f"{output_dir} keeps the {store.saved_rows} results written before the disk filled (this run "
                f"finished {len(store.rows) - store.saved_rows} more that are not saved); free space and run the "
                f"same command again: it skips the saved results and runs the rest") from None
        finally:
            if source is not None:
                source.close()
    elapsed = time.perf_counter() - started
    return {"episodes_run": len(todo), "episodes_skipped_done": total - len(todo),
            "skipped_not_multiple_choice": skipped_not_mc, "seconds": elapsed,
            "episodes_per_s": (len(todo) / elapsed) if todo and elapsed > 0 else 0.0}


def write_spec(output_dir: Path, spec: EvalSpec) -> None:
    """Write eval.json; a folder produced by a different evaluation is refused (naming the field)."""
    path = output_dir / SPEC_FILE
    if path.exists():
        old = json.loads(path.read_text())
        for name in ("policy_id", "suite", "condition", "max_turns", "max_tokens"):
            if old.get(name) != getattr(spec, name):
                raise ValueError(f"{path}: this folder holds an evaluation with {name}={old.get(name)!r}, not "
                                 f"{getattr(spec, name)!r}; use another --output")
        spec = spec.model_copy(update={"seeds": sorted(set(old.get("seeds", [])) | set(spec.seeds)),
                                       "created_at": old.get("created_at")})
    write_text_atomic(path, json.dumps(spec.model_dump(), indent=1))


def package_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("healthcare-ai-gym", "torch", "transformers", "ray", "vllm"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def run_eval(policy, items: list[EvalItem], output_dir: str | os.PathLike, options: EvalOptions, *,
             policy_text: str | None = None, suite: str = "custom", limit: int | None = None,
             policy_source: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write eval.json, run the missing episodes, return the run's counts (see `run_episodes`)."""
    from datetime import datetime, timezone

    out = Path(output_dir)
    spec = EvalSpec(policy=policy_text or policy.policy_id, policy_id=policy.policy_id, suite=suite,
                    condition=options.condition, seeds=list(options.seeds), limit=limit,
                    max_turns=options.settings.max_turns, max_tokens=options.settings.max_tokens,
                    versions=package_versions(), policy_source=dict(policy_source or {}), created_at=datetime.now(timezone.utc).isoformat(timespec="seconds"))
    write_spec(out, spec)
    return asyncio.run(run_episodes(policy, items, out, options))
