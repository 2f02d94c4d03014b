"""The `vllm` generator backend (GPU nodes, optional `gpu` extra).

NOT GPU-VERIFIED in this repository's CPU sessions: this module is written against the vLLM
0.33 Python API (`LLM`, `SamplingParams`, `TokensPrompt`, `collective_rpc`, `worker_extension_cls`)
and is imported only when a config selects `generator.backend: vllm`. The CPU tests cover the
same interface through the `hf` backend. Run `bench/gpu_step.py` on a GPU node to exercise it.

Weights reach vLLM two ways:

* `update_weights(state_dict, version)`: a full CPU state dict (what the learner publishes through
  the Ray object store), loaded bucket by bucket through the worker's `model.load_weights`, so no
  second full copy of the model is ever held on the GPU.
* `join_weight_sync(...)` + `receive_weights(version)`: the GPU path. The learner's rank 0 and the
  vLLM workers form a `learner.weight_sync.WeightSyncGroup` (NCCL) and the learner broadcasts
  parameters in size-capped buckets (each ZeRO-3 module gathered only for its turn, on the learner
  side); every blocking point has a timeout, so a dead or missing peer becomes an error that names
  it instead of a silent hang.

Log-probs: vLLM's default returns raw-model log-probs; we ask for `logprobs_mode=
"processed_logprobs"`, the log-probs of the distribution after temperature / top-k / top-p, i.e.
the one the token was actually sampled from (the contract of `actors.generator`).
"""

from __future__ import annotations

import time
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from actors.generator import GenerationRequest, GenerationResult, Generator, SamplingConfig


class VLLMOptions(BaseModel):
    """Options under `generator.options` when `generator.backend: vllm`."""

    model_config = ConfigDict(extra="forbid")
    dtype: str = "bfloat16"
    gpu_memory_utilization: float = Field(default=0.85, gt=0, le=1)
    tensor_parallel_size: int = Field(default=1, ge=1)
    max_model_len: int = Field(default=8192 + 12288, ge=16)
    enable_prefix_caching: bool = True
    enforce_eager: bool = False
    # Bucket cap for object-store (state dict) weight updates; the broadcast path uses weight_sync.bucket_mb.
    bucket_mb: int = Field(default=512, ge=1)


class WeightSyncExtension:
    """Mixed into every vLLM worker (`worker_extension_cls`); called through `collective_rpc`.

    `self.model_runner` and `self.device` are the worker's own attributes.
    """

    def hcgym_load_weights(self, named_tensors: list[tuple[str, Any]]) -> int:
        """Load one bucket of (name, tensor) pairs through the model's own loader (handles fused
        qkv / gate-up projections and tensor-parallel sharding)."""
        model = self.model_runner.model
        loaded = model.load_weights(weights=[(name, tensor.to(self.device)) for name, tensor in named_tensors])
        return len(loaded) if loaded is not None else len(named_tensors)

    def hcgym_join_weight_sync(self, config: dict, rank_offset: int, world_size: int, peer_names: list[str]) -> None:
        """Join the learner's weight-sync group (`learner.weight_sync.WeightSyncGroup`, NCCL) as
        receiver `rank_offset + tensor-parallel rank`."""
        from vllm.distributed.parallel_state import get_tensor_model_parallel_rank

        from learner.config_models import WeightSyncConfig
        from learner.weight_sync import WeightSyncGroup

        rank = rank_offset + get_tensor_model_parallel_rank()
        self._hcgym_group = WeightSyncGroup(rank, world_size, WeightSyncConfig.model_validate(config), peer_names,
                                            device=str(self.device))

    def hcgym_receive(self, version: int) -> int:
        """Receive broadcast `version` bucket by bucket and load each tensor as it arrives (the group's
        own timeouts name a stalled peer)."""
        if not hasattr(self, "_hcgym_group"):
            raise RuntimeError("hcgym_receive before hcgym_join_weight_sync")
        model = self.model_runner.model
        loaded = 0
        for name, tensor in self._hcgym_group.receive(version):
            # load_weights copies (and shards for tensor parallelism) before the next bucket arrives.
            model.load_weights(weights=[(name, tensor)])
            loaded += 1
        return loaded


class VLLMGenerator(Generator):
    """vLLM engine behind the `Generator` interface."""

    name = "vllm"

    def __init__(self, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None) -> None:
        super().__init__(model_dir, sampling, stop_token_ids, initial_version, options)
        try:
            from vllm import LLM
        except ImportError as exc:  # the CPU install does not carry the gpu extra
            raise ImportError(
                "generator.backend 'vllm' needs the optional gpu extra: pip install 'healthcare-ai-gym[gpu]' "
                f"on a CUDA node ({exc})"
            ) from exc
        self.options = VLLMOptions.model_validate(options or {})
        self.llm = LLM(
            model=model_dir,
            tokenizer=model_dir,
            dtype=self.options.dtype,
            gpu_memory_utilization=self.options.gpu_memory_utilization,
            tensor_parallel_size=self.options.tensor_parallel_size,
            max_model_len=self.options.max_model_len,
            enable_prefix_caching=self.options.enable_prefix_caching,
            enforce_eager=self.options.enforce_eager,
            worker_extension_cls="actors.generator_vllm.WeightSyncExtension",
            logprobs_mode="processed_logprobs",
            skip_tokenizer_init=False,
        )

    def _params(self, request: GenerationRequest):
        from vllm import SamplingParams

        return SamplingParams(
            # temperature 0 is vLLM's greedy mode.
            temperature=0.0 if request.greedy else self.sampling.temperature,
            top_p=self.sampling.top_p,
            top_k=self.sampling.top_k if self.sampling.top_k > 0 else -1,
            max_tokens=request.max_new_tokens,
            seed=int(request.seed) & 0x7FFF_FFFF,
            logprobs=0,  # the sampled token's own log-prob
            stop_token_ids=self.stop_token_ids,
            # Keep the stop token in the output: TITO needs the ids exactly as sampled.
            include_stop_str_in_output=True,
            skip_special_tokens=False,
            detokenize=False,
        )

    def generate(self, requests: list[GenerationRequest]) -> list[GenerationResult]:
        from vllm.inputs import TokensPrompt

        if not requests:
            return []
        self.check_version(requests)
        started = time.perf_counter()
        outputs = self.llm.generate(
            [TokensPrompt(prompt_token_ids=r.prompt_ids) for r in requests],
            sampling_params=[self._params(r) for r in requests],
            use_tqdm=False,
        )
        elapsed = time.perf_counter() - started
        results = []
        for request, output in zip(requests, outputs):
            completion = output.outputs[0]
            token_ids = list(completion.token_ids)
            logprobs = [float(step[token].logprob) for token, step in zip(token_ids, completion.logprobs or [])]
            if len(logprobs) != len(token_ids):
                raise RuntimeError(
                    f"vLLM returned {len(logprobs)} log-probs for {len(token_ids)} tokens (request {request.request_id})"
                )
            stopped = bool(token_ids) and token_ids[-1] in self.stop_token_ids
            results.append(GenerationResult(
                request_id=request.request_id, token_ids=token_ids, logprobs=logprobs,
                finish_reason="stop" if stopped else "length", policy_version=self.version, generate_s=elapsed,
            ))
        return results

    def update_weights(self, state_dict: dict[str, Any], version: int) -> None:
        cap = self.options.bucket_mb * 2**20
        bucket: list[tuple[str, Any]] = []
        size = 0
        for name, tensor in state_dict.items():
            bucket.append((name, tensor))
            size += tensor.numel() * tensor.element_size()
            if size >= cap:
                self.llm.collective_rpc("hcgym_load_weights", args=(bucket,))
                bucket, size = [], 0
        if bucket:
            self.llm.collective_rpc("hcgym_load_weights", args=(bucket,))
        # Cached prefixes were computed with the old weights.
        self.llm.reset_prefix_cache()
        self.version = int(version)

    # -- GPU broadcast path ----------------------------------------------------------------------
    def join_weight_sync(self, config: dict[str, Any], rank: int, world_size: int, peer_names: list[str]) -> None:
        # With tensor parallelism every TP worker is a receiver: ranks rank .. rank + tp - 1.
        self.llm.collective_rpc("hcgym_join_weight_sync", args=(config, rank, world_size, peer_names))

    def receive_weights(self, version: int) -> None:
        self.llm.collective_rpc("hcgym_receive", args=(version,))
        self.llm.reset_prefix_cache()  # cached prefixes were computed with the old weights
        self.version = int(version)
