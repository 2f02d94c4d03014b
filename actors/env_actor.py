"""Environment actors: a pool of Ray actors, each hosting several environments.

`EnvActor` executes an episode's `reset` / `step` calls on a `HealthcareGymEnv` it keeps per
episode; `EnvPool` schedules episodes over the actors (least-loaded actor with a free slot) and
hands the agent loop a `RemoteEnv` handle. Tokenization and generation stay outside: the actor
only runs tools and scores episodes.

Fault model. The actors are created with `max_restarts`, so Ray restarts one that dies. A restart
loses its environments, so every episode that was in flight on it is lost: its next call fails
with `RayActorError` (in flight at the crash) or finds its episode unknown (sent after the
restart). `RemoteEnv` turns both into `EnvActorLost`; `run_episode` then re-runs the episode from
its start with the same `EpisodeSpec` (same seed), on whichever actor has room. `EpisodeLedger`
accounts for every episode: each one completes exactly once, and every lost attempt is recorded,
so a test can check that nothing was lost or counted twice.

Hostile actions and env failures. `env.step` never raises on any action; should an env
method raise anyway (a bug in a domain's toolkit or scorer), `EnvActor.step` / `finish` end that
episode as truncated with reward 0 and an `EpisodeEnd` (reason "env_error") naming the failure, instead of raising
into the agent loop, which would fail the episode's whole group. The actor keeps serving (a Python
exception never kills it) and does not reuse that episode's env.

Batched calls. By default (`EnvPool(batch_calls=True)`) an episode's calls do not each cost an
actor round trip: `RemoteEnv` hands them to the pool's `_ActorBatcher` for its actor, which sends
every call queued for that actor in one `EnvActor.batch` call (calls queued in the same
event-loop tick always travel together, so `asyncio.gather` over many episodes coalesces at no added
latency; at most `max_batches_in_flight` batches per actor are outstanding, and calls arriving
meanwhile wait for the next one). The actor runs the calls in order, returns the answers of the
whole batch at once (or, with `stream_after_s`, streams them back in chunks as they finish through
`EnvActor.batch_stream`) and answers each call separately: every call's arguments and result are pickled on their own, so
an exception, a bad argument or an unpicklable result fails only that call's episode, never the
batch. A batch lost with its actor fails each of its unanswered calls with `EnvActorLost`, as
single calls would. Figures: docs/benchmarks.md, "Batched env actors".
"""

from __future__ import annotations

import asyncio
import json
import os
import pickle
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

from actors.agent_loop import AgentLoop, EpisodeSpec, GenerateFn, finish_episode, make_env
from envs.episode import EpisodeEnd
from actors.types import RolloutSample


def register_domains(domain_modules: dict[str, str] | None) -> None:
    """Register extra domain modules (name -> module path) in this process's registry."""
    from envs import registry

    for name, module in (domain_modules or {}).items():
        if registry.DOMAINS.get(name, module) != module:
            raise ValueError(f"domain {name!r} is already registered as {registry.DOMAINS[name]!r}, not {module!r}")
        registry.DOMAINS[name] = module


class EpisodeNotFoundError(KeyError):
    """The actor does not know the episode (it was restarted since the episode's reset)."""


class EnvActorLost(RuntimeError):
    """The env actor running an episode died or restarted; the episode must be re-run."""


class EnvActor:
    """Hosts up to `slots` environments (one per in-flight episode), reusing idle ones.

    Args:
        actor_index: Position in the pool (for error messages and accounting).
        max_turns: Assistant turns per episode (the env truncates after them).
        slots: In-flight episodes this actor accepts.
        env_kwargs: Extra `HealthcareGymEnv` arguments (e.g. `reward_weights`).
    """

    def __init__(self, actor_index: int, max_turns: int, slots: int = 4,
                 env_kwargs: dict[str, Any] | None = None, domain_modules: dict[str, str] | None = None) -> None:
        register_domains(domain_modules)

        self.actor_index = actor_index
        self.max_turns = max_turns
        self.slots = slots
        self.env_kwargs = dict(env_kwargs or {})
        self.incarnation = uuid.uuid4().hex[:8]  # changes on every (re)start
        self._active: dict[str, Any] = {}
        self._idle: dict[tuple[str, str | None], list[Any]] = {}
        self.episodes_started = 0
        self.env_errors = 0  # episodes ended because their env raised (see `step`)
        self.batches = 0  # `batch` calls served, and the calls they carried
        self.batched_calls = 0
        self._broken: set[str] = set()

    def ping(self) -> dict[str, Any]:
        return {"actor_index": self.actor_index, "pid": os.getpid(), "incarnation": self.incarnation,
                "active": len(self._active), "episodes_started": self.episodes_started,
                "env_errors": self.env_errors, "batches": self.batches, "batched_calls": self.batched_calls,
                # the actor process's CPU time (all threads): what a benchmark divides by to see
                # whether a pool's actors were busy or waiting on the driver
                "cpu_s": time.process_time()}

    def _env_for(self, domain: str, split: str | None):
        idle = self._idle.setdefault((domain, split), [])
        if idle:
            return idle.pop()
        return make_env(domain, split, self.max_turns, self.env_kwargs)

    def reset(self, key: str, spec: dict[str, Any]) -> tuple[str, dict[str, Any]]:
        spec = EpisodeSpec.model_validate(spec)
        if key in self._active:
            raise ValueError(f"env actor {self.actor_index}: episode key {key!r} is already active")
        if len(self._active) >= self.slots:
            raise RuntimeError(f"env actor {self.actor_index}: all {self.slots} slots are busy")
        env = self._env_for(spec.domain, spec.split)
        obs, info = env.reset(seed=spec.seed, options={"task_id": spec.task_id})
        self._active[key] = (env, (spec.domain, spec.split))
        self.episodes_started += 1
        return obs, info

    def _env(self, key: str):
        try:
            return self._active[key][0]
        except KeyError:
            raise EpisodeNotFoundError(
                f"env actor {self.actor_index} (incarnation {self.incarnation}) has no episode {key!r}: "
                f"it was restarted after the episode began"
            ) from None

    def step(self, key: str, action: str) -> tuple[str, float, bool, bool, dict[str, Any]]:
        """`env.step` for one episode. Never raises for a hostile action or a failing env method:
        `env.step` itself never raises on any action; an exception from the env anyway (a bug in a
        domain's toolkit or scorer) ends that episode here, unscored (reward 0, an `EpisodeEnd` with
        reason "env_error" naming the failure), so the rest of the batch and this actor carry on."""
        env = self._env(key)
        try:
            obs, reward, terminated, truncated, info = env.step(action)
            info = {k: v for k, v in info.items() if k not in ("trajectory", "reward_breakdown")}
        except Exception as exc:
            return self._failed(key, env, "step", exc)
        return obs, float(reward), bool(terminated), bool(truncated), info

    def finish(self, key: str, reason: str) -> EpisodeEnd:
        """Score an episode the agent loop stopped (idempotent: an episode already over returns its
        end); a failure is returned as an `env_error` end, not raised."""
        env = self._env(key)
        try:
            return finish_episode(env, reason)
        except Exception as exc:
            return self._failed(key, env, "finish", exc)[4]["end"]

    def _failed(self, key: str, env: Any, method: str, exc: Exception) -> tuple[str, float, bool, bool, dict[str, Any]]:
        """The episode's end after its env raised: truncated, reward 0, the failure named in
        `info["env_error"]` and `info["end"].env_error`. The env is not reused (its state is unknown)."""
        record = getattr(env, "_record", None)
        where = f"{getattr(env, 'domain_name', '?')}/{getattr(record, 'task_id', '?')}"
        error = (f"env actor {self.actor_index}: {method} of episode {key!r} ({where}) failed: "
                 f"{type(exc).__name__}: {str(exc)[:500]}")
        self.env_errors += 1
        self._broken.add(key)
        observation = json.dumps({"error": "the environment failed on this action; the episode ends here"})
        info = {"env_error": error, "end": EpisodeEnd.failed(error), "tool_calls": [], "parse_errors": [],
                "tool_errors": []}
        return observation, 0.0, False, True, info

    def release(self, key: str) -> None:
        entry = self._active.pop(key, None)
        if entry is not None and key not in self._broken:
            env, where = entry
            self._idle.setdefault(where, []).append(env)
        self._broken.discard(key)

    def batch(self, calls: list[bytes]) -> list[tuple[bool, bytes]]:
        """Run several episodes' calls in one actor call, in order; answer each one on its own.

        Each call is `pickle.dumps((method, key, args))` with `method` one of `BATCHED_METHODS`;
        each answer is `(True, pickle.dumps(result))` or `(False, pickle.dumps(exception))`.
        Pickling per call is what keeps episodes isolated: a call whose payload does not unpickle,
        names an unknown method, raises (an unknown episode, busy slots, a bad spec), or returns
        something unpicklable fails alone, and the calls after it still run.
        """
        self.batches += 1
        self.batched_calls += len(calls)
        return [self._run_batched(payload) for payload in calls]

    def batch_stream(self, calls: list[bytes], flush_after_s: float = 0.002):
        """`batch`, streamed: yields `(first_index, answers)` chunks as the calls finish, a chunk
        whenever `flush_after_s` of work has passed since the last one (and one at the end), so the
        driver can carry on with the episodes already answered while slow calls (a search-heavy
        step) still run, and cheap calls still travel back together."""
        self.batches += 1
        self.batched_calls += len(calls)
        start, chunk, last = 0, [], time.perf_counter()
        for index, payload in enumerate(calls):
            chunk.append(self._run_batched(payload))
            now = time.perf_counter()
            if now - last >= flush_after_s and index + 1 < len(calls):
                yield start, chunk
                start, chunk, last = index + 1, [], time.perf_counter()
        yield start, chunk

    def _run_batched(self, payload: bytes) -> tuple[bool, bytes]:
        try:
            method, key, args = pickle.loads(payload)
            if method not in BATCHED_METHODS:
                raise ValueError(f"env actor {self.actor_index}: batched call to {method!r}; "
                                 f"expected one of {sorted(BATCHED_METHODS)}")
            return True, pickle.dumps(getattr(self, method)(key, *args), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            return False, _pickled_exception(exc, f"env actor {self.actor_index}")


#: What `EnvActor.batch` may call (never `batch` itself or `ping`).
BATCHED_METHODS = frozenset({"reset", "step", "finish", "release"})


def _pickled_exception(exc: Exception, where: str) -> bytes:
    """`exc` pickled, or a RuntimeError carrying its type and message if it does not pickle."""
    try:
        data = pickle.dumps(exc, protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(data)  # some exceptions pickle but cannot be rebuilt (required __init__ args)
        return data
    except Exception:
        return pickle.dumps(RuntimeError(f"{where}: {type(exc).__name__}: {str(exc)[:500]}"))


def _is_actor_failure(exc: BaseException) -> bool:
    from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError

    return isinstance(exc, (RayActorError, ActorDiedError, ActorUnavailableError, EpisodeNotFoundError))


class _ActorBatcher:
    """Coalesces the calls of all episodes waiting on one env actor into `EnvActor.batch` calls.

    A call is queued and a send is scheduled for the end of the current event-loop tick, so every
    call made in the same tick (e.g. the resets of an `asyncio.gather` of episodes) travels in one
    batch without any timer. At most `max_in_flight` batches are outstanding per actor: while they
    run, new calls queue and leave together when one returns, so the batch size follows the load
    (one call when the actor is idle, many when it is busy). With two in flight the actor works on
    one batch while the driver consumes the previous one's results. Batches are submitted in
    queue order and a Ray actor runs one caller's calls in submission order, so an episode's calls
    (and a release before the next reset of its slot) keep their order.
    """

    def __init__(self, actor: Any, actor_index: int, max_batch: int, max_in_flight: int,
                 stream_after_s: float | None = None) -> None:
        self.actor = actor
        self.actor_index = actor_index
        self.max_batch = max_batch
        self.max_in_flight = max_in_flight
        self.stream_after_s = stream_after_s
        self.loop = asyncio.get_running_loop()
        self._queue: list[tuple[bytes, asyncio.Future]] = []
        self._in_flight = 0
        self._scheduled = False

    def submit(self, method: str, key: str, args: tuple) -> asyncio.Future:
        """Queue one call; its future resolves with the call's result or raises its exception.

        Raises:
            TypeError: the arguments cannot be pickled (raised here, for this episode only).
        """
        try:
            payload = pickle.dumps((method, key, args), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            raise TypeError(f"env actor {self.actor_index}: the arguments of {method} for episode {key!r} "
                            f"cannot be sent ({type(exc).__name__}: {exc})") from exc
        future = self.loop.create_future()
        self._queue.append((payload, future))
        if not self._scheduled:
            self._scheduled = True
            self.loop.call_soon(self._pump)
        return future

    def _pump(self) -> None:
        self._scheduled = False
        while self._queue and self._in_flight < self.max_in_flight:
            batch, self._queue = self._queue[:self.max_batch], self._queue[self.max_batch:]
            self._in_flight += 1
            payloads = [payload for payload, _ in batch]
            try:
                if self.stream_after_s is None:
                    ref = self.actor.batch.remote(payloads)
                else:
                    ref = self.actor.batch_stream.remote(payloads, self.stream_after_s)
            except Exception as exc:  # submission itself failed: fail this batch's calls only
                self._in_flight -= 1
                self._settle(batch, None, exc)
                continue
            asyncio.ensure_future(self._collect(ref, batch, self.stream_after_s is not None))

    def retire(self) -> None:
        """Send every queued call now, whatever is in flight: a batcher being replaced (the pool's
        mode changed, or a new event loop) must not strand calls, releases above all (a release
        never sent keeps its slot busy in the actor). They are submitted before any call of the
        batcher that replaces this one, so the actor still runs them first."""
        queue, self._queue = self._queue, []
        if not queue:
            return
        try:
            ref = self.actor.batch.remote([payload for payload, _ in queue])
        except Exception as exc:
            self._settle(queue, None, exc)
            return
        if self.loop is _running_loop():  # else their episodes' loop has ended: nobody awaits them
            self._in_flight += 1
            asyncio.ensure_future(self._collect(ref, queue, False))

    async def _collect(self, ref: Any, batch: list[tuple[bytes, asyncio.Future]], streamed: bool) -> None:
        settled = 0
        try:
            if not streamed:
                self._settle(batch, await ref, None)
            else:
                async for chunk_ref in ref:  # chunks in order, as the actor finishes them
                    start, answers = await chunk_ref
                    self._settle(batch[start:start + len(answers)], answers, None)
                    settled = start + len(answers)
        except Exception as exc:  # the actor died (or the call failed as a whole): the calls not yet
            self._settle(batch[settled:], None, exc)  # answered fail, each with the same error
        except asyncio.CancelledError:
            # The loop is shutting down (asyncio.run cancels what is left, e.g. the last releases):
            # start no new batch from here, it would be a task the loop never runs. What is still
            # queued is sent by `retire` when the pool is next used.
            self._in_flight -= 1
            for _, future in batch[settled:]:
                future.cancel()
            raise
        self._in_flight -= 1
        self._pump()

    @staticmethod
    def _settle(batch: list[tuple[bytes, asyncio.Future]], answers: list[tuple[bool, bytes]] | None,
                error: BaseException | None) -> None:
        for index, (_, future) in enumerate(batch):
            if future.done():  # its episode was cancelled meanwhile
                continue
            if error is not None:
                future.set_exception(error)
                continue
            ok, data = answers[index]
            try:
                value = pickle.loads(data)
            except Exception as exc:
                future.set_exception(RuntimeError(f"an env actor answer did not unpickle: {type(exc).__name__}: {exc}"))
                continue
            if ok:
                future.set_result(value)
            else:
                future.set_exception(value)


class RemoteEnv:
    """The agent loop's `EnvHandle` for one episode on one `EnvActor` (calls batched by the pool's
    `_ActorBatcher` for that actor, or one actor call each with `EnvPool(batch_calls=False)`)."""

    def __init__(self, pool: "EnvPool", actor_index: int, key: str) -> None:
        self.pool = pool
        self.actor_index = actor_index
        self.key = key
        self.actor = pool.actors[actor_index]
        self.batcher = pool.batcher(actor_index)

    async def _call(self, method: str, *args):
        try:
            if self.batcher is not None:
                return await self.batcher.submit(method, self.key, args)
            return await getattr(self.actor, method).remote(self.key, *args)
        except Exception as exc:
            if _is_actor_failure(exc):
                raise EnvActorLost(f"env actor {self.actor_index} lost episode {self.key!r} during {method}: "
                                   f"{type(exc).__name__}") from exc
            raise

    async def reset(self, spec: EpisodeSpec):
        return await self._call("reset", spec.model_dump())

    async def step(self, action: str):
        return await self._call("step", action)

    async def finish(self, reason: str):
        return await self._call("finish", reason)

    async def close(self) -> None:
        if self.batcher is not None:
            # Not awaited: the release travels with the actor's next batch, ahead of any later
            # reset on this slot (calls keep their order), and a dead actor has nothing to release.
            self.batcher.submit("release", self.key, ()).add_done_callback(_ignore_result)
            return
        try:
            await self.actor.release.remote(self.key)
        except Exception as exc:  # a dead actor has nothing to release
            if not _is_actor_failure(exc):
                raise


def _ignore_result(future: asyncio.Future) -> None:
    if not future.cancelled():
        future.exception()  # retrieved, so asyncio does not log it as never retrieved


class EnvPool:
    """Creates the env actors and schedules episodes over them.

    Args:
        num_actors: Env actors.
        slots_per_actor: Episodes in flight per actor.
        max_turns: Passed to every environment.
        env_kwargs: Extra environment arguments.
        domain_modules: Extra domains to register in every actor (name -> module path).
        max_restarts: Ray restarts per actor (-1 = unlimited).
        num_cpus: CPU reservation per actor (fractional is fine: tools are light).
        resources: Custom Ray resources per actor (e.g. {"env_node": 1}), to place the actors on
            the nodes that have them; a restarted actor goes to any node that has them too.
        kb_service: Name of a running knowledge-base service (kb_service.service) the actors' knowledge
            tools share, instead of each opening the KB.
        env_vars: Environment variables of the actor processes.
        batch_calls: Send the calls of all episodes waiting on an actor together (`_ActorBatcher`);
            False sends each reset / step / finish / release as its own actor call.
        max_batch: Most calls in one batch.
        max_batches_in_flight: Batches outstanding per actor (2: the actor runs one while the
            driver consumes the other's results).
        stream_after_s: Stream each batch's answers back in chunks, one whenever this much actor
            time has passed since the last (`EnvActor.batch_stream`), so slow calls do not hold back
            the episodes already answered; None (the default) returns each batch's answers at once
            (`EnvActor.batch`). Measured (docs/benchmarks.md, "Batched env actors"): answers at once
            were faster in 8 of 10 same-run comparisons, streaming (2 ms) only with 2 actors on
            heavy steps; a Ray streaming generator costs ~0.35 ms a chunk.
    """

    def __init__(self, num_actors: int, slots_per_actor: int, max_turns: int,
                 env_kwargs: dict[str, Any] | None = None, domain_modules: dict[str, str] | None = None,
                 max_restarts: int = -1, num_cpus: float = 0.0, kb_service: str | None = None,
                 env_vars: dict[str, str] | None = None, batch_calls: bool = True, max_batch: int = 64,
                 max_batches_in_flight: int = 2, stream_after_s: float | None = None,
                 resources: dict[str, float] | None = None) -> None:
        import ray

        if num_actors < 1 or slots_per_actor < 1:
            raise ValueError(f"env pool needs num_actors >= 1 and slots_per_actor >= 1, got "
                             f"{num_actors} and {slots_per_actor}")
        if max_batch < 1 or max_batches_in_flight < 1:
            raise ValueError(f"env pool needs max_batch >= 1 and max_batches_in_flight >= 1, got "
                             f"{max_batch} and {max_batches_in_flight}")
        self.batch_calls = batch_calls
        self.max_batch = max_batch
        self.max_batches_in_flight = max_batches_in_flight
        if stream_after_s is not None and stream_after_s < 0:
            raise ValueError(f"env pool needs stream_after_s >= 0 or None, got {stream_after_s}")
        self.stream_after_s = stream_after_s
        self._batchers: dict[int, _ActorBatcher] = {}
        options: dict[str, Any] = {"max_restarts": max_restarts, "max_task_retries": 0, "num_cpus": num_cpus}
        if resources:
            options["resources"] = dict(resources)
        variables = dict(env_vars or {})
        if kb_service:
            variables["HCGYM_KB_SERVICE"] = kb_service
        if variables:
            options["runtime_env"] = {"env_vars": variables}
        cls = ray.remote(EnvActor).options(**options)
        self.actors = [cls.remote(i, max_turns, slots_per_actor, env_kwargs, domain_modules) for i in range(num_actors)]
        self.slots = slots_per_actor
        self.in_flight: list[set[str]] = [set() for _ in range(num_actors)]
        self.lost: list[int] = [0] * num_actors
        # An actor that lost an episode is left out of scheduling until it answers a ping again
        # (Ray is restarting it; calls sent meanwhile would fail too).
        self.healthy: list[bool] = [True] * num_actors
        self._probes: dict[int, asyncio.Task] = {}
        self._free = asyncio.Condition() if _has_loop() else None

    async def ready(self, timeout_s: float = 300.0) -> list[dict[str, Any]]:
        """Ping every actor, waiting for restarting ones; returns their `ping` answers."""

        async def ping(actor):
            deadline = asyncio.get_running_loop().time() + timeout_s
            while True:
                try:
                    return await actor.ping.remote()
                except Exception as exc:
                    if not _is_actor_failure(exc) or asyncio.get_running_loop().time() > deadline:
                        raise
                    await asyncio.sleep(0.2)

        return list(await asyncio.gather(*[ping(a) for a in self.actors]))

    async def lease(self, spec: EpisodeSpec) -> RemoteEnv:
        """Wait for a free slot on the least-loaded actor and reserve it for the episode."""
        if self._free is None:
            self._free = asyncio.Condition()
        async with self._free:
            while True:
                loads = [(len(s), i) for i, s in enumerate(self.in_flight)
                         if len(s) < self.slots and self.healthy[i]]
                if loads:
                    _, index = min(loads)
                    break
                try:
                    await self._free.wait()
                except asyncio.CancelledError:  # pass on a wake-up this waiter may have consumed
                    self._free.notify(1)
                    raise
            key = f"{spec.sample_id}#{uuid.uuid4().hex[:6]}"  # unique per attempt
            self.in_flight[index].add(key)
            if len(loads) > 1 or loads[0][0] + 1 < self.slots:  # room left: wake the next waiter
                self._free.notify(1)
        return RemoteEnv(self, index, key)

    async def give_back(self, env: RemoteEnv, lost: bool = False) -> None:
        if lost:
            self.lost[env.actor_index] += 1
            self._mark_down(env.actor_index)
        else:
            await env.close()
        async with self._free:
            self.in_flight[env.actor_index].discard(env.key)
            # One slot freed: wake one waiter (each lease wakes the next while room is left).
            # notify_all here woke every waiting episode per finished one (quadratic in the queue).
            self._free.notify(1)

    def _mark_down(self, index: int) -> None:
        self.healthy[index] = False
        if index not in self._probes or self._probes[index].done():
            self._probes[index] = asyncio.ensure_future(self._probe(index))

    async def _probe(self, index: int, interval_s: float = 0.2, timeout_s: float = 600.0) -> None:
        """Wait until the (restarted) actor answers, then schedule on it again."""
        deadline = asyncio.get_running_loop().time() + timeout_s
        while asyncio.get_running_loop().time() < deadline:
            try:
                await self.actors[index].ping.remote()
                break
            except Exception as exc:
                if not _is_actor_failure(exc):
                    raise
                await asyncio.sleep(interval_s)
        else:
            return  # stays out of scheduling; the other actors carry on
        async with self._free:
            self.healthy[index] = True
            self._free.notify_all()

    def loads(self) -> list[int]:
        return [len(s) for s in self.in_flight]

    def batcher(self, index: int) -> _ActorBatcher | None:
        """The call batcher of actor `index` in the running event loop (None without batching).
        A pool used from a new event loop (another `asyncio.run`) gets new batchers."""
        if not self.batch_calls:
            while self._batchers:  # batching was switched off: send what the batchers still hold
                self._batchers.popitem()[1].retire()
            return None
        batcher = self._batchers.get(index)
        if (batcher is None or batcher.loop is not asyncio.get_running_loop()
                or batcher.stream_after_s != self.stream_after_s):
            if batcher is not None:
                batcher.retire()
            batcher = self._batchers[index] = _ActorBatcher(self.actors[index], index, self.max_batch,
                                                            self.max_batches_in_flight, self.stream_after_s)
        return batcher


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


def _has_loop() -> bool:
    try:
        asyncio.get_running_loop()
        return True
    except RuntimeError:
        return False


@dataclass
class EpisodeLedger:
    """Accounting for episodes: admitted once, completed once, every lost attempt recorded."""

    admitted: dict[str, int] = field(default_factory=dict)   # sample id -> attempts so far
    completed: set[str] = field(default_factory=set)
    lost_attempts: list[tuple[str, str]] = field(default_factory=list)  # (sample id, where)
    failed: dict[str, str] = field(default_factory=dict)     # gave up (attempts exhausted / bad task)

    def admit(self, sample_id: str) -> None:
        if sample_id in self.admitted:
            raise ValueError(f"episode {sample_id!r} admitted twice")
        self.admitted[sample_id] = 0

    def attempt(self, sample_id: str) -> int:
        self.admitted[sample_id] += 1
        return self.admitted[sample_id]

    def lose(self, sample_id: str, where: str) -> None:
        self.lost_attempts.append((sample_id, where))

    def complete(self, sample_id: str) -> None:
        if sample_id in self.completed:
            raise RuntimeError(f"episode {sample_id!r} completed twice")
        if sample_id not in self.admitted:
            raise RuntimeError(f"episode {sample_id!r} completed but never admitted")
        self.completed.add(sample_id)

    def fail(self, sample_id: str, why: str) -> None:
        self.failed[sample_id] = why

    def balance(self) -> dict[str, int]:
        """admitted = completed + failed + in flight; reruns = lost attempts."""
        in_flight = len(self.admitted) - len(self.completed) - len(self.failed)
        return {"admitted": len(self.admitted), "completed": len(self.completed), "failed": len(self.failed),
                "in_flight": in_flight, "reruns": len(self.lost_attempts),
                "attempts": sum(self.admitted.values())}


async def run_episode(spec: EpisodeSpec, loop: AgentLoop, pool: EnvPool, generate: GenerateFn,
                      ledger: EpisodeLedger, max_attempts: int = 5) -> RolloutSample:
    """Run one admitted episode to completion, re-running it from its start (same spec, same seed)
    when its env actor is lost.

    Raises:
        EnvActorLost: after `max_attempts` lost attempts (recorded as failed in the ledger).
        Exception: any other error of the episode (recorded as failed in the ledger).
    """
    last: Exception | None = None
    for _ in range(max_attempts):
        ledger.attempt(spec.sample_id)
        env = await pool.lease(spec)
        try:
            sample = await loop.run(spec, env, generate)
        except EnvActorLost as exc:
            ledger.lose(spec.sample_id, f"env actor {env.actor_index}")
            await pool.give_back(env, lost=True)
            last = exc
            continue
        except Exception as exc:
            # Not the env actor's fault (e.g. the generator stayed unreachable): the episode ends
            # here, so the ledger counts it failed rather than in flight for ever.
            ledger.fail(spec.sample_id, f"{type(exc).__name__}: {exc}")
            await pool.give_back(env)  # free the slot and its env
            raise
        except BaseException:  # cancelled (the run is stopping): neither completed nor failed
            await pool.give_back(env)
            raise
        await pool.give_back(env)
        sample.metadata["env_actor"] = env.actor_index
        sample.metadata["attempts"] = ledger.admitted[spec.sample_id]
        ledger.complete(spec.sample_id)
        return sample
    ledger.fail(spec.sample_id, f"lost {max_attempts} times: {last}")
    raise EnvActorLost(f"episode {spec.sample_id!r} lost {max_attempts} times; last: {last}")
