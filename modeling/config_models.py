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
    kl_estimator: KLEstimator = Field(default="k3", description="per-token estimate of KL(pi_theta || pi_ref): "
                                                                "k1 = log-ratio, k3 = r - 1 - log r")
    # verl's low_var_kl bounds at 10. k3 = r - 1 - log r
    # with r = pi_ref / pi_theta grows like r on a sampled token the policy finds unlikely and the
    # reference likes (the tiny model's KL_ref means of 4-6 nats/token come from a few such tokens).
    # With kl_grad.mode "pathwise" that token's gradient is 1 - r (~1e4): bound it there. The default
    # "unbiased" gradient is -log r, already bounded.
    kl_clamp: float | None = Field(default=None, gt=0, description="bound on each token's KL_ref estimate in the loss; "
                                                                     "null = unbounded")
    scale_advantages: bool = Field(default=True, description="divide by the group's std (False = Dr.GRPO)")
    advantage_eps: float = Field(default=1e-6, gt=0, description="added to the group's reward std before dividing by it")
    loss_aggregation: Literal["token_mean", "sequence_mean"] = Field(
        default="token_mean", description="token_mean: mean over the batch's response tokens; sequence_mean: mean per "
                                          "sequence, then over the batch's sequences")
    # A sequence-level advantage blames every token of a
    # failed episode, including the ones it shares with successful episodes (the tool-call syntax,
    # `submit_answer`): on the tiny model, failed episodes' pushes erased `submit_answer` within five
    # steps at lr 3e-4 although submitting episodes had the higher rewards (docs/training.md). Values
    # below 1 trust failures less than successes, as asymmetric REINFORCE does.
    negative_advantage_weight: float = Field(default=1.0, ge=0, le=1, description="weight of negative advantages "
                                                                                   "(1.0 = Eq. 1)")
    # Off-policy correction, losses.py Eq. 1b-1d; mu = the generator's sampling log-probs. It corrects
    # tokens sampled by an older policy version (trainer.max_staleness > 0) and the generator's
    # numerics differing from the learner's (vLLM).
    tis_cap: float | None = Field(
        default=None, gt=0,
        description="cap C of the weight min(pi_old / mu, C) on every sampled-token loss term (policy gradient, "
                    "KL_ref, k1/k3 distillation); null = off; unset with trainer.max_staleness > 0: 2.0 (write null "
                    "to keep it off)")


class DistillConfig(ConfigModel):
    """Eq. 2-3: turn-level truncated on-policy distillation toward the (EMA) teacher."""

    enabled: bool = Field(default=False, description="add the distillation term toward the teacher (needs "
                                                     "teacher.enabled)")
    lambda_distill: float = Field(default=4.0, ge=0, description="weight of the distillation term in the loss")
    # k1 is the default: what the teacher serves cheaply.
    estimator: Literal["k1", "k3", "topk"] = Field(
        default="k1", description="k1 / k3: per-token estimates from the sampled tokens' log-probs; topk: exact KL "
                                  "over the teacher's top-k tokens plus one tail bucket")
    topk: int = Field(default=20, ge=1, description="teacher top-k size when estimator = topk")
    max_turn_tokens: int = Field(default=12_288, ge=1, description="L_max: turns ending beyond it are dropped")
    truncation_basis: Literal["response", "generated", "context"] = Field(
        default="response", description="what L_max is measured on: response = tokens after the prompt up to the turn's "
                                        "end (generated plus tool tokens), generated = the episode's assistant tokens "
                                        "so far, context = absolute position including the prompt")
    drop_length_truncated_turns: bool = Field(
        default=True, description="also drop turns the generator cut at its token limit (TurnSpan.truncated)"
    )
    turn_reduction: Literal["sum", "mean"] = Field(
        default="sum", description="sum: the per-turn means summed over turns (Eq. 2); mean: divided by the number "
                                   "of kept turns")


class KLGradConfig(ConfigModel):
    """How sampled-token KL estimates are differentiated (applies to KL_ref and the distillation KL).

    "unbiased": value of the estimator plus a score-function term, so the gradient is the gradient
    of E_{x~pi_theta}[estimate] = KL(pi_theta || pi_other) (the k1 estimate alone has zero expected
    gradient). "pathwise": differentiate the estimate's value only (the GRPO/DeepSeek k3 convention).
    """

    mode: Literal["unbiased", "pathwise"] = Field(
        default="unbiased", description="unbiased: estimate plus a score-function term (the gradient of the KL); "
                                        "pathwise: the estimate's value differentiated alone")


class LossConfig(ConfigModel):
    grpo: GRPOConfig = Field(default_factory=GRPOConfig)
    distill: DistillConfig = Field(default_factory=DistillConfig)
    kl_grad: KLGradConfig = Field(default_factory=KLGradConfig)
    entropy_coef: float = Field(default=0.0, ge=0, description="entropy bonus (0 = only logged)")


class OptimConfig(ConfigModel):
    # Upper bounds catch typos (`lr: 5e7` for 5e-7): Adam steps of size ~lr per weight, so past 1 a
    # single update rewrites the model.
    lr: float = Field(default=5e-7, gt=0, le=1, description="AdamW learning rate (constant)")
    weight_decay: float = Field(default=0.0, ge=0, le=1, description="AdamW decoupled weight decay")
    betas: tuple[Annotated[float, Field(ge=0, lt=1)], Annotated[float, Field(ge=0, lt=1)]] = Field(
        default=(0.9, 0.999), description="AdamW (beta1, beta2), each in [0, 1)")
    eps: float = Field(default=1e-8, gt=0, le=1, description="AdamW epsilon")
    max_grad_norm: float = Field(default=1.0, gt=0, description="clip the gradients' global L2 norm to this")
    micro_batch_size: int = Field(default=1, ge=1, description="samples per forward/backward (at most, with "
                                                                  "max_tokens_per_micro_batch)")
    max_tokens_per_micro_batch: int | None = Field(
        default=None, ge=1, description="split each rank's samples into micro-batches of at most this many tokens "
                                        "(a longer sample is a micro-batch alone), up to micro_batch_size samples each; "
                                        "null: micro_batch_size samples. The loss normalisation is the whole batch's")
    micro_batch_order: Literal["length", "index"] = Field(
        default="length", description="how each rank's samples are grouped into micro-batches: length = sorted "
                                       "longest first, then cut, so each micro-batch pads to about its own length; "
                                       "index = in batch order (sequences of mixed lengths pad to the longest). The "
                                       "update is the same either way (the loss normalisation is the whole batch's)")
    updates_per_batch: int = Field(default=1, ge=1, description="optimizer steps per batch (clipping matters when > 1)")


class DeepSpeedConfig(ConfigModel):
    """DeepSpeed ZeRO-3. On CPU it runs with gloo; `world_size` ranks are separate Ray actors."""

    zero_stage: Literal[1, 2, 3] = Field(default=3, description="ZeRO stage: 1 shards optimizer states, 2 also "
                                                                "gradients, 3 also parameters")
    world_size: int = Field(default=1, ge=1, description="learner ranks, one Ray actor each (> 1 needs learner.backend "
                                                         "deepspeed)")
    num_cpus_per_rank: float = Field(default=1.0, ge=0, description="CPUs Ray reserves per rank actor")
    num_gpus_per_rank: float = Field(default=0.0, ge=0, description="GPUs Ray reserves per rank actor")
    offload_optimizer: bool = Field(default=False, description="keep the optimizer states in host memory")
    offload_param: bool = Field(default=False, description="keep the parameters in host memory (ZeRO-3)")
    master_addr: str = Field(default="127.0.0.1", description="torch.distributed rendezvous address (with several "
                                                              "ranks: rank 0's node, found at start)")
    master_port: int | None = Field(default=None, description="None = pick a free port")
    # The build takes 70-100 s (stack notes 4).
    skip_shm_build: bool = Field(default=True, description="skip the JIT build of DeepSpeed's shared-memory comm op "
                                                            "on CPU")
    timeout_s: float = Field(default=600.0, gt=0, description="torch.distributed collective timeout")


class LearnerConfig(ConfigModel):
    backend: Literal["torch", "deepspeed"] = Field(default="torch", description="torch: one process; deepspeed: ZeRO "
                                                                              "over learner.deepspeed.world_size ranks")
    dtype: Literal["float32", "bfloat16"] = Field(default="float32", description="dtype of the policy's weights and "
                                                                              "forwards")
    device: Literal["cpu", "cuda"] = Field(default="cpu", description="device the policy trains on")
    temperature: float = Field(default=1.0, gt=0, description="the generator's sampling temperature")
    gradient_checkpointing: bool = Field(default=False, description="recompute activations in the backward pass "
                                                                      "instead of keeping them")
    logprob_chunk_size: int = Field(default=1024, ge=1, description="positions per LM-head chunk when computing "
                                                                    "log-probs (bounds the logits' memory)")
    pack_sequences: bool | Literal["auto"] = Field(
        default="auto", description="run the policy, reference and pi_old forwards on each micro-batch's real tokens "
                                    "only (sequences packed into one row, position ids restarting per sequence); "
                                    "'auto': always with a varlen attention (flash attention, or the sdpa_varlen the "
                                    "learner loads with where transformers picks sdpa: each packed sequence attends on "
                                    "its own), else (plain sdpa, eager: a dense block mask covers the whole packed row) "
                                    "a micro-batch whose packed attention area N^2 is at most its padded B*T^2; "
                                    "recurrent layers (Qwen3.5's linear attention) run each packed sequence on its "
                                    "own, so no state crosses sequences")
    loss: LossConfig = Field(default_factory=LossConfig)
    optim: OptimConfig = Field(default_factory=OptimConfig)
    deepspeed: DeepSpeedConfig = Field(default_factory=DeepSpeedConfig)
    reference_model_dir: str | None = Field(default=None, description="frozen KL reference; None = the initial policy")
    train_vision_tower: bool = Field(default=False, description="also train a multimodal checkpoint's vision tower "
                                                                "(model.visual.*; the language model always trains); "
                                                                "no effect on text-only models")

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

    enabled: bool = Field(default=True, description="insert a hint turn into the teacher's context of each trajectory")
    reinforcing: str = Field(
        default="Privileged feedback: this attempt's reasoning appears sound and reaches the correct answer.",
        description="hint text for a correct trajectory")
    corrective: str = Field(
        default="Privileged feedback: this attempt is incorrect; revisit the differential diagnosis and the evidence.",
        description="hint text for an incorrect trajectory")
    # A system turn of its own keeps the ChatML layout valid for the teacher.
    template: str = Field(default="<|im_start|>system\n{hint}<|im_end|>\n",
                          description="how a hint is rendered into tokens; {hint} is replaced by the hint text")
    # So the hint sits between the last prompt turn and the response header.
    before_generation_prompt: bool = Field(
        default=True, description="insert before the prompt's trailing generation prompt ('<|im_start|>assistant\\n') "
                                  "when the prompt ends with it; false: exactly at the prompt's end")
    correctness_rule: Literal["correct_flag", "reward_above"] = Field(
        default="correct_flag", description="which trajectories count as correct: correct_flag = the sample's correct "
                                            "flag (reward.correct_if), reward_above = reward > reward_threshold")
    # Checked by RunConfig: outside the reward's range every trajectory would get the same hint.
    reward_threshold: float = Field(default=0.0, description="reward above which a trajectory counts as correct "
                                                             "(correctness_rule reward_above); inside the reward's range")

    @model_validator(mode="after")
    def _template_has_slot(self) -> HintConfig:
        if "{hint}" not in self.template:
            raise ValueError("teacher.hints.template must contain {hint}, where the hint text is inserted")
        return self


class TeacherConfig(ConfigModel):
    """The EMA teacher actor (Sec. 4.2 "Stability mechanisms", Algorithm 1)."""

    enabled: bool = Field(default=False, description="run the EMA teacher actor (needs learner.loss.distill.enabled)")
    ema_alpha: float = Field(default=0.995, ge=0, le=1, description="EMA decay: theta_T <- alpha theta_T + "
                                                                    "(1 - alpha) theta_S")
    ema_interval: int = Field(default=5, ge=0, description="EMA every N learner steps; 0 = never")
    hard_copy_interval: int = Field(default=30, ge=0, description="theta_T <- theta_S every M steps; 0 = never")
    hints: HintConfig = Field(default_factory=HintConfig)
    serve_topk: int = Field(default=0, ge=0, description="also return the teacher's top-k per position (0 = off)")
    batch_size: int = Field(default=4, ge=1, description="samples per teacher forward (at most, with "
                                                          "max_tokens_per_batch)")
    max_tokens_per_batch: int | None = Field(default=None, ge=1, description="teacher forwards of at most this many "
                                                                             "sample tokens (a longer sample alone)")
    batch_order: Literal["length", "index"] = Field(
        default="length", description="which queued samples form a teacher forward: length = the oldest queued "
                                      "sample with those nearest it in length (sorted, then cut), index = in arrival "
                                      "order. Samples a learner step waits for go first either way")
    temperature: float = Field(default=1.0, gt=0, description="temperature of the teacher's log-probs")
    dtype: Literal["float32", "bfloat16"] = Field(default="float32", description="dtype of the teacher's weights and "
                                                                              "forwards")
    device: Literal["cpu", "cuda"] = Field(default="cpu", description="device the teacher runs on")
    logprob_chunk_size: int = Field(default=1024, ge=1, description="positions per LM-head chunk when computing "
                                                                    "log-probs (bounds the logits' memory)")
    pack_sequences: bool | Literal["auto"] = Field(
        default="auto", description="the teacher's forwards on real tokens only, as learner.pack_sequences (same "
                                    "values: 'auto' always packs under the sdpa_varlen attention the teacher loads "
                                    "with, whose packed sequences attend one at a time, so a sample's values do not "
                                    "depend on the samples it is batched with beyond float rounding, as padded); "
                                    "false: padded")
    # The master takes 4 bytes per parameter: 38 GB for a 9B model beside its 19 GB of bf16 weights;
    # `hcgym plan` says which one fits.
    ema_shadow_device: Literal["model", "cpu"] = Field(
        default="model", description="where the fp32 EMA master lives when the teacher computes in bf16: model = the "
                                     "teacher's device, cpu = host memory (leaves the GPU to the scoring forward)")


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

    transport: Literal["object_store", "collective"] = Field(
        default="object_store", description="object_store: state dicts through Ray's object store; collective: "
                                            "bucketed broadcasts in a torch.distributed group")
    # Gloo is decided from the members' device identities at join: modeling.weight_sync.choose_transport.
    backend: Literal["nccl", "gloo"] = Field(
        default="nccl", description="collective backend when every member has a GPU of its own (gloo, buckets staged "
                                    "through CPU memory, when a member is on the CPU or two share a GPU)")
    bucket_mb: float = Field(default=512.0, gt=0, description="size cap of one broadcast bucket")
    timeout_s: float = Field(default=120.0, gt=0, description="seconds a weight sync may take, whichever transport "
                                                              "(a broadcast, or a generator loading a pushed state dict)")
    master_addr: str = Field(default="127.0.0.1", description="rendezvous address of the collective group (a run "
                                                              "uses learner rank 0's node)")
    master_port: int | None = Field(default=None, description="port of the group's first formation on learner rank 0's "
                                                              "node; null = a free port (re-formations take a free one)")
