"""A memory and capacity plan of a run config on a GPU kind, before the cluster bill (`hcgym plan`).

Every figure is a pure function of the config, the model's architecture (its config.json, or the
built-in table when the checkpoint is not on this machine) and the GPU kind. The formulas, per
actor (bytes; N = all parameters, N_t = trainable ones, W = learner ranks, b = micro-batch,
s = max_prompt_tokens + max_response_tokens, h = hidden size, L = layers, I = MLP width, V = vocab):

Learner rank (DeepSpeed ZeRO-3 with bf16 and a client AdamW, deepspeed 0.19.8 stage3.py):
- parameters: 2N/W bf16 partition of the policy, and another 2N/W of the frozen KL reference
  (its own inference ZeRO-3 engine, when loss.grpo.kl_beta > 0); host memory with offload_param;
- optimizer: fp32 master 4N_t/W + Adam m and v 8N_t/W; host memory with offload_optimizer;
- gradients: the partition buffer in the model dtype (grad_accum_dtype unset: 2N_t/W) plus the fp32
  copy of one optimizer sub-group at the step (4·min(sub_group_size = 1e9, N_t/W)); host memory
  with offload_optimizer;
- ZeRO-3 working set: the largest module gathered whole (the embedding or LM head, V·h) plus the
  prefetch bucket (5e7) in bf16, and the reduce bucket (5e8 elements, bf16); on the GPU whatever
  is offloaded;
- activations: with gradient checkpointing, each layer's input is kept (L·b·s·h·2) plus one
  layer's full activations recomputed in the backward, b·s·2·(4h + P + 4I), where P is the widest
  token-mixer's projection outputs plus its core output (Qwen3.5 full attention: q+gate, k, v,
  attention out; GatedDeltaNet: qkv, z, b, a, core out); without it, L times that layer figure.
  Plus the LM head over one chunk of positions: b·chunk·V·4 bytes for the fp32 logits, their
  log-softmax and its gradient (x3).
Teacher (inference): weights N in its dtype, the fp32 EMA shadow 4N on the GPU or in host memory
(teacher.ema_shadow_device), one layer's working set batch·s·2·(2h + P + 2I) and the LM-head
chunk batch·chunk·V·4·2 (logits and log-softmax).
Generator (vLLM): weights 2N; the rest of gpu_memory_utilization·memory holds the KV cache, per
token L_full·kv_heads·head_dim·2 (K and V)·2 bytes over the full-attention layers, and per sequence
the fixed-size GatedDeltaNet state of each linear-attention layer: the recurrent state
v_heads·k_dim·v_dim·4 bytes (fp32) plus the conv state (2·k_heads·k_dim + v_heads·v_dim)·(kernel-1)·2.
Checkpoint (learner/learner_actor.save_checkpoint + DeepSpeedBackend.save_state + Teacher.save):
the bf16 policy 2N, per rank fp32 master 4N_t/W and Adam m, v 8N_t/W, and the teacher's weights
(4N, the fp32 shadow, when the teacher computes in bf16).

A GPU fits an actor when the actor's total is at most GPU_HEADROOM of its memory: the CUDA context,
NCCL buffers and the caching allocator's fragmentation take the rest.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from pydantic import BaseModel, ConfigDict, Field

from modeling.config_models import ConfigModel

if TYPE_CHECKING:
    from learner.config import RunConfig

GIB = 2**30
MIB = 2**20
GPU_HEADROOM = 0.9

GpuKind = Literal["a100-40gb", "a100-80gb", "h100-80gb", "h200-141gb"]


class GpuSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    memory_mib: int = Field(description="total memory as nvidia-smi reports it")


#: Memory of each GPU kind, as nvidia-smi reports it (MiB).
GPUS: dict[str, GpuSpec] = {
    "a100-40gb": GpuSpec(name="NVIDIA A100 40GB", memory_mib=40_960),
    "a100-80gb": GpuSpec(name="NVIDIA A100 80GB", memory_mib=81_920),
    "h100-80gb": GpuSpec(name="NVIDIA H100 80GB HBM3", memory_mib=81_559),
    "h200-141gb": GpuSpec(name="NVIDIA H200 141GB HBM3e", memory_mib=143_771),
}


class ClusterConfig(ConfigModel):
    """The nodes a run is planned for (`hcgym plan`); training itself reads none of it.

    The defaults are cluster.yaml's node type (AWS p4de.24xlarge) and its gp3 root volume.
    """

    gpu: GpuKind = Field(default="a100-80gb", description="GPU model of every node")
    gpus_per_node: int = Field(default=8, ge=1, description="GPUs per node")
    cpus_per_node: int = Field(default=96, ge=1, description="CPU cores per node")
    host_memory_gib: float = Field(default=1152.0, gt=0, description="host memory per node, GiB")
    # gp3's baseline is 125 MiB/s, provisioned up to 1000 MiB/s (cluster.yaml's
    # BlockDeviceMappings.Ebs.Throughput).
    checkpoint_volume_mib_s: float = Field(default=125.0, gt=0, description="sustained write throughput of the volume "
                                                                            "the run directory is on, MiB/s")


# ---------------------------------------------------------------------------------------------
# Architecture
# ---------------------------------------------------------------------------------------------


class Architecture(BaseModel):
    """What the plan needs of a model's config.json."""

    model_config = ConfigDict(extra="forbid", frozen=True, protected_namespaces=())
    model_type: str
    vocab_size: int
    hidden_size: int
    intermediate_size: int
    num_hidden_layers: int
    num_attention_heads: int
    num_key_value_heads: int
    head_dim: int
    tie_word_embeddings: bool = False
    attention_bias: bool = False          # q, k, v biases (qwen2)
    qk_norm: bool = False                 # q_norm / k_norm of head_dim (qwen3, qwen3.5)
    attn_output_gate: bool = False        # q_proj also emits a gate (qwen3.5)
    layer_types: tuple[str, ...] = ()     # "full_attention" / "linear_attention"; empty = all full
    linear_num_key_heads: int = 0
    linear_num_value_heads: int = 0
    linear_key_head_dim: int = 0
    linear_value_head_dim: int = 0
    linear_conv_kernel_dim: int = 0
    vision_params: int = 0                # the vision tower (frozen unless learner.train_vision_tower)
    source: str = ""

    @property
    def full_attention_layers(self) -> int:
        return self.layer_types.count("full_attention") if self.layer_types else self.num_hidden_layers

    @property
    def linear_attention_layers(self) -> int:
        return self.layer_types.count("linear_attention")

    @property
    def linear_qkv_width(self) -> int:
        return 2 * self.linear_num_key_heads * self.linear_key_head_dim + self.linear_num_value_heads * self.linear_value_head_dim


def text_parameters(a: Architecture) -> int:
    """Parameters of the language model (embedding, layers, final norm, LM head unless tied)."""
    h, hd = a.hidden_size, a.head_dim
    q_width = a.num_attention_heads * hd * (2 if a.attn_output_gate else 1)
    kv_width = a.num_key_value_heads * hd
    full = h * q_width + 2 * h * kv_width + a.num_attention_heads * hd * h
    if a.attention_bias:
        full += q_width + 2 * kv_width
    if a.qk_norm:
        full += 2 * hd
    v_width = a.linear_num_value_heads * a.linear_value_head_dim
    linear = (h * a.linear_qkv_width                       # in_proj_qkv
              + h * v_width                                # in_proj_z (output gate)
              + 2 * h * a.linear_num_value_heads           # in_proj_b, in_proj_a
              + a.linear_qkv_width * a.linear_conv_kernel_dim  # depthwise conv1d, no bias
              + 2 * a.linear_num_value_heads               # dt_bias, A_log
              + a.linear_value_head_dim                    # gated RMSNorm
              + v_width * h)                               # out_proj
    per_layer = 3 * h * a.intermediate_size + 2 * h     # SwiGLU MLP + two RMSNorms
    layers = (a.full_attention_layers * (full + per_layer)
              + a.linear_attention_layers * (linear + per_layer))
    embed = a.vocab_size * h
    return embed + layers + h + (0 if a.tie_word_embeddings else embed)


def qwen3_5_vision_parameters(v: dict) -> int:
    """Parameters of a Qwen3.5 vision tower (transformers' Qwen3_5VisionModel): patch embedding
    (Conv3d with bias), learned position embedding, blocks with LayerNorms, fused qkv and a GELU MLP
    (all with biases), and the 2x2 patch merger."""
    c, d, i = v.get("in_channels", 3), v["hidden_size"], v["intermediate_size"]
    patch = c * v.get("temporal_patch_size", 2) * v["patch_size"] ** 2 * d + d
    block = 2 * 2 * d + (d * 3 * d + 3 * d) + (d * d + d) + (d * i + i) + (i * d + d)
    merged = d * v.get("spatial_merge_size", 2) ** 2
    merger = 2 * d + (merged * merged + merged) + (merged * v["out_hidden_size"] + v["out_hidden_size"])
    return patch + v["num_position_embeddings"] * d + v["depth"] * block + merger


def architecture_from_config(config: dict, source: str = "config.json") -> Architecture:
    """The `Architecture` of a Hugging Face config.json mapping (text_config of a multimodal model).

    Raises:
        ValueError: naming the source and the missing key or unsupported model type.
    """
    text = config.get("text_config") or config
    model_type = str(config.get("model_type") or text.get("model_type") or "")
    family = model_type.removesuffix("_text")
    if family not in ("qwen2", "qwen3", "qwen3_5", "llama"):
        raise ValueError(f"{source}: model_type {model_type!r} is not one the plan knows (qwen2, qwen3, qwen3_5, llama)")
    try:
        heads = int(text["num_attention_heads"])
        hidden = int(text["hidden_size"])
        layers = int(text["num_hidden_layers"])
        fields = dict(model_type=family, vocab_size=int(text["vocab_size"]), hidden_size=hidden,
                      intermediate_size=int(text["intermediate_size"]), num_hidden_layers=layers,
                      num_attention_heads=heads, num_key_value_heads=int(text.get("num_key_value_heads", heads)),
                      head_dim=int(text.get("head_dim") or hidden // heads))
    except KeyError as exc:
        raise ValueError(f"{source}: missing key {exc.args[0]!r}") from None
    tie = config.get("tie_word_embeddings", text.get("tie_word_embeddings", family != "qwen3_5"))
    fields.update(tie_word_embeddings=bool(tie), attention_bias=bool(text.get("attention_bias", family == "qwen2")),
                  qk_norm=family in ("qwen3", "qwen3_5"), source=source)
    if family == "qwen3_5":
        layer_types = text.get("layer_types") or [
            "linear_attention" if (i + 1) % int(text.get("full_attention_interval", 4)) else "full_attention"
            for i in range(layers)]
        fields.update(attn_output_gate=bool(text.get("attn_output_gate", True)), layer_types=tuple(layer_types),
                      linear_num_key_heads=int(text["linear_num_key_heads"]),
                      linear_num_value_heads=int(text["linear_num_value_heads"]),
                      linear_key_head_dim=int(text["linear_key_head_dim"]),
                      linear_value_head_dim=int(text["linear_value_head_dim"]),
                      linear_conv_kernel_dim=int(text.get("linear_conv_kernel_dim", 4)))
        if config.get("vision_config"):
            fields["vision_params"] = qwen3_5_vision_parameters(config["vision_config"])
    return Architecture(**fields)


#: Architectures of the models the shipped configs name, for planning without the checkpoint.
#: Qwen/Qwen3.5-9B: the text fields are transformers 5.19's Qwen3_5TextConfig defaults (its docstring:
#: "the Qwen3.5-9B style configuration") and match the model card (hidden 4096, 32 layers laid out as
#: 8 x (3 Gated DeltaNet + 1 Gated Attention), DeltaNet 16 QK / 32 V heads of 128, attention 16 Q /
#: 4 KV heads of 256, FFN 12288, vocab 248320 padded, untied LM output); the vision tower is
#: Qwen3_5VisionConfig's defaults with out_hidden_size 4096 (the text hidden size it projects into).
BUILTIN_CONFIGS: dict[str, dict] = {
    "Qwen/Qwen3.5-9B": {
        "model_type": "qwen3_5",
        "tie_word_embeddings": False,
        "text_config": {
            "model_type": "qwen3_5_text", "vocab_size": 248320, "hidden_size": 4096, "intermediate_size": 12288,
            "num_hidden_layers": 32, "num_attention_heads": 16, "num_key_value_heads": 4, "head_dim": 256,
            "attn_output_gate": True, "full_attention_interval": 4, "linear_num_key_heads": 16,
            "linear_num_value_heads": 32, "linear_key_head_dim": 128, "linear_value_head_dim": 128,
            "linear_conv_kernel_dim": 4,
        },
        "vision_config": {"depth": 27, "hidden_size": 1152, "intermediate_size": 4304, "num_heads": 16,
                          "in_channels": 3, "patch_size": 16, "temporal_patch_size": 2, "spatial_merge_size": 2,
                          "num_position_embeddings": 2304, "out_hidden_size": 4096},
    },
}


def resolve_architecture(cfg: RunConfig) -> Architecture:
    """The run's model architecture: the checkpoint's config.json (a local folder or the HF cache),
    else the built-in table; a tiny model from its build settings.

    Raises:
        ValueError: the checkpoint is absent and the model is not in the built-in table.
    """
    model = cfg.model
    if model.kind == "tiny":
        from modeling.model import TINY_MODEL_DEFAULTS

        fields = {**TINY_MODEL_DEFAULTS, **model.tiny.overrides, "vocab_size": model.tiny.vocab_size,
                  "model_type": model.tiny.architecture}
        return architecture_from_config(fields, source="model.tiny")
    path = str(model.path)
    try:
        from modeling.hf_checkpoint import resolve_model_path

        folder = resolve_model_path(path, revision=model.revision)
        config_file = folder / "config.json"
        return architecture_from_config(json.loads(config_file.read_text(encoding="utf-8")), source=str(config_file))
    except (FileNotFoundError, ValueError, OSError) as exc:
        if path in BUILTIN_CONFIGS:
            return architecture_from_config(BUILTIN_CONFIGS[path], source=f"built-in table ({path}; checkpoint not "
                                                                          f"on this machine)")
        raise ValueError(f"model.path: {path!r}: no config.json on this machine ({exc}) and not in the plan's "
                         f"built-in table ({', '.join(BUILTIN_CONFIGS)}); `hcgym model fetch {path}` first") from None


# ---------------------------------------------------------------------------------------------
# The figures
# ---------------------------------------------------------------------------------------------

ZERO3_SUB_GROUP = 10**9          # DeepSpeedZeroConfig.sub_group_size default
ZERO3_PREFETCH = 5 * 10**7       # stage3_prefetch_bucket_size default
ZERO3_REDUCE_BUCKET = 5 * 10**8  # reduce_bucket_size default


class Item(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    gib: float
    where: Literal["gpu", "host"]


class ActorPlan(BaseModel):
    model_config = ConfigDict(extra="forbid")
    actor: str
    count: int
    gpus_each: float
    cpus_each: float
    items: list[Item]
    gpu_gib: float
    host_gib: float
    gpu_budget_gib: float
    fits: bool
    notes: list[str] = Field(default_factory=list)


class CheckpointPlan(BaseModel):
    model_config = ConfigDict(extra="forbid")
    size_gib: float
    volume_mib_s: float
    write_minutes: float
    interval_steps: int
    writes: int


class Plan(BaseModel):
    model_config = ConfigDict(extra="forbid")
    config_name: str
    gpu: str
    gpu_memory_gib: float
    architecture_source: str
    parameters: int
    trainable_parameters: int
    sequence_tokens: int
    actors: list[ActorPlan]
    gpus: float
    cpus: float
    nodes: int
    host_gib_per_node: float
    checkpoint: CheckpointPlan
    linear_attention_kernels: str
    problems: list[str]

    @property
    def fits(self) -> bool:
        return not self.problems


def _gib(n_bytes: float) -> float:
    return n_bytes / GIB


def layer_projection_width(a: Architecture) -> int:
    """P: the widest token mixer's projection outputs plus its core output, per token."""
    full = a.num_attention_heads * a.head_dim * (2 if a.attn_output_gate else 1) + 2 * a.num_key_value_heads * a.head_dim \
        + a.num_attention_heads * a.head_dim
    if not a.linear_attention_layers:
        return full
    v_width = a.linear_num_value_heads * a.linear_value_head_dim
    linear = a.linear_qkv_width + v_width + 2 * a.linear_num_value_heads + v_width
    return max(full, linear)


def training_activation_bytes(a: Architecture, micro_batch: int, seq: int, chunk: int, checkpointing: bool) -> dict[str, float]:
    """Activations of one learner forward + backward (bf16), see the module docstring."""
    tokens = micro_batch * seq
    layer = tokens * 2 * (4 * a.hidden_size + layer_projection_width(a) + 4 * a.intermediate_size)
    head = micro_batch * min(chunk, seq) * a.vocab_size * 4 * 3
    if checkpointing:
        return {"layer inputs (checkpointed)": a.num_hidden_layers * tokens * a.hidden_size * 2,
                "one layer recomputed": layer, "LM-head chunk": head}
    return {"all layers' activations": a.num_hidden_layers * layer, "LM-head chunk": head}


def kv_bytes_per_token(a: Architecture, dtype_bytes: int = 2) -> int:
    return a.full_attention_layers * a.num_key_value_heads * a.head_dim * 2 * dtype_bytes


def linear_state_bytes_per_sequence(a: Architecture) -> int:
    recurrent = a.linear_num_value_heads * a.linear_key_head_dim * a.linear_value_head_dim * 4
    conv = a.linear_qkv_width * max(a.linear_conv_kernel_dim - 1, 0) * 2
    return a.linear_attention_layers * (recurrent + conv)


def smallest_world_size(need, budget: float, start: int, limit: int = 64) -> int | None:
    """The smallest world size >= start whose per-rank need (a function of it) fits the budget."""
    for world in range(start, limit + 1):
        if need(world) <= budget:
            return world
    return None


def _learner(cfg: RunConfig, a: Architecture, n: int, n_train: int, budget: float) -> tuple[ActorPlan, list[str]]:
    ds, lc = cfg.learner.deepspeed, cfg.learner
    seq = cfg.rollout.max_prompt_tokens + cfg.rollout.max_response_tokens
    bytes_p = 2 if lc.dtype == "bfloat16" else 4
    reference = lc.loss.grpo.kl_beta > 0

    def items_for(world: int, offload_param: bool, offload_opt: bool, checkpointing: bool) -> list[Item]:
        pw = "host" if offload_param else "gpu"
        ow = "host" if offload_opt else "gpu"
        out = [Item(name=f"policy params ({lc.dtype}, 1/{world})", gib=_gib(bytes_p * n / world), where=pw)]
        if reference:
            out.append(Item(name=f"KL reference params ({lc.dtype}, 1/{world})", gib=_gib(bytes_p * n / world), where=pw))
        out += [
            Item(name="fp32 master weights", gib=_gib(4 * n_train / world), where=ow),
            Item(name="Adam m and v (fp32)", gib=_gib(8 * n_train / world), where=ow),
            Item(name=f"gradient partition ({lc.dtype})", gib=_gib(bytes_p * n_train / world), where=ow),
            Item(name="fp32 gradients of one optimizer sub-group", gib=_gib(4 * min(ZERO3_SUB_GROUP, n_train / world)),
                 where=ow),
            Item(name="ZeRO-3 gathered module + prefetch + reduce bucket",
                 gib=_gib(bytes_p * (a.vocab_size * a.hidden_size + ZERO3_PREFETCH) + 2 * ZERO3_REDUCE_BUCKET),
                 where="gpu"),
        ]
        acts = training_activation_bytes(a, lc.optim.micro_batch_size, seq, lc.logprob_chunk_size, checkpointing)
        out += [Item(name=f"activations: {k}", gib=_gib(v), where="gpu") for k, v in acts.items()]
        return out

    def gpu_need(items: list[Item]) -> float:
        return sum(i.gib for i in items if i.where == "gpu")

    items = items_for(ds.world_size, ds.offload_param, ds.offload_optimizer, lc.gradient_checkpointing)
    on_gpu = lc.device == "cuda"
    need = gpu_need(items) if on_gpu else 0.0
    host = sum(i.gib for i in items if i.where == "host") if on_gpu else sum(i.gib for i in items)
    problems: list[str] = []
    notes: list[str] = []
    fits = need <= budget
    if on_gpu and not fits:
        fixes = []
        if not lc.gradient_checkpointing and gpu_need(items_for(ds.world_size, ds.offload_param, ds.offload_optimizer,
                                                                  True)) <= budget:
            fixes.append("turn on learner.gradient_checkpointing")
        if not ds.offload_optimizer and gpu_need(items_for(ds.world_size, ds.offload_param, True,
                                                           lc.gradient_checkpointing)) <= budget:
            fixes.append("turn on learner.deepspeed.offload_optimizer")
        if not ds.offload_param and gpu_need(items_for(ds.world_size, True, ds.offload_optimizer,
                                                       lc.gradient_checkpointing)) <= budget:
            fixes.append("turn on learner.deepspeed.offload_param")
        world = smallest_world_size(lambda w: gpu_need(items_for(w, ds.offload_param, ds.offload_optimizer,
                                                                  lc.gradient_checkpointing)), budget, ds.world_size + 1)
        if world is not None:
            fixes.append(f"use {world} ranks (learner.deepspeed.world_size: {world})")
        if lc.optim.micro_batch_size > 1:
            fixes.append("lower learner.optim.micro_batch_size")
        problems.append(f"learner rank needs {need:.1f} GiB of GPU memory, over {budget:.1f} GiB: "
                        + (" or ".join(fixes) if fixes else "shorten rollout.max_prompt_tokens + max_response_tokens "
                                                            "or use a larger GPU"))
    if on_gpu and fits and (ds.offload_optimizer or ds.offload_param):
        lean = items_for(ds.world_size, False, False, lc.gradient_checkpointing)
        if gpu_need(lean) <= budget:
            notes.append(f"fits without offload ({gpu_need(lean):.1f} GiB): DeepSpeed 0.19.8 warns that ZeRO offload "
                         f"with a client optimizer is slow; turn learner.deepspeed.offload_optimizer / offload_param off")
    plan = ActorPlan(actor="learner rank", count=ds.world_size, gpus_each=ds.num_gpus_per_rank,
                     cpus_each=ds.num_cpus_per_rank, items=items, gpu_gib=need, host_gib=host,
                     gpu_budget_gib=budget, fits=fits, notes=notes)
    return plan, problems


def _teacher(cfg: RunConfig, a: Architecture, n: int, budget: float) -> tuple[ActorPlan, list[str]]:
    t = cfg.teacher
    seq = cfg.rollout.max_prompt_tokens + cfg.rollout.max_response_tokens
    bytes_w = 2 if t.dtype == "bfloat16" else 4
    on_gpu = t.device == "cuda"
    shadow_where = "host" if (t.ema_shadow_device == "cpu" or not on_gpu) else "gpu"
    weights_where = "gpu" if on_gpu else "host"
    tokens = t.batch_size * seq

    def items_for(shadow: str, batch: int) -> list[Item]:
        out = [Item(name=f"weights ({t.dtype})", gib=_gib(bytes_w * n), where=weights_where)]
        if t.dtype != "float32":
            out.append(Item(name="EMA shadow (fp32)", gib=_gib(4 * n), where=shadow))
        tok = batch * seq
        out += [
            Item(name="forward working set (one layer)", where=weights_where,
                 gib=_gib(tok * 2 * (2 * a.hidden_size + layer_projection_width(a) + 2 * a.intermediate_size))),
            Item(name="LM-head chunk", where=weights_where,
                 gib=_gib(batch * min(t.logprob_chunk_size, seq) * a.vocab_size * 4 * 2)),
        ]
        return out

    items = items_for(shadow_where, t.batch_size)
    need = sum(i.gib for i in items if i.where == "gpu")
    host = sum(i.gib for i in items if i.where == "host")
    problems: list[str] = []
    notes = [f"scores batches of {t.batch_size} x {seq} tokens ({tokens} tokens)"]
    fits = need <= budget
    if on_gpu and not fits:
        fixes = []
        if shadow_where == "gpu" and sum(i.gib for i in items_for("host", t.batch_size) if i.where == "gpu") <= budget:
            fixes.append("set teacher.ema_shadow_device: cpu")
        for batch in range(t.batch_size - 1, 0, -1):
            if sum(i.gib for i in items_for(shadow_where, batch) if i.where == "gpu") <= budget:
                fixes.append(f"lower teacher.batch_size to {batch}")
                break
        problems.append(f"teacher needs {need:.1f} GiB of GPU memory, over {budget:.1f} GiB: "
                        + (" or ".join(fixes) if fixes else "use a larger GPU"))
    if on_gpu and fits and shadow_where == "host":
        lean = sum(i.gib for i in items_for("gpu", t.batch_size) if i.where == "gpu")
        if lean <= budget:
            notes.append(f"the EMA shadow would fit on the GPU ({lean:.1f} GiB): teacher.ema_shadow_device: model "
                         f"saves the host round trip of each EMA update")
    plan = ActorPlan(actor="teacher", count=1, gpus_each=cfg.ray.teacher_num_gpus, cpus_each=cfg.ray.teacher_num_cpus,
                     items=items, gpu_gib=need, host_gib=host, gpu_budget_gib=budget, fits=fits, notes=notes)
    return plan, problems


def _generator(cfg: RunConfig, a: Architecture, n: int, gpu_gib: float) -> tuple[ActorPlan, list[str]]:
    g = cfg.generator
    seq = cfg.rollout.max_prompt_tokens + cfg.rollout.max_response_tokens
    max_len = int(g.options.get("max_model_len") or seq)
    util = float(g.options.get("gpu_memory_utilization", 0.9))
    weights = _gib(2 * n)
    kv_token = kv_bytes_per_token(a)
    state = linear_state_bytes_per_sequence(a)
    per_seq = _gib(kv_token * max_len + state)
    room = util * gpu_gib - weights
    items = [Item(name="weights (bf16)", gib=weights, where="gpu"),
             Item(name=f"KV cache + state ({util:.2f} x memory - weights)", gib=max(room, 0.0), where="gpu")]
    notes = [f"KV per token {kv_token / 1024:.0f} KiB over {a.full_attention_layers} full-attention layers; "
             f"linear-attention state {state / MIB:.1f} MiB per sequence over {a.linear_attention_layers} layers; "
             f"{per_seq:.2f} GiB per {max_len}-token sequence"]
    problems: list[str] = []
    fits = True
    if g.backend == "vllm" and g.num_gpus > 0:
        concurrent = int(room // per_seq) if room > 0 else 0
        notes.append(f"{concurrent} full-length sequences at once (max_batch_size {g.max_batch_size}; vLLM preempts "
                     f"past the cache, shorter sequences share it)")
        if concurrent < 1:
            fits = False
            problems.append(f"generator: {util:.2f} x {gpu_gib:.1f} GiB leaves {room:.1f} GiB after the weights, under one "
                            f"{max_len}-token sequence's {per_seq:.2f} GiB: raise generator.options.gpu_memory_utilization "
                            f"or lower generator.options.max_model_len")
    plan = ActorPlan(actor="generator (vLLM)" if g.backend == "vllm" else "generator (HF)", count=g.num_generators,
                     gpus_each=g.num_gpus, cpus_each=g.num_cpus, items=items,
                     gpu_gib=weights + max(room, 0.0) if g.num_gpus > 0 else 0.0,
                     host_gib=0.0 if g.num_gpus > 0 else weights, gpu_budget_gib=util * gpu_gib, fits=fits, notes=notes)
    return plan, problems


def linear_attention_kernels(a: Architecture) -> str:
    """Which GatedDeltaNet implementation transformers will run on the learner and the teacher."""
    if not a.linear_attention_layers:
        return "no linear-attention layers"
    here = importlib.util.find_spec("fla") is not None
    return (f"{a.linear_attention_layers} GatedDeltaNet layers: the chunked delta rule runs flash-linear-attention's "
            f"Triton kernel when `fla` imports (cluster.yaml installs flash-linear-attention into the learner's venv; "
            f"{'present' if here else 'absent'} on this machine), else transformers' Python loop over 64-token "
            f"chunks; the causal conv1d runs torch's conv (the causal-conv1d package compiles CUDA at install and "
            f"is not installed)")


def plan_run(cfg: RunConfig, gpu: str | None = None, architecture: Architecture | None = None) -> Plan:
    """The memory and capacity plan of `cfg` on `gpu` (default: cfg.cluster.gpu).

    Raises:
        ValueError: an unknown GPU kind, or a model whose architecture cannot be found.
    """
    cluster = cfg.cluster
    kind = gpu or cluster.gpu
    if kind not in GPUS:
        raise ValueError(f"--gpu {kind!r}: unknown GPU kind; known: {', '.join(GPUS)}")
    gpu_gib = GPUS[kind].memory_mib / 1024
    budget = GPU_HEADROOM * gpu_gib
    a = architecture or resolve_architecture(cfg)
    n_text = text_parameters(a)
    n = n_text + a.vision_params
    n_train = n if cfg.learner.train_vision_tower else n_text
    seq = cfg.rollout.max_prompt_tokens + cfg.rollout.max_response_tokens

    actors: list[ActorPlan] = []
    problems: list[str] = []
    learner, p = _learner(cfg, a, n, n_train, budget)
    actors.append(learner)
    problems += p
    generator, p = _generator(cfg, a, n, gpu_gib)
    actors.append(generator)
    problems += p
    if cfg.teacher.enabled:
        teacher, p = _teacher(cfg, a, n, budget)
        actors.append(teacher)
        problems += p

    gpus = sum(x.count * x.gpus_each for x in actors) + cfg.ray.learner_num_gpus
    cpus = (sum(x.count * x.cpus_each for x in actors) + cfg.ray.learner_num_cpus
            + cfg.kb.replicas * cfg.kb.num_cpus * cfg.kb.service)
    nodes = max(1, math.ceil(gpus / cluster.gpus_per_node), math.ceil(cpus / cluster.cpus_per_node))
    host_per_node = sum(x.count * x.host_gib for x in actors) / nodes
    if host_per_node > cluster.host_memory_gib:
        problems.append(f"host memory: {host_per_node:.0f} GiB per node (offloaded states, CPU EMA shadow) over "
                        f"cluster.host_memory_gib {cluster.host_memory_gib:.0f}: turn off learner.deepspeed.offload_param "
                        f"or use nodes with more memory")

    # The run checkpoint: bf16 policy, each rank's fp32 master and Adam moments, the teacher's weights.
    size = 2 * n + 12 * n_train
    if cfg.teacher.enabled:
        size += 4 * n
    size_gib = _gib(size)
    minutes = size / (cluster.checkpoint_volume_mib_s * MIB) / 60
    interval = cfg.trainer.checkpoint_interval
    steps = cfg.trainer.max_steps
    writes = (steps // interval if interval else 0) + (0 if interval and steps % interval == 0 else 1)
    checkpoint = CheckpointPlan(size_gib=size_gib, volume_mib_s=cluster.checkpoint_volume_mib_s, write_minutes=minutes,
                                interval_steps=interval, writes=writes)
    return Plan(config_name=cfg.name, gpu=f"{kind} ({GPUS[kind].name}, {gpu_gib:.1f} GiB)", gpu_memory_gib=gpu_gib,
                architecture_source=a.source, parameters=n, trainable_parameters=n_train, sequence_tokens=seq,
                actors=actors, gpus=gpus, cpus=cpus, nodes=nodes, host_gib_per_node=host_per_node,
                checkpoint=checkpoint, linear_attention_kernels=linear_attention_kernels(a), problems=problems)


def format_plan(plan: Plan) -> str:
    """The plan as text, one block per actor."""
    lines = [f"plan of {plan.config_name} on {plan.gpu} (fits when an actor's GPU total <= "
             f"{GPU_HEADROOM:.0%} of memory)",
             f"model: {plan.parameters / 1e9:.3f} B parameters ({plan.trainable_parameters / 1e9:.3f} B trained), "
             f"from {plan.architecture_source}; sequence {plan.sequence_tokens} tokens"]
    for actor in plan.actors:
        lines.append(f"\n{actor.actor} x{actor.count} ({actor.gpus_each:g} GPU, {actor.cpus_each:g} CPU each): "
                     f"GPU {actor.gpu_gib:.1f} / {actor.gpu_budget_gib:.1f} GiB, host {actor.host_gib:.1f} GiB"
                     f"{'' if actor.fits else '  DOES NOT FIT'}")
        lines += [f"  {item.where:4} {item.gib:8.2f} GiB  {item.name}" for item in actor.items]
        lines += [f"  note: {note}" for note in actor.notes]
    c = plan.checkpoint
    lines += [
        f"\nresources: {plan.gpus:g} GPUs, {plan.cpus:g} CPUs -> {plan.nodes} node(s); host memory "
        f"{plan.host_gib_per_node:.0f} GiB per node",
        f"checkpoint: {c.size_gib:.1f} GiB, {c.write_minutes:.1f} min at {c.volume_mib_s:g} MiB/s, "
        f"every {c.interval_steps or 'end-of-run'} steps ({c.writes} writes)",
        f"linear attention: {plan.linear_attention_kernels}",
    ]
    lines += ["\nDOES NOT FIT:"] + [f"  - {p}" for p in plan.problems] if plan.problems else ["\nfits."]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# The node check of cluster.yaml's setup
# ---------------------------------------------------------------------------------------------

#: Minimum Linux driver of each CUDA build the pinned torch wheel may be (NVIDIA's CUDA toolkit /
#: driver table: CUDA 13.0 GA needs >= 580.65.06). The torch 2.13.0 wheel on PyPI is a CUDA 13.0 build
#: (its metadata requires the CUDA 13 runtime and NCCL cu13).
MIN_DRIVER_FOR_CUDA: dict[str, str] = {"13.0": "580.65.06"}


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.strip().split(".") if part.isdigit())


def driver_problem(torch_cuda: str | None, driver: str | None) -> str | None:
    """Why a node's NVIDIA driver cannot run torch's CUDA build, or None when it can."""
    if torch_cuda is None:
        return "torch is a CPU build (torch.version.cuda is None): install the CUDA wheel (PyPI's torch==2.13.0)"
    key = ".".join(torch_cuda.split(".")[:2])
    needed = MIN_DRIVER_FOR_CUDA.get(key)
    if driver is None:
        return (f"no NVIDIA driver found (nvidia-smi missing or failing); torch's CUDA {torch_cuda} build needs driver "
                f">= {needed or 'the one in NVIDIA CUDA compatibility table'}")
    if needed is not None and _version(driver) < _version(needed):
        return f"NVIDIA driver {driver} is older than {needed}, the minimum for torch's CUDA {torch_cuda} build"
    return None


def check_gpu_node() -> str:
    """cluster.yaml's setup check: torch sees a GPU (else: the driver found and the one needed) and a C
    compiler is on PATH (Triton and DeepSpeed's JIT ops build with it). Returns a one-line summary.

    Raises:
        SystemExit: naming what is missing.
    """
    import shutil
    import subprocess

    import torch

    problems = []
    if not torch.cuda.is_available():
        try:
            out = subprocess.run(["nvidia-smi", "--query-gpu=driver_version", "--format=csv,noheader"],
                                 capture_output=True, text=True, timeout=60, check=True).stdout.split()
            driver = out[0] if out else None
        except (OSError, subprocess.SubprocessError):
            driver = None
        problems.append(driver_problem(torch.version.cuda, driver)
                        or f"torch {torch.__version__} sees no GPU although driver {driver} supports CUDA {torch.version.cuda}")
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        problems.append("no C compiler on PATH (Triton compiles its launcher with it): apt-get install build-essential")
    if problems:
        raise SystemExit("GPU node check failed: " + "; ".join(problems))
    return f"torch {torch.__version__} CUDA {torch.version.cuda}, {torch.cuda.device_count()} GPU(s)"
