"""Pydantic configs of the learner side: losses, optimizer, backends, teacher, weight sync.

The driver's top-level `RunConfig` composes these as fields. Every model forbids unknown keys, so a
typo in YAML fails with the key's path instead of silently running the default.
Defaults are the paper's (Appendix D, Table "Training hyperparameters") where it names a value.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import ConfigDict, Field, model_validator

from envs.core.models import StrictModel

KLEstimator = Literal["k1", "k3"]

class ConfigModel(StrictModel):
    """Base of every config section: unknown keys and non-finite numbers (NaN, infinity) are
    errors, also when a section is built in code or re-validated in an actor from a dict."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


# The truncation C of the behaviour weight min(pi_old / mu, C) that runs with max_staleness > 0 get
# by default: 2 as in TIS (Yao et al. 2025) and verl's rollout-correction default; no token of a
# stale batch weighs more than twice what it would on-policy.
OFFPOLICY_TIS_CAP = 2.0


class GRPOConfig(ConfigModel):
    """Eq. 1: clipped group-relative policy gradient plus a KL penalty to a frozen reference."""

    clip_eps_low: float = Field(default=0.2, ge=0, lt=1, description="lower clip range: ratio >= 1 - eps")
    clip_eps_high: float = Field(default=0.2, ge=0, description="upper clip range: ratio <= 1 + eps")
    kl_beta: float = Field(default=0.01, ge=0, description="weight of KL(pi_theta || pi_ref); 0 = no reference model")
    kl_estimator: KLEstimator = "k3"
    # Bound on each token's KL estimate in the loss (verl's low_var_kl uses 10). k3 = r - 1 - log r
    # with r = pi_ref / pi_theta grows like r on a sampled token the policy finds unlikely and the
    # reference likes (the tiny model's KL_ref means of 4-6 nats/token come from a few such tokens).
    # With kl_grad.mode "pathwise" that token's gradient is 1 - r (~1e4): bound it there. The default
    # "unbiased" gradient is -log r, already bounded. None = unbounded.
    kl_clamp: float | None = Field(default=None, gt=0)
    scale_advantages: bool = Field(default=True, description="divide by the group's std (False = Dr.GRPO)")
    advantage_eps: float = Field(default=1e-6, gt=0)
    loss_aggregation: Literal["token_mean", "sequence_mean"] = "token_mean"
    # Weight of negative advantages (1.0 = Eq. 1). A sequence-level advantage blames every token of a
    # failed episode, including the ones it shares with successful episodes (the tool-call syntax,
    # `submit_answer`): on the tiny model, failed episodes' pushes erased `submit_answer` within five
    # steps at lr 3e-4 although submitting episodes had the higher rewards (docs/training.md). Values
    # below 1 trust failures less than successes, as asymmetric REINFORCE does.
    negative_advantage_weight: float = Field(default=1.0, ge=0, le=1)
    # Off-policy correction, losses.py Eq. 1b-1d: every sampled-token term of the loss (policy
    # gradient, KL_ref, k1/k3 distillation) is weighted by w = min(pi_old / mu, tis_cap), mu = the
    # generator's sampling log-probs. It corrects tokens sampled by an older policy version
    # (trainer.max_staleness > 0) and the generator's numerics differing from the learner's (vLLM).
    # None = off. Unless set explicitly, RunConfig sets it to OFFPOLICY_TIS_CAP whenever
    # trainer.max_staleness > 0; write `tis_cap: null` to train a stale run uncorrected.
    tis_cap: float | None = Field(default=None, gt=0)


class DistillConfig(ConfigModel):
    """Eq. 2-3: turn-level truncated on-policy distillation toward the (EMA) teacher."""

    enabled: bool = False
    lambda_distill: float = Field(default=4.0, ge=0)
    # k1 / k3: per-token estimates from the sampled tokens' log-probs (the default, what the teacher
    # serves cheaply); topk: exact KL over the teacher's top-k tokens plus one tail bucket.
    estimator: Literal["k1", "k3", "topk"] = "k1"
    topk: int = Field(default=20, ge=1, description="teacher top-k size when estimator = topk")
    max_turn_tokens: int = Field(default=12_288, ge=1, description="L_max: turns ending beyond it are dropped")
    # What L_max is measured on: "response" = tokens after the prompt up to the turn's end (generated
    # plus tool tokens), "generated" = the episode's assistant tokens so far, "context" = absolute
    # position including the prompt.
    truncation_basis: Literal["response", "generated", "context"] = "response"
    drop_length_truncated_turns: bool = Field(
        default=True, description="also drop turns the generator cut at its token limit (TurnSpan.truncated)"
    )
    # Eq. 2 sums the per-turn means over turns; "mean" divides by the number of kept turns.
    turn_reduction: Literal["sum", "mean"] = "sum"


class KLGradConfig(ConfigModel):
    """How sampled-token KL estimates are differentiated (applies to KL_ref and the distillation KL).

    "unbiased": value of the estimator plus a score-function term, so the gradient is the gradient
    of E_{x~pi_theta}[estimate] = KL(pi_theta || pi_other) (the k1 estimate alone has zero expected
    gradient). "pathwise": differentiate the estimate's value only (the GRPO/DeepSeek k3 convention).
    """

    mode: Literal["unbiased", "pathwise"] = "unbiased"


class LossConfig(ConfigModel):
    grpo: GRPOConfig = Field(default_factory=GRPOConfig)
    distill: DistillConfig = Field(default_factory=DistillConfig)
    kl_grad: KLGradConfig = Field(default_factory=KLGradConfig)
    entropy_coef: float = Field(default=0.0, ge=0, description="entropy bonus (0 = only logged)")


class OptimConfig(ConfigModel):
    # Upper bounds catch typos (`lr: 5e7` for 5e-7): Adam steps of size ~lr per weight, so past 1 a
    # single update rewrites the model.
    lr: float = Field(default=5e-7, gt=0, le=1)
    weight_decay: float = Field(default=0.0, ge=0, le=1)
    betas: tuple[Annotated[float, Field(ge=0, lt=1)], Annotated[float, Field(ge=0, lt=1)]] = (0.9, 0.999)
    eps: float = Field(default=1e-8, gt=0, le=1)
    max_grad_norm: float = Field(default=1.0, gt=0)
    micro_batch_size: int = Field(default=1, ge=1, description="samples per forward/backward (at most, with "
                                                                  "max_tokens_per_micro_batch)")
    max_tokens_per_micro_batch: int | None = Field(
        default=None, ge=1, description="split each rank's samples into micro-batches of at most this many tokens "
                                        "(a longer sample is a micro-batch alone), up to micro_batch_size samples each; "
                                        "null: micro_batch_size samples. The loss normalisation is the whole batch's")
    updates_per_batch: int = Field(default=1, ge=1, description="optimizer steps per batch (clipping matters when > 1)")


class DeepSpeedConfig(ConfigModel):
    """DeepSpeed ZeRO-3. On CPU it runs with gloo; `world_size` ranks are separate Ray actors."""

    zero_stage: Literal[1, 2, 3] = 3
    world_size: int = Field(default=1, ge=1)
    num_cpus_per_rank: float = Field(default=1.0, ge=0)
    num_gpus_per_rank: float = Field(default=0.0, ge=0)
    offload_optimizer: bool = False
    offload_param: bool = False
    master_addr: str = "127.0.0.1"
    master_port: int | None = Field(default=None, description="None = pick a free port")
    # Skip the 70-100 s JIT build of DeepSpeed's shared-memory comm op on CPU (stack notes 4).
    skip_shm_build: bool = True
    timeout_s: float = Field(default=600.0, gt=0, description="torch.distributed collective timeout")


class LearnerConfig(ConfigModel):
    backend: Literal["torch", "deepspeed"] = "torch"
    dtype: Literal["float32", "bfloat16"] = "float32"
    device: Literal["cpu", "cuda"] = "cpu"
    temperature: float = Field(default=1.0, gt=0, description="the generator's sampling temperature")
    gradient_checkpointing: bool = False
    logprob_chunk_size: int = Field(default=1024, ge=1)
    pack_sequences: bool = Field(
        default=True, description="run the policy, reference and pi_old forwards on each micro-batch's real tokens "
                                  "only (sequences packed into one row, position ids restarting per sequence); a model "
                                  "with recurrent layers (Qwen3.5's linear attention) runs padded")
    loss: LossConfig = Field(default_factory=LossConfig)
    optim: OptimConfig = Field(default_factory=OptimConfig)
    deepspeed: DeepSpeedConfig = Field(default_factory=DeepSpeedConfig)
    reference_model_dir: str | None = Field(default=None, description="frozen KL reference; None = the initial policy")
    # Multimodal checkpoints (Qwen3.5, Qwen2.5-VL): the language model always trains; the vision
    # tower (`model.visual.*`) stays frozen unless this is set. No effect on text-only models.
    train_vision_tower: bool = False

    @model_validator(mode="after")
    def _consistent(self) -> LearnerConfig:
        if self.backend == "torch" and self.deepspeed.world_size != 1:
            raise ValueError("learner.deepspeed.world_size > 1 needs learner.backend = 'deepspeed'")
        if self.device == "cuda" and self.deepspeed.world_size > 1 and self.deepspeed.num_gpus_per_rank <= 0:
            raise ValueError("learner.deepspeed.num_gpus_per_rank must be > 0 when learner.device is 'cuda' "
                             "and world_size > 1 (each rank actor needs its GPU)")
        return self


class HintConfig(ConfigModel):
    """Outcome-conditioned privileged hints (Sec. 4.2)."""

    enabled: bool = True
    reinforcing: str = "Privileged feedback: this attempt's reasoning appears sound and reaches the correct answer."
    corrective: str = "Privileged feedback: this attempt is incorrect; revisit the differential diagnosis and the evidence."
    # How a hint is rendered into tokens; {hint} is replaced. A system turn of its own keeps the
    # ChatML layout valid for the teacher.
    template: str = "<|im_start|>system\n{hint}<|im_end|>\n"
    # Insert before the prompt's trailing generation prompt ("<|im_start|>assistant\n") when the
    # prompt ends with it, so the hint sits between the last prompt turn and the response header;
    # otherwise exactly at prompt_length.
    before_generation_prompt: bool = True
    # Which trajectories count as correct: the sample's `correct` flag (set by the driver from the
    # grader), or the reference's rule "reward > threshold".
    correctness_rule: Literal["correct_flag", "reward_above"] = "correct_flag"
    # Must lie inside the run's reward range (checked by RunConfig), else every trajectory gets the same hint.
    reward_threshold: float = 0.0

    @model_validator(mode="after")
    def _template_has_slot(self) -> HintConfig:
        if "{hint}" not in self.template:
            raise ValueError("teacher.hints.template must contain {hint}, where the hint text is inserted")
        return self


class TeacherConfig(ConfigModel):
    """The EMA teacher actor (Sec. 4.2 "Stability mechanisms", Algorithm 1)."""

    enabled: bool = False
    ema_alpha: float = Field(default=0.995, ge=0, le=1)
    ema_interval: int = Field(default=5, ge=0, description="EMA every N learner steps; 0 = never")
    hard_copy_interval: int = Field(default=30, ge=0, description="theta_T <- theta_S every M steps; 0 = never")
    hints: HintConfig = Field(default_factory=HintConfig)
    serve_topk: int = Field(default=0, ge=0, description="also return the teacher's top-k per position (0 = off)")
    batch_size: int = Field(default=4, ge=1, description="samples per teacher forward (at most, with "
                                                          "max_tokens_per_batch)")
    max_tokens_per_batch: int | None = Field(default=None, ge=1, description="teacher forwards of at most this many "
                                                                             "sample tokens (a longer sample alone)")
    temperature: float = Field(default=1.0, gt=0)
    dtype: Literal["float32", "bfloat16"] = "float32"
    device: Literal["cpu", "cuda"] = "cpu"
    logprob_chunk_size: int = Field(default=1024, ge=1)
    pack_sequences: bool = Field(
        default=False, description="the teacher's forwards on real tokens only (as learner.pack_sequences). Off by "
                                   "default: the teacher batches samples in arrival order, and a packed row's values "
                                   "move at float rounding with its neighbours, so runs and resumes would differ in "
                                   "the last bits; padded rows do not")
    # Where the fp32 EMA master lives when the teacher computes in bf16 (4 bytes per parameter: 38 GB
    # for a 9B model beside its 19 GB of bf16 weights): "model" = the teacher's device, "cpu" = host
    # memory, leaving the GPU to the scoring forward; `hcgym plan` says which one fits.
    ema_shadow_device: Literal["model", "cpu"] = "model"


def teacher_update_action(step: int, config: TeacherConfig) -> Literal["hard_copy", "ema", "none"]:
    """What the teacher does after learner step `step` (1-based): hard copy wins over EMA on ties.

    Args:
        step: The learner step just completed (>= 1).
        config: Teacher schedule.
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    if config.hard_copy_interval and step % config.hard_copy_interval == 0:
        return "hard_copy"
    if config.ema_interval and step % config.ema_interval == 0:
        return "ema"
    return "none"


class WeightSyncConfig(ConfigModel):
    """Learner -> generators / teacher weight transfer."""

    transport: Literal["object_store", "collective"] = "object_store"
    # The collective backend when every member has a GPU of its own; gloo with the buckets staged
    # through CPU memory whenever a member is on the CPU or two members share a GPU (decided from
    # the members' device identities at join: modeling.weight_sync.choose_transport).
    backend: Literal["nccl", "gloo"] = "nccl"
    bucket_mb: float = Field(default=512.0, gt=0, description="size cap of one broadcast bucket")
    # One limit for a weight sync, whichever transport: a collective broadcast, or a generator loading a
    # pushed state dict from the object store.
    timeout_s: float = Field(default=120.0, gt=0, description="seconds a weight sync may take")
    master_addr: str = "127.0.0.1"
    master_port: int | None = None
