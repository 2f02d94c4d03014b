"""The training objective, top to bottom: GRPO (Eq. 1) + TT-OPD (Eq. 2-3) = L_total (Eq. 5).

Everything here is plain tensor math on right-padded [B, T] batches whose column t is the token at
position t of `RolloutSample.input_ids`; the learner backends only run forward/backward around it.

    L_total = L_GRPO(theta_S; R) + lambda_distill * L_distill                                (Eq. 5)
    L_GRPO  = -E[min(rho * A, clip(rho, 1-eps_lo, 1+eps_hi) * A)] + beta * KL(pi_theta || pi_ref)  (Eq. 1)
    A_i     = (R_i - mean_g R) / (std_g R + eps)                          (group-relative advantage)
    L_distill(tau) = sum_t 1/|a_t| sum_k KL(pi_S(.|s_t, a_t^<k) || pi_T(.|s_t^+, a_t^<k))    (Eq. 2)
                     over the assistant turns t that end within L_max (turn truncation)

Normalisation is global: a micro-batch's loss is its share of the whole batch's loss (sums divided
by the batch's token / sequence counts in `BatchNorms`), so summing micro-batch gradients, or
rank gradients under DeepSpeed, gives exactly the gradient of the full-batch loss.

KL estimators with x ~ p (the sampled token), r = q(x) / p(x) (Schulman, "Approximating KL"):
    k1 = log p(x) - log q(x)           unbiased, high variance, can be negative
    k2 = 0.5 * (log p(x) - log q(x))^2 biased, low variance (logged only)
    k3 = r - 1 - log r                 unbiased, >= 0, low variance
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from actors.types import RolloutSample
from learner.config_models import DistillConfig, LossConfig

# ----------------------------------------------------------------------------------------------
# Group-relative advantages (Eq. 1, A_i)
# ----------------------------------------------------------------------------------------------


def group_advantages(
    rewards: Sequence[float], group_ids: Sequence[str], *, scale: bool = True, eps: float = 1e-6
) -> torch.Tensor:
    """A_i = (R_i - mean of its group) / (std of its group + eps); std is the sample std (n - 1).

    A group of one sample, or one whose rewards are all equal, gets advantage 0 for every member.

    Args:
        rewards: One reward per sample.
        group_ids: The GRPO group of each sample (samples of the same prompt).
        scale: Divide by the group's std (False gives the Dr.GRPO advantage R_i - mean).
        eps: Added to the std.

    Returns:
        [B] float32 advantages.
    """
    if len(rewards) != len(group_ids):
        raise ValueError(f"rewards has {len(rewards)} entries but group_ids has {len(group_ids)}")
    r = torch.tensor(list(rewards), dtype=torch.float64)
    adv = torch.zeros_like(r)
    groups: dict[str, list[int]] = {}
    for i, g in enumerate(group_ids):
        groups.setdefault(g, []).append(i)
    for members in groups.values():
        idx = torch.tensor(members)
        vals = r[idx]
        if len(members) < 2:
            continue
        centred = vals - vals.mean()
        std = vals.std(unbiased=True)
        if scale:
            # A group without contrast carries no signal: 0, not 0/0 when eps is 0.
            adv[idx] = centred / (std + eps) if std > 0 else torch.zeros_like(centred)
        else:
            adv[idx] = centred
    return adv.float()


# ----------------------------------------------------------------------------------------------
# KL estimators
# ----------------------------------------------------------------------------------------------


def kl_estimate(logp: torch.Tensor, logq: torch.Tensor, estimator: str) -> torch.Tensor:
    """Per-token estimate of KL(p || q) from the sampled tokens' log-probs (x ~ p).

    Args:
        logp: log p(x) of the sampled tokens (the policy being trained).
        logq: log q(x) of the same tokens under the other model (reference or teacher).
        estimator: "k1", "k2" or "k3".
    """
    log_ratio = logq - logp  # log r, r = q / p
    if estimator == "k1":
        return -log_ratio
    if estimator == "k2":
        return 0.5 * log_ratio.pow(2)
    if estimator == "k3":
        # Clamp before exp: a token the other model finds vanishingly unlikely must not produce inf.
        log_ratio = log_ratio.clamp(-20.0, 20.0)
        return torch.expm1(log_ratio) - log_ratio
    raise ValueError(f"unknown KL estimator {estimator!r}: expected 'k1', 'k2' or 'k3'")


def kl_surrogate(
    logp: torch.Tensor, old_logp: torch.Tensor, logq: torch.Tensor, estimator: str, mode: str,
    clamp: float | None = None,
) -> torch.Tensor:
    """A differentiable per-token term whose gradient estimates grad KL(pi_theta || q).

    "unbiased": rho * estimate with rho = pi_theta / pi_old carrying the gradient. Its gradient is
    rho * (estimate * grad log pi_theta + grad estimate), the unbiased gradient of
    E_{x~pi_old}[rho * estimate] = KL(pi_theta || q) (rho = 1 in value on the first update).
    "pathwise": the estimate alone (GRPO's k3 convention; its gradient is not that of the reverse KL).
    Both are token-level, as in GRPO and on-policy distillation practice: the KL of later tokens is not
    credited back to the earlier choices that led there.

    Args:
        logp: Current log-probs (with grad).
        old_logp: Log-probs of the policy that sampled the batch, as the learner computes them (detached).
        logq: The other model's log-probs (detached).
        estimator: "k1" or "k3".
        mode: "unbiased" or "pathwise".
        clamp: Bound each token's estimate to [-clamp, clamp] (beyond it the token adds a constant,
            no gradient through the estimate), or None.
    """
    est = kl_estimate(logp, logq.detach(), estimator)
    if clamp is not None:
        est = est.clamp(-clamp, clamp)
    if mode == "pathwise":
        return est
    if mode == "unbiased":
        return torch.exp(logp - old_logp.detach()) * est
    raise ValueError(f"unknown KL gradient mode {mode!r}: expected 'unbiased' or 'pathwise'")


def topk_kl(student_logp_at_ids: torch.Tensor, teacher_topk_logp: torch.Tensor) -> torch.Tensor:
    """KL(pi_S || pi_T) over the teacher's top-k tokens plus one bucket for the rest of the vocabulary.

    The coarsened distributions (K tokens + tail) give a KL that never exceeds the full one (data
    processing inequality) and is exact in the limit K -> vocabulary; it needs no sampling.

    Args:
        student_logp_at_ids: [..., K] student log-probs at the teacher's top-k ids (with grad).
        teacher_topk_logp: [..., K] teacher log-probs of those ids.

    Returns:
        [...] per-position KL.
    """
    if student_logp_at_ids.shape != teacher_topk_logp.shape:
        raise ValueError(
            f"top-k shapes differ: student {tuple(student_logp_at_ids.shape)} vs teacher {tuple(teacher_topk_logp.shape)}"
        )
    tiny = 1e-12
    p = student_logp_at_ids.exp()
    q = teacher_topk_logp.exp()
    p_tail = (1.0 - p.sum(-1)).clamp(min=tiny)
    q_tail = (1.0 - q.sum(-1)).clamp(min=tiny)
    head = (p * (student_logp_at_ids - teacher_topk_logp)).sum(-1)
    return head + p_tail * (p_tail.log() - q_tail.log())


# ----------------------------------------------------------------------------------------------
# Turn truncation (Eq. 2: the "truncated" in TT-OPD)
# ----------------------------------------------------------------------------------------------


@dataclass
class TurnWeights:
    """Per-position weights of the distillation sum for one sample.

    weights[p] = 1/|a_t| (or 1/(|a_t| * kept turns) for turn_reduction="mean") on the generated tokens
    of every kept turn t, 0 elsewhere; so sum_p weights[p] * KL[p] is Eq. 2 for this trajectory.
    """

    weights: list[float]
    kept_turns: list[int] = field(default_factory=list)
    dropped_turns: list[int] = field(default_factory=list)


def turn_weights(sample: RolloutSample, config: DistillConfig) -> TurnWeights:
    """Which assistant turns enter the distillation loss, and each token's 1/|a_t| weight.

    A turn is dropped when it ends beyond `max_turn_tokens` on the configured basis, or (when
    `drop_length_truncated_turns`) when the generator cut it at its token limit. Only positions with
    `loss_mask == 1` inside a turn's span count as its tokens |a_t|.

    Args:
        sample: The trajectory.
        config: Distillation settings.
    """
    n = len(sample.input_ids)
    weights = [0.0] * n
    out = TurnWeights(weights=weights)
    generated_so_far = 0
    kept: list[tuple[int, list[int]]] = []
    for index, span in enumerate(sample.turns):
        positions = [p for p in range(span.start, span.end) if sample.loss_mask[p]]
        generated_so_far += len(positions)
        if config.truncation_basis == "response":
            extent = span.end - sample.prompt_length
        elif config.truncation_basis == "generated":
            extent = generated_so_far
        else:
            extent = span.end
        over_limit = extent > config.max_turn_tokens
        cut = span.truncated and config.drop_length_truncated_turns
        if over_limit or cut:
            out.dropped_turns.append(index)
            continue
        if positions:
            kept.append((index, positions))
    scale = 1.0 / len(kept) if (config.turn_reduction == "mean" and kept) else 1.0
    for index, positions in kept:
        out.kept_turns.append(index)
        w = scale / len(positions)
        for p in positions:
            weights[p] = w
    return out


# ----------------------------------------------------------------------------------------------
# The batch and the loss
# ----------------------------------------------------------------------------------------------


@dataclass
class BatchNorms:
    """Whole-batch denominators, so micro-batch (and rank) losses add up to the batch loss."""

    num_tokens: float      # loss-mask tokens in the whole batch (token_mean)
    num_sequences: float   # samples in the whole batch (sequence_mean, distillation mean)


@dataclass
class LossInputs:
    """One (micro-)batch, right-padded to [B, T]; every tensor is aligned to input positions.

    `logprobs` carries the gradient; everything else is detached data.
    """

    logprobs: torch.Tensor                         # [B, T] current policy log p(x_t | x_<t)
    old_logprobs: torch.Tensor                     # [B, T] policy that the ratio is taken against
    rollout_logprobs: torch.Tensor                 # [B, T] generator's sampling log-probs
    loss_mask: torch.Tensor                        # [B, T] 1 on generated tokens
    advantages: torch.Tensor                       # [B]
    ref_logprobs: torch.Tensor | None = None       # [B, T] frozen reference
    entropy: torch.Tensor | None = None            # [B, T] (with grad when entropy_coef > 0)
    teacher_logprobs: torch.Tensor | None = None   # [B, T] sampled-token teacher log-probs
    distill_weights: torch.Tensor | None = None    # [B, T] TurnWeights.weights
    student_topk_logprobs: torch.Tensor | None = None  # [B, T, K] student log-probs at teacher ids
    teacher_topk_logprobs: torch.Tensor | None = None  # [B, T, K]


@dataclass
class LossOutput:
    loss: torch.Tensor                        # scalar to backpropagate (this micro-batch's share)
    metrics: dict[str, float]                 # sums over this micro-batch (see `finalize_metrics`)


def _masked_sum(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return (x * mask).sum()


def compute_loss(inputs: LossInputs, config: LossConfig, norms: BatchNorms) -> LossOutput:
    """L_total for one micro-batch as its share of the full batch (Eq. 1, 2, 5).

    Args:
        inputs: Tensors of the micro-batch.
        config: Loss settings.
        norms: Denominators of the whole batch.

    Returns:
        The loss to backpropagate and summed metrics; `finalize_metrics` turns the sums of all
        micro-batches into means.
    """
    g = config.grpo
    mask = inputs.loss_mask.float()
    logp = inputs.logprobs
    old = inputs.old_logprobs.detach()
    adv = inputs.advantages.detach().unsqueeze(-1)  # [B, 1]: one advantage for every token of a sample

    def aggregate(per_token: torch.Tensor) -> torch.Tensor:
        if g.loss_aggregation == "token_mean":
            return _masked_sum(per_token, mask) / norms.num_tokens
        per_seq = (per_token * mask).sum(-1) / mask.sum(-1).clamp(min=1.0)
        return per_seq.sum() / norms.num_sequences

    # --- Eq. 1: clipped surrogate with the importance ratio rho = pi_theta / pi_old -------------
    ratio = torch.exp(logp - old)
    unclipped = -adv * ratio
    clipped = -adv * ratio.clamp(1.0 - g.clip_eps_low, 1.0 + g.clip_eps_high)
    pg_per_token = torch.maximum(unclipped, clipped)
    if g.tis_cap is not None:
        # Truncated importance sampling: correct for the generator's numerics differing from ours.
        tis = torch.exp(old - inputs.rollout_logprobs).clamp(max=g.tis_cap).detach()
        pg_per_token = pg_per_token * tis
    policy_loss = aggregate(pg_per_token)

    # --- Eq. 1: beta * KL(pi_theta || pi_ref) ---------------------------------------------------
    kl_ref_loss = torch.zeros((), dtype=logp.dtype, device=logp.device)
    kl_ref_value = torch.zeros(())
    if g.kl_beta > 0:
        if inputs.ref_logprobs is None:
            raise ValueError("loss.grpo.kl_beta > 0 but no reference log-probs were computed")
        kl_ref_tok = kl_surrogate(logp, old, inputs.ref_logprobs, g.kl_estimator, config.kl_grad.mode, g.kl_clamp)
        kl_ref_loss = g.kl_beta * aggregate(kl_ref_tok)
        kl_ref_value = _masked_sum(kl_estimate(logp.detach(), inputs.ref_logprobs, g.kl_estimator), mask)

    # --- Eq. 2: turn-level truncated distillation toward the teacher ---------------------------
    d = config.distill
    distill_loss = torch.zeros((), dtype=logp.dtype, device=logp.device)
    kl_teacher_value = torch.zeros(())
    distill_tokens = torch.zeros(())
    if d.enabled and d.lambda_distill > 0:
        if inputs.distill_weights is None:
            raise ValueError("loss.distill.enabled but no teacher outputs / turn weights were given")
        w = inputs.distill_weights
        in_turn = (w > 0).float()
        if d.estimator == "topk":
            if inputs.student_topk_logprobs is None or inputs.teacher_topk_logprobs is None:
                raise ValueError("loss.distill.estimator = 'topk' needs the teacher's top-k log-probs")
            kl_tok = topk_kl(inputs.student_topk_logprobs, inputs.teacher_topk_logprobs)
            kl_report = kl_tok.detach()
        else:
            if inputs.teacher_logprobs is None:
                raise ValueError("loss.distill.enabled but teacher log-probs are missing")
            kl_tok = kl_surrogate(logp, old, inputs.teacher_logprobs, d.estimator, config.kl_grad.mode)
            kl_report = kl_estimate(logp.detach(), inputs.teacher_logprobs, d.estimator)
        # sum_t 1/|a_t| sum_k KL_k per trajectory (the weights carry 1/|a_t| and the truncation),
        # then the mean over the batch's trajectories.
        per_traj = (kl_tok * w).sum(-1)
        distill_loss = per_traj.sum() / norms.num_sequences
        kl_teacher_value = _masked_sum(kl_report, in_turn)
        distill_tokens = in_turn.sum()

    # --- entropy (logged; optional bonus) ---------------------------------------------------------
    entropy_sum = torch.zeros(())
    entropy_bonus = torch.zeros((), dtype=logp.dtype, device=logp.device)
    if inputs.entropy is not None:
        entropy_sum = _masked_sum(inputs.entropy.detach(), mask)
        if config.entropy_coef > 0:
            entropy_bonus = config.entropy_coef * aggregate(inputs.entropy)

    # --- Eq. 5: L_total ---------------------------------------------------------------------------
    loss = policy_loss + kl_ref_loss + d.lambda_distill * distill_loss - entropy_bonus

    with torch.no_grad():
        clip_hi = ((ratio > 1.0 + g.clip_eps_high) & (adv > 0)) | ((ratio < 1.0 - g.clip_eps_low) & (adv < 0))
        metrics = {
            "policy_loss": float(policy_loss),
            "kl_ref_loss": float(kl_ref_loss),
            "distill_loss": float(distill_loss),
            "loss": float(loss),
            "sum/kl_ref": float(kl_ref_value),
            "sum/kl_teacher": float(kl_teacher_value),
            "sum/distill_tokens": float(distill_tokens),
            "sum/entropy": float(entropy_sum),
            "sum/clipped": float(_masked_sum(clip_hi.float(), mask)),
            "sum/logprob_diff": float(_masked_sum(old - inputs.rollout_logprobs, mask)),
            "sum/logprob_abs_diff": float(_masked_sum((old - inputs.rollout_logprobs).abs(), mask)),
            "sum/tokens": float(mask.sum()),
        }
    return LossOutput(loss=loss, metrics=metrics)


def finalize_metrics(parts: Sequence[dict[str, float]]) -> dict[str, float]:
    """Combine the micro-batch metrics of one step: losses add up, `sum/*` become token means."""
    if not parts:
        return {}
    total: dict[str, float] = {}
    for part in parts:
        for key, value in part.items():
            total[key] = total.get(key, 0.0) + value
    tokens = max(total.get("sum/tokens", 0.0), 1.0)
    distill_tokens = total.get("sum/distill_tokens", 0.0)
    out = {k: v for k, v in total.items() if not k.startswith("sum/")}
    out["kl_ref"] = total.get("sum/kl_ref", 0.0) / tokens
    out["kl_teacher"] = total.get("sum/kl_teacher", 0.0) / distill_tokens if distill_tokens else 0.0
    out["entropy"] = total.get("sum/entropy", 0.0) / tokens
    out["clip_frac"] = total.get("sum/clipped", 0.0) / tokens
    out["logprob_diff"] = total.get("sum/logprob_diff", 0.0) / tokens
    out["logprob_abs_diff"] = total.get("sum/logprob_abs_diff", 0.0) / tokens
    out["train_tokens"] = total.get("sum/tokens", 0.0)
    out["distill_tokens"] = distill_tokens
    return out
