"""The `hf` generator backend: a transformers causal LM with our own sampling loop over the KV cache,
CPU or GPU. Each request carries its own seed and gets its own `torch.Generator`, so a request
re-run with the same seed and weights samples the same tokens whatever else is in the batch (up to
float noise from padding). Log-probs are those of `actors.generator.processed_logprobs`.
"""

from __future__ import annotations

import time
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from actors.generator import (GenerationRequest, GenerationResult, Generator, GeneratorBackend, SamplingConfig,
                              processed_logprobs)


class HFOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    device: str = "cpu"
    dtype: Literal["float32", "bfloat16", "float16"] = "float32"
    # Multi-turn episodes: keep each conversation's KV cache after a turn, so its next turn encodes
    # only the new tokens (the generated turn's last token and the tool result) instead of the whole
    # context again. Reused only with the same weights and an exactly matching token prefix.
    # Off by default: it holds up to `kv_cache_max_tokens` of keys/values per generator, a budget to
    # size for the model at hand. With finished rows leaving the batch it generates faster than
    # re-encoding on the tiny CPU model too (docs/benchmarks.md, "Generation").
    reuse_kv_cache: bool = False
    # Most cached tokens kept over all conversations (least recently used dropped first).
    kv_cache_max_tokens: int = Field(default=262_144, ge=0)
    # A batch runs until its longest row ends; without this, finished rows keep stepping (a decode
    # step costs about as much per finished row as per live one). On: once at least a quarter of
    # the batch's rows have finished, they leave it (their keys/values, mask, positions and sampling
    # state are dropped), so a batch of 32 re-packs at most 9 times. Same tokens either way (each
    # row samples from its own uniforms at its own step); off only to measure or compare
    # (docs/benchmarks.md, "Generation").
    compact_finished_rows: bool = True

    @field_validator("device")
    @classmethod
    def _device(cls, value: str) -> str:
        if not (value == "cpu" or value.startswith("cuda")):
            raise ValueError(f"device must be 'cpu' or 'cuda[:N]', got {value!r}")
        return value


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
        # decode_row_steps: rows fed to decode forwards; live_row_steps: of those, rows still
        # generating (the rest are finished rows stepping with a pad token); compactions: re-packs.
        self.cache_stats = {"reused_requests": 0, "reused_tokens": 0, "encoded_prompt_tokens": 0,
                            "decode_row_steps": 0, "live_row_steps": 0, "compactions": 0}

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

    def _store_prefixes(self, entries, past, mask) -> None:
        """Keep each row's keys and values of its real tokens (prompt and all but the last sampled
        token: the last one was never fed as a real token) for the conversation's next turn.
        `entries`: (batch row of `past`/`mask`, request, its sampled ids)."""
        layers = getattr(past, "layers", None)
        if not layers or any(type(layer).__name__ != "DynamicLayer" for layer in layers):
            return  # sliding-window or recurrent layers (Qwen3.5): their state is not a per-token cache
        cap = self.options.kv_cache_max_tokens
        for i, r, ids in entries:
            key = self.conversation_key(r)
            if key is None or not ids:
                continue
            cols = mask[i].nonzero().flatten()
            tokens = list(r.prompt_ids) + ids[:-1]
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

    @staticmethod
    def _can_drop_rows(past) -> bool:
        """Whether every layer of this cache keeps its state batch-first in tensors it re-binds on
        update, so `reorder_cache` with a shorter index list leaves a smaller, consistent cache:
        dynamic key/value layers and (Qwen3.5) linear-attention conv/recurrent states. Static
        layers are not: they are allocated once for a fixed batch (and may be captured by a
        compiled graph), so a batch on them keeps its finished rows."""
        from transformers.cache_utils import DynamicLayer, LinearAttentionLayer, StaticLayer

        layers = getattr(past, "layers", None)
        return bool(layers) and callable(getattr(past, "reorder_cache", None)) and all(
            isinstance(layer, (DynamicLayer, LinearAttentionLayer)) and not isinstance(layer, StaticLayer)
            for layer in layers)

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
        # whatever else shares the batch (or leaves it).
        uniforms = torch.stack([
            torch.rand(max_new, dtype=torch.float64,
                       generator=torch.Generator(device="cpu").manual_seed(int(r.seed) & 0x7FFF_FFFF_FFFF_FFFF))
            for r in requests])
        greedy = torch.tensor([r.greedy for r in requests])
        live = list(range(B))  # batch row -> request index; rows leave when compacted
        stats = self.cache_stats
        reuse = self.options.reuse_kv_cache

        with torch.no_grad():
            out, mask, next_pos = self._prefill(requests, torch)
            past = out.past_key_values
            compact = self.options.compact_finished_rows and self._can_drop_rows(past)
            for step in range(max_new):
                n = len(live)
                logp = processed_logprobs(out.logits[:, -1, :], self.sampling).cpu()
                cdf = logp.exp().double().cumsum(-1)
                # Zero-probability tokens (top-k / top-p) never win: their CDF step is empty.
                targets = (uniforms[:, step] * cdf[:, -1]).unsqueeze(-1)
                sampled = torch.searchsorted(cdf, targets, right=True).squeeze(-1).clamp(max=logp.shape[-1] - 1)
                chosen = torch.where(greedy, logp.argmax(-1), sampled)
                chosen_lp = logp[torch.arange(n), chosen].tolist()
                chosen_ids = chosen.tolist()
                step_tokens = torch.full((n, 1), self.pad_id, dtype=torch.long)
                done = []
                for b, i in enumerate(live):
                    if finish[i] is not None:
                        done.append(b)
                        continue
                    token = chosen_ids[b]
                    out_ids[i].append(token)
                    out_lp[i].append(chosen_lp[b])
                    step_tokens[b, 0] = token
                    if token in stop:
                        finish[i] = "stop"
                    elif len(out_ids[i]) >= requests[i].max_new_tokens:
                        finish[i] = "length"
                    if finish[i] is not None:
                        done.append(b)
                if len(done) == n:
                    break
                # A re-pack costs a fraction of one decode step; a finished row left in costs a row of
                # every later step. Waiting for a quarter bounds the re-packs (9 for a batch of 32).
                if compact and 4 * len(done) >= n:
                    if reuse:  # the leaving rows' keys/values are kept before they are dropped
                        self._store_prefixes([(b, requests[live[b]], out_ids[live[b]]) for b in done], past, mask)
                    gone = set(done)
                    keep = [b for b in range(n) if b not in gone]
                    index = torch.tensor(keep, dtype=torch.long)
                    past.reorder_cache(index.to(self.device))
                    mask, next_pos = mask[index.to(mask.device)], next_pos[index.to(next_pos.device)]
                    step_tokens, uniforms, greedy = step_tokens[index], uniforms[index], greedy[index]
                    live = [live[b] for b in keep]
                    done = []
                    stats["compactions"] += 1
                # Finished rows still in the batch step with a pad token that nothing attends to later.
                alive = torch.tensor([[0 if finish[i] is not None else 1] for i in live], dtype=torch.long)
                mask = torch.cat([mask, alive.to(self.device)], dim=1)
                stats["decode_row_steps"] += len(live)
                stats["live_row_steps"] += len(live) - len(done)
                out = self.model(input_ids=step_tokens.to(self.device), attention_mask=mask,
                                 position_ids=next_pos, past_key_values=past, use_cache=True)
                past = out.past_key_values
                next_pos = next_pos + 1
            if reuse:
                self._store_prefixes([(b, requests[i], out_ids[i]) for b, i in enumerate(live)], past, mask)
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


BACKEND = GeneratorBackend(name="hf", generator=HFGenerator, options=HFOptions)
