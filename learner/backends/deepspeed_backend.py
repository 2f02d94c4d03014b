"""DeepSpeed ZeRO-3 backend: parameters, gradients and optimizer state partitioned over the ranks.

On CPU it runs with torch.distributed's gloo backend (the tests use 2 ranks on 2 CPUs); on GPUs
with NCCL (not exercised in this repository's CI: no GPU was available while it was written).

Choices that come from measurements on our machines (docs/../stack_notes):
- the rendezvous variables (MASTER_ADDR, ...) are set here, otherwise DeepSpeed falls back to
  MPI discovery and fails on `mpi4py`;
- a client `torch.optim.AdamW` and `zero_force_ds_cpu_optimizer: false`: DeepSpeed's fused / CPU
  Adam would JIT-compile C++ for 85-105 s on a fresh machine;
- `build_shm_op` is skipped on CPU (another 70-100 s JIT build) unless configured otherwise;
- `import torch._dynamo` before `zero.Init`, which patches `Tensor.__new__`;
- `managed_gradient_accumulation: false`: the learner decides how many micro-batches a step has
  (it varies with dynamic sampling) and calls `step()` once per batch.

The policy is built under `zero.Init` (partitioned from birth) as the checkpoint's own architecture
class and its weights are loaded from the (sharded) safetensors checkpoint one module at a time
(`modeling.hf_checkpoint.load_weights_by_module`), so no rank ever holds the whole model. The same layer-by-
layer gathering serves `iter_full_parameters` (weight sync, checkpoints).

Checkpoints are our own, not DeepSpeed's (whose loader unpickles with weights_only=False): each
rank writes its fp32 master partition (safetensors) and its base-optimizer state (weights-only torch).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import torch

from learner.backends.base import DTYPES, LearnerBackend
from modeling.checkpoint import load_tensors, load_torch_state, save_tensors, save_torch_state
from modeling.config_models import LearnerConfig


def _prepare_environment(config: LearnerConfig, rank: int, world_size: int, master_port: int | None) -> None:
    ds = config.deepspeed
    port = master_port or ds.master_port
    if port is None:
        raise ValueError("the deepspeed backend needs a rendezvous port (learner.deepspeed.master_port or master_port=)")
    # Ray gives each rank actor its own GPU(s) through CUDA_VISIBLE_DEVICES, so the local device index
    # is the rank modulo what this process can see (usually 0), not the global rank.
    local = 0 if config.device == "cpu" else rank % max(1, torch.cuda.device_count())
    os.environ.update({
        "MASTER_ADDR": ds.master_addr, "MASTER_PORT": str(port), "RANK": str(rank),
        "WORLD_SIZE": str(world_size), "LOCAL_RANK": str(local),
    })
    # The CPU runtime defaults (envs/_runtime.py) may have set DS_ACCELERATOR=cpu on a GPU node whose
    # CUDA_VISIBLE_DEVICES was unset; the learner config decides.
    os.environ["DS_ACCELERATOR"] = "cpu" if config.device == "cpu" else "cuda"


def _ds_config(config: LearnerConfig) -> dict:
    ds, o = config.deepspeed, config.optim
    zero: dict = {
        "stage": ds.zero_stage,
        "overlap_comm": False,
        "contiguous_gradients": True,
        "stage3_gather_16bit_weights_on_model_save": True,
    }
    if ds.offload_optimizer:
        zero["offload_optimizer"] = {"device": "cpu", "pin_memory": config.device == "cuda"}
    if ds.offload_param:
        zero["offload_param"] = {"device": "cpu", "pin_memory": config.device == "cuda"}
    return {
        "train_micro_batch_size_per_gpu": o.micro_batch_size,
        "gradient_accumulation_steps": 1,
        "managed_gradient_accumulation": False,
        "gradient_clipping": o.max_grad_norm,
        "zero_optimization": zero,
        "bf16": {"enabled": config.dtype == "bfloat16"},
        "zero_force_ds_cpu_optimizer": False,
        "steps_per_print": 10**9,
        "wall_clock_breakdown": False,
    }


def _load_weights_module_by_module(model: torch.nn.Module, model_dir: str, rank: int) -> None:
    """Fill a zero.Init-partitioned model from its (sharded) safetensors checkpoint, one module's
    parameters at a time: rank 0 reads and writes, every rank joins the gather (collective)."""
    import deepspeed

    from modeling.hf_checkpoint import load_weights_by_module

    load_weights_by_module(model, model_dir,
                           gather=lambda params: deepspeed.zero.GatheredParameters(params, modifier_rank=0),
                           write=rank == 0)


def _register_external_parameters(model: torch.nn.Module) -> int:
    """Let ZeRO-3 gather parameters that a module reads from its child without calling the child.

    ZeRO-3 gathers a module's own parameters around its forward. The gated delta net of Qwen3-Next /
    Qwen3.5 (linear attention) passes `self.conv1d.weight` to a conv kernel instead of calling
    `self.conv1d(...)`, so that weight would stay a partitioned, empty tensor (an IndexError in the
    first forward); registered as external parameters of the parent, it is gathered with it.

    Returns:
        How many parameters were registered.
    """
    import deepspeed

    count = 0
    for module in model.modules():
        conv = getattr(module, "conv1d", None)
        if isinstance(conv, torch.nn.Conv1d) and type(module).__name__.endswith("GatedDeltaNet"):
            for param in conv.parameters(recurse=False):
                deepspeed.zero.register_external_parameter(module, param)
                count += 1
    return count


class DeepSpeedBackend(LearnerBackend):
    """ZeRO-3 over `world_size` ranks (one process each)."""

    name = "deepspeed"

    def __init__(self, config: LearnerConfig, model_dir: str, seed: int, rank: int = 0, world_size: int = 1,
                 master_port: int | None = None):
        super().__init__(config, model_dir, seed, rank, world_size)
        _prepare_environment(config, rank, world_size, master_port)
        import deepspeed
        import deepspeed.comm
        import torch._dynamo  # must be loaded before zero.Init patches Tensor.__new__ (stack notes 4)

        if config.device == "cpu" and config.deepspeed.skip_shm_build:
            # `import deepspeed.comm.torch` would bind the torch package (deepspeed.comm has a `torch`
            # attribute), so patch through sys.modules.
            __import__("deepspeed.comm.torch")
            sys.modules["deepspeed.comm.torch"].build_shm_op = lambda: None
        from modeling.attention import use_varlen_attention
        from modeling.hf_checkpoint import build_empty_model, freeze_vision_tower, load_hf_config, resolve_model_path
        from modeling.transformers_setup import prepare_transformers

        prepare_transformers()
        torch.manual_seed(seed)
        dist_backend = "gloo" if config.device == "cpu" else "nccl"
        deepspeed.init_distributed(dist_backend=dist_backend, auto_mpi_discovery=False,
                                   timeout=timedelta(seconds=config.deepspeed.timeout_s))
        if config.device == "cuda":
            torch.cuda.set_device(int(os.environ["LOCAL_RANK"]))
        self._dtype = DTYPES[config.dtype]
        self._ds_config = _ds_config(config)

        def build(directory: str) -> torch.nn.Module:
            path = resolve_model_path(directory)
            # The checkpoint's own architecture class (config.architectures[0]), so parameter names are
            # the checkpoint's (model.language_model.* for Qwen3.5). No random init: every tensor is
            # loaded below (and HF's init indexes the embedding's padding row, which a partitioned
            # parameter does not have). zero.Init picks the partitions' dtype from the config's bf16
            # switch (DeepSpeed 0.19.8 ignores an explicit dtype on CPU).
            with deepspeed.zero.Init(config_dict_or_path=self._ds_config):
                model = build_empty_model(load_hf_config(path), self._dtype)
            _load_weights_module_by_module(model, str(path), rank)
            _register_external_parameters(model)
            use_varlen_attention(model)  # as the torch backend (base.load_causal_lm)
            return model

        model = build(model_dir)
        freeze_vision_tower(model, train_vision_tower=config.train_vision_tower)
        if config.gradient_checkpointing:
            model.gradient_checkpointing_enable()
        model.train()
        o = config.optim
        trainable = [p for p in model.parameters() if p.requires_grad]  # not a frozen vision tower
        optimizer = torch.optim.AdamW(trainable, lr=o.lr, betas=o.betas, eps=o.eps,
                                      weight_decay=o.weight_decay)
        self._engine, self._optimizer, _, _ = deepspeed.initialize(model=model, optimizer=optimizer,
                                                                   config=self._ds_config)
        self._reference = None
        if config.loss.grpo.kl_beta > 0:
            ref = build(config.reference_model_dir or model_dir)
            ref.eval().requires_grad_(False)
            # An inference-only ZeRO-3 engine keeps the frozen reference partitioned too.
            ref_cfg = {k: v for k, v in self._ds_config.items() if k not in ("gradient_clipping",)}
            self._reference, *_ = deepspeed.initialize(model=ref, config=ref_cfg)
            self._reference.eval()

    @property
    def policy(self) -> torch.nn.Module:
        # Forward through the module: ZeRO-3's hooks live on every submodule, and our chunked
        # log-prob code calls the decoder and the LM head separately.
        return self._engine.module

    @property
    def reference(self) -> torch.nn.Module | None:
        return None if self._reference is None else self._reference.module

    def begin_forward(self) -> None:
        # engine.forward() would do this; we call the module directly (chunked LM head), so we must:
        # without it ZeRO-3's micro-step counter stays 0 and every backward overwrites, instead of
        # adding to, the gradients of the previous micro-batches.
        self._optimizer.clear_backward_seen_flag()

    def backward(self, loss: torch.Tensor) -> None:
        self._engine.backward(loss, scale_wrt_gas=False)

    def step(self) -> float:
        self._engine.step()
        norm = self._engine.get_global_grad_norm()
        return float(norm) if norm is not None else float("nan")

    def iter_full_parameters(self) -> Iterator[tuple[str, torch.Tensor]]:
        import deepspeed

        module = self._engine.module
        for mod_name, sub in module.named_modules():
            # Module by module, so a tied lm_head.weight is yielded under its own name as well.
            params = list(sub.named_parameters(recurse=False))
            if not params:
                continue
            # One module at a time, every rank gathering; modifier_rank=None: nothing is written back.
            with deepspeed.zero.GatheredParameters([p for _, p in params], modifier_rank=None):
                for pname, param in params:
                    yield (f"{mod_name}.{pname}" if mod_name else pname), param.data

    def load_full_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        import deepspeed

        module = self._engine.module
        if self.rank == 0:
            own = {n for n, _ in module.named_parameters()}  # canonical names: a tied alias may be absent
            missing = sorted(own - set(state))
            if missing:
                raise ValueError(f"weights lack {missing[:5]}")
        seen: set[int] = set()
        for mod_name, sub in module.named_modules():
            params = [(n, p) for n, p in sub.named_parameters(recurse=False) if id(p) not in seen]
            seen.update(id(p) for _, p in params)
            if not params:
                continue
            with deepspeed.zero.GatheredParameters([p for _, p in params], modifier_rank=0):
                if self.rank == 0:
                    with torch.no_grad():
                        for pname, param in params:
                            key = f"{mod_name}.{pname}" if mod_name else pname
                            param.copy_(state[key].to(param.dtype))
        # The optimizer's fp32 master partitions must follow the new weights.
        self._optimizer.refresh_fp32_params()

    def save_state(self, directory: Path) -> None:
        opt = self._optimizer
        directory = Path(directory)
        flat = {f"group_{i}": t for i, t in enumerate(opt.fp32_partitioned_groups_flat)}
        save_tensors(directory / f"fp32_partition_rank{self.rank}.safetensors", flat)
        opt._set_fp32_optimizer_param_groups()
        try:
            base = opt.optimizer.state_dict()
        finally:
            opt._clear_fp32_optimizer_param_groups()
        save_torch_state(directory / f"optimizer_rank{self.rank}.pt", base)
        save_torch_state(directory / f"engine_rank{self.rank}.pt",
                         {"global_steps": self._engine.global_steps, "global_samples": self._engine.global_samples})

    def load_state(self, directory: Path) -> None:
        from deepspeed.checkpoint.constants import FP32_FLAT_GROUPS, LOSS_SCALER, OPTIMIZER_STATE_DICT

        opt = self._optimizer
        directory = Path(directory)
        flat = load_tensors(directory / f"fp32_partition_rank{self.rank}.safetensors")
        groups = [flat[f"group_{i}"] for i in range(len(flat))]
        if len(groups) != len(opt.fp32_partitioned_groups_flat):
            raise ValueError(f"checkpoint has {len(groups)} fp32 partitions, this rank {len(opt.fp32_partitioned_groups_flat)}")
        state = {
            LOSS_SCALER: opt.loss_scaler,
            "dynamic_loss_scale": opt.dynamic_loss_scale,
            "overflow": False,
            OPTIMIZER_STATE_DICT: load_torch_state(directory / f"optimizer_rank{self.rank}.pt"),
            FP32_FLAT_GROUPS: groups,
        }
        # Restores the base optimizer, the fp32 partitions and, from them, the bf16/fp32 model partitions.
        opt._rigid_load_state_dict(state, load_optimizer_states=True)
        engine_state = load_torch_state(directory / f"engine_rank{self.rank}.pt")
        self._engine.global_steps = int(engine_state["global_steps"])
        self._engine.global_samples = int(engine_state["global_samples"])

    def autocast(self):
        return contextlib.nullcontext()

    def shutdown(self) -> None:
        with contextlib.suppress(Exception):  # best effort at teardown
            self._engine.destroy()
        if torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()
