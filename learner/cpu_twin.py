"""Rehearse a GPU cluster config on a CPU machine: the same run, on the model's tiny twin.

`hcgym train --config configs/qwen35_9b_ttopd.yaml --cpu-twin` (or `python -m learner.train ...
--cpu-twin`) loads the shipped config, applies the one documented set of hardware overrides below
(`CPU_TWIN_OVERRIDES`: dotted key -> CPU value -> reason) and trains on this machine. Every other
key runs as shipped: the learner backend and its world size (the DeepSpeed ranks stay separate Ray
actors over gloo), ZeRO stage, parameter and optimizer offload, gradient checkpointing, dtypes,
micro-batches, the loss, the teacher with its hints and EMA schedule, the reward, the vLLM generator
backend (its CPU build, `.venv-vllm`) and the collective weight sync. What breaks here would break
on the cluster, before the first GPU hour is paid for.

Two kinds of override, each with its reason:
- hardware: devices, NCCL, GPU and per-actor CPU reservations, node paths, the cluster address;
- scaled: lengths, batch and counts that a CPU cannot run at production size in minutes;
- twin: what a randomly initialised policy cannot do that a trained one does (end a turn early).

`twin_config(shipped, model_dir)` applies the table to a loaded `RunConfig`; `config_diff(a, b)`
gives the dotted keys in which two configs differ (tests/training/test_gpu_config_twins.py holds the
diff between every shipped GPU config and its twin equal to this table). A config key that only
works on GPUs must be added here with its reason, or the test fails when a shipped config sets it.

Example:
    >>> from learner.config import load_config
    >>> twin = twin_config(load_config("configs/qwen35_9b_grpo.yaml"), model_dir="/tmp/twin")
    >>> twin.learner.device, twin.weight_sync.backend, twin.learner.deepspeed.world_size
    ('cpu', 'gloo', 4)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, Literal

from pydantic import BaseModel, ConfigDict

from learner.config import RunConfig, validate_config

#: Stands for the twin model folder in the table (`twin_config`'s `model_dir`).
TWIN_MODEL = "<tiny twin of model.path>"


Condition = Literal["always", "vllm", "no_vllm_cpu"]
Kind = Literal["hardware", "scaled", "twin"]


class TwinOverride(BaseModel):
    """One documented difference between a shipped GPU config and its CPU twin.

    `when`: "always"; "vllm": the twin runs the vLLM generator; "no_vllm_cpu": the shipped config
    runs vLLM but vLLM's CPU build cannot start the twin's architecture (`VLLM_CPU_UNSUPPORTED`).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    key: str
    value: Any
    kind: Kind
    reason: str
    when: Condition = "always"


def _o(key: str, value: Any, kind: Kind, reason: str, when: Condition = "always") -> TwinOverride:
    return TwinOverride(key=key, value=value, kind=kind, reason=reason, when=when)


#: Architectures vLLM's CPU build (vllm-cpu 0.32) cannot start, with the reason. On GPU nodes they run.
VLLM_CPU_UNSUPPORTED: dict[str, str] = {
    "Qwen3_5ForConditionalGeneration": (
        "vLLM's qwen3_5 module imports transformers' Qwen2-VL image processor, which imports torchvision, "
        "whose only registry build is CUDA (fails against torch +cpu; actors/README.md)"),
}


# Scaled lengths: a random twin writes until its token limits, so these set each episode's cost.
_RESPONSE_TOKENS = 256
_TURN_TOKENS = 16

#: The overrides, in the order they are applied. Values replace the shipped ones (or add the key).
CPU_TWIN_OVERRIDES: tuple[TwinOverride, ...] = (
    # --- hardware -------------------------------------------------------------------------------
    _o("model.path", TWIN_MODEL, "hardware",
       "the shipped model's tiny twin (modeling.model.build_twin_model): its architecture class and module "
       "layout (Qwen3.5: hybrid linear/full attention, vision tower) at hidden size 128 and 2 layers"),
    _o("learner.device", "cpu", "hardware", "a CPU machine has no GPU"),
    _o("teacher.device", "cpu", "hardware", "a CPU machine has no GPU"),
    _o("weight_sync.backend", "gloo", "hardware", "NCCL needs GPUs; the same collective code path over gloo"),
    _o("generator.num_gpus", 0, "hardware", "a CPU machine has no GPU"),
    _o("learner.deepspeed.num_gpus_per_rank", 0, "hardware", "a CPU machine has no GPU (the ranks stay one Ray actor each)"),
    _o("ray.teacher_num_gpus", 0, "hardware", "a CPU machine has no GPU"),
    _o("generator.num_cpus", 0, "hardware",
       "the GPU nodes reserve cores per engine; here every actor shares the machine's cores"),
    _o("learner.deepspeed.num_cpus_per_rank", 0.25, "hardware",
       "the GPU nodes reserve 4 cores per rank; here the ranks share the machine's cores (a placement-group "
       "bundle must ask for something: 4 ranks x 0.25 + the learner's 1 fit a 2-core machine)"),
    _o("ray.teacher_num_cpus", 0, "hardware", "the teacher shares the machine's cores"),
    _o("ray.address", None, "hardware", "'auto' joins the cluster's head; the twin starts a local Ray"),
    _o("generator.python_executable", "auto", "hardware",
       "the nodes' vLLM venv path; here vLLM's CPU build in .venv-vllm (`make vllm-cpu`)"),
    _o("generator.options.gpu_memory_utilization", 0.1, "hardware",
       "vLLM's CPU build reads it as a share of host RAM and refuses to start when that much is not free",
       when="vllm"),
    _o("generator.backend", "hf", "hardware",
       "vLLM's CPU build cannot start this architecture (VLLM_CPU_UNSUPPORTED); the HF generator samples "
       "from the same folder with the same weight names", when="no_vllm_cpu"),
    _o("generator.options", {"dtype": "bfloat16"}, "hardware",
       "the HF generator's options (the vLLM-only ones go with the backend), in the shipped dtype",
       when="no_vllm_cpu"),
    _o("learner.deepspeed.skip_shm_build", True, "hardware",
       "DeepSpeed's CPU accelerator JIT-builds a shared-memory comm op (70-100 s); GPUs never build it"),
    # --- scaled ---------------------------------------------------------------------------------
    _o("rollout.max_response_tokens", _RESPONSE_TOKENS, "scaled",
       "L_max 12288 -> 256: a random twin writes until its limits; room for several turns with tool results"),
    _o("rollout.max_new_tokens_per_turn", _TURN_TOKENS, "scaled", "4096 -> 16 (CPU decoding)"),
    _o("rollout.system_prompt", "compact", "scaled",
       "the env prompt's JSON tool schemas are ~6,200 tokens in the twin's 2,048-token vocabulary, in every "
       "forward of learner, reference, teacher and generator; the compact prompt lists the same tools in one "
       "line each"),
    _o("reward.max_length", _RESPONSE_TOKENS, "scaled", "Eq. 4's length scale follows L_max, as shipped"),
    _o("learner.loss.distill.max_turn_tokens", _RESPONSE_TOKENS, "scaled",
       "the turn-truncation bound follows L_max, as shipped"),
    _o("generator.num_generators", 1, "scaled",
       "each vLLM CPU engine is a process with its own KV cache (~25 s start); one serves a CPU machine"),
    _o("rollout.num_env_actors", 2, "scaled", "8 env processes would only compete for a CPU machine's cores"),
    _o("trainer.batch_size", 2, "scaled", "8 groups of 3 episodes per step -> 2 (CPU time per step)"),
    _o("trainer.max_steps", 2, "scaled", "a rehearsal: two steps run the per-step paths (rollouts, learner, weight sync, teacher scoring, final "
       "checkpoint and validation); the teacher's first EMA (step 5) is past it"),
    _o("learner.loss.distill.drop_length_truncated_turns", False, "twin",
       "a random twin almost never ends a turn before its token limit: every turn would be dropped and the "
       "distillation term (Eq. 2) would never run"),
    _o("data.max_train_tasks", 32, "scaled", "the prompt-length filter reads every train task at start"),
    _o("data.max_val_tasks", 2, "scaled", "validation at start and end would run the whole test split"),
    _o("rollout.env_vars.HCGYM_EMBEDDINGS", "0", "scaled",
       "grade free text by token overlap: a sentence-embedding model load costs ~16 s per env process"),
)


def override_table() -> dict[str, TwinOverride]:
    """The overrides by dotted key."""
    return {o.key: o for o in CPU_TWIN_OVERRIDES}


def flatten(data: Any, prefix: str = "") -> dict[str, Any]:
    """Dotted keys of a nested mapping (lists and other values are leaves): {"a": {"b": 1}} -> {"a.b": 1}."""
    if isinstance(data, dict):  # an empty mapping adds no key: {} and absent are the same setting
        out: dict[str, Any] = {}
        for key, value in data.items():
            out.update(flatten(value, f"{prefix}.{key}" if prefix else str(key)))
        return out
    return {prefix: data} if prefix else {}


def _set(data: dict, dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    node = data
    for key in keys[:-1]:
        node = node.setdefault(key, {})
    node[keys[-1]] = value


#: GPU settings a twin keeps as shipped because training never reads them, with the reason.
INERT_GPU_KEYS: dict[str, str] = {
    "cluster": "the nodes `hcgym plan` sizes the run for (modeling/plan.py); training reads none of it",
}


def gpu_residue(cfg: RunConfig) -> list[str]:
    """`key: value` for every setting that asks for a GPU and is neither in the table nor inert: a
    device or collective backend named cuda / nccl, or a `*gpu*` key above 0."""
    table = {o.key for o in CPU_TWIN_OVERRIDES} | set(INERT_GPU_KEYS)
    found = []
    for key, value in flatten(cfg.model_dump(mode="json")).items():
        if any(key == k or key.startswith(k + ".") for k in table):
            continue
        if isinstance(value, str) and value.lower() in ("cuda", "nccl"):
            found.append(f"{key}: {value}")
        elif ("gpu" in key.rsplit(".", 1)[-1] and isinstance(value, (int, float)) and not isinstance(value, bool)
              and value > 0):
            found.append(f"{key}: {value}")
    return found


def config_diff(a: RunConfig, b: RunConfig) -> dict[str, tuple[Any, Any]]:
    """Dotted key -> (value in a, value in b) for every key in which the two configs differ."""
    fa, fb = flatten(a.model_dump(mode="json")), flatten(b.model_dump(mode="json"))
    return {k: (fa.get(k), fb.get(k)) for k in sorted(fa.keys() | fb.keys()) if fa.get(k) != fb.get(k)}


def model_architecture(model_dir: str | Path) -> str:
    """`config.architectures[0]` of a model folder."""
    return json.loads((Path(model_dir) / "config.json").read_text())["architectures"][0]


def applicable_overrides(shipped: RunConfig, model_dir: str | Path) -> list[TwinOverride]:
    """The table's overrides that apply to `shipped` run on the twin in `model_dir`, in order."""
    no_vllm_cpu = shipped.generator.backend == "vllm" and model_architecture(model_dir) in VLLM_CPU_UNSUPPORTED
    vllm = shipped.generator.backend == "vllm" and not no_vllm_cpu
    wanted = {"always": True, "vllm": vllm, "no_vllm_cpu": no_vllm_cpu}
    return [o for o in CPU_TWIN_OVERRIDES if wanted[o.when]]


def twin_config(shipped: RunConfig, model_dir: str | Path, *, output_dir: str | Path | None = None,
                source: str = "<cpu twin>") -> RunConfig:
    """The CPU twin of a shipped config: the applicable `CPU_TWIN_OVERRIDES`, everything else as shipped.

    Args:
        shipped: The loaded GPU config.
        model_dir: The twin model folder (`build_cpu_twin_model` or `modeling.model.build_twin_model`),
            written as `model.path`.
        output_dir: The run folder, if not the shipped one.
        source: Named in validation errors.

    Raises:
        learner.config.ConfigError: when the twin does not validate (naming the key).
        ValueError: naming each GPU setting left in the twin that the table does not override.
    """
    data = shipped.model_dump(mode="json", exclude_unset=False)
    for override in applicable_overrides(shipped, model_dir):
        _set(data, override.key, str(model_dir) if override.value == TWIN_MODEL else override.value)
    if output_dir is not None:
        data["output_dir"] = str(output_dir)
    twin = validate_config(data, source)
    residue = gpu_residue(twin)
    if residue:
        raise ValueError(f"{source}: GPU settings the CPU twin does not override: {'; '.join(residue)}; add each to "
                         f"learner/cpu_twin.py CPU_TWIN_OVERRIDES with its CPU value and the reason")
    return twin


def _architecture(cfg: RunConfig) -> str:
    """`config.architectures[0]` of the shipped model: from its folder or the HF cache, else from the hub
    id's name (a laptop need not hold the 9B checkpoint to rehearse its run)."""
    from modeling.hf_checkpoint import resolve_model_path

    path = cfg.model.path or ""
    try:
        config = json.loads((resolve_model_path(path, revision=cfg.model.revision) / "config.json").read_text())
        return config["architectures"][0]
    except (FileNotFoundError, ValueError, KeyError, IndexError):
        pass
    name = path.lower().replace("_", ".")
    for marker, architecture in (("qwen3.5", "Qwen3_5ForConditionalGeneration"), ("qwen3", "Qwen3ForCausalLM"),
                                 ("llama", "LlamaForCausalLM")):
        if marker in name:
            return architecture
    raise ValueError(f"model.path: cannot tell the architecture of {path!r} (no config.json locally or in the "
                     f"Hugging Face cache, and the name matches no twin family)")


def build_cpu_twin_model(cfg: RunConfig, directory: str | Path, *, log: Callable[[str], None] = print) -> Path:
    """The tiny twin of `cfg.model` in `directory` (built once, reused after): a byte-level BPE
    tokenizer trained on the run's domains (system prompts and tickets) and the twin of the shipped
    model's architecture."""
    import time

    from envs import registry
    from envs.env import build_system_prompt, render_ticket
    from actors.agent_loop import compact_system_prompt
    from actors.env_actor import register_domains
    from modeling.model import build_twin_model, train_tokenizer, twin_family

    directory = Path(directory)
    model_dir = directory / "model"
    if (model_dir / "config.json").is_file():
        return model_dir
    if cfg.model.kind != "pretrained":
        raise ValueError("--cpu-twin rehearses a config with model.kind 'pretrained' (a tiny model runs as it is)")
    family = twin_family(_architecture(cfg))
    t0 = time.perf_counter()
    register_domains(cfg.data.domain_modules)
    texts: list[str] = []
    for domain in cfg.data.domains:
        env = registry.get_environment(domain)
        texts += [build_system_prompt(env), compact_system_prompt(env.toolkit.schemas())]
        texts += [render_ticket(t) for t in registry.get_tasks(domain, cfg.data.train_split)[:200]]
    tokenizer = train_tokenizer(texts, 2048, directory / "tokenizer", max_stdlib_files=40)
    build_twin_model(family, directory / "partial", tokenizer, seed=cfg.seed)
    (directory / "partial").rename(model_dir)
    log(f"[cpu twin] {family} twin of {cfg.model.path} built in {time.perf_counter() - t0:.1f}s: {model_dir}")
    return model_dir


def describe() -> str:
    """The table as text (`--cpu-twin` prints it)."""
    width = max(len(o.key) for o in CPU_TWIN_OVERRIDES)
    return "\n".join(f"  {o.key:<{width}} = {json.dumps(o.value)}  [{o.kind}{'' if o.when == 'always' else ', ' + o.when}] "
                     f"{o.reason}" for o in CPU_TWIN_OVERRIDES)
