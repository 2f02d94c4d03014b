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

Off-policy correction (Eq. 1b-1d). With `trainer.max_staleness` S > 0 a token trained at step s
may have been sampled by the policy of version s-1-lag (lag <= S; `RolloutSample.policy_versions`),
and always by the generator's own numerics. Three distributions meet in one token x_t:
    mu(x_t)        the behaviour policy that sampled it (`RolloutSample.sampling_logprobs`)
    pi_old(x_t)    the learner's policy at the start of this step (recomputed here, the "proximal" policy)
    pi_theta(x_t)  the policy being optimised (pi_theta = pi_old in value on the step's first update)
Eq. 1 and every sampled-token KL estimate are expectations over x ~ pi_old (resp. pi_theta); the
batch holds x ~ mu. Without a correction (`tis_cap` None) a stale token is
trained as if pi_old had sampled it: its ratio is 1 and its KL_ref term k3(pi_ref / pi_theta) is
taken at a token the current policy may have moved far away from. On the demo (lr 3e-4, S = 1)
that made KL_ref 70 nats/token and the grad norm 3.5 at step 2: 184 of its 13,193 lag-1 tokens
(the ` "` of a malformed `{"answer", "`, which step 1 had made ~2e4 times less likely: pi 0.8-1.0
-> 4e-5) carried 99.7 % of the k3 sum (docs/training.md, "Off-policy correction").

We use the decoupled PPO objective (Hilton et al. 2022, "Batch size-invariance for policy
optimization"; AReaL, Fu et al. 2025) with a truncated behaviour weight (TIS, Yao et al. 2025):

    w_t     = min(pi_old(x_t) / mu(x_t), C)          detached, C = `loss.grpo.tis_cap`     (Eq. 1b)
    L_GRPO  = -E_{x~mu}[ w_t * min(rho_t * A, clip(rho_t, 1-eps_lo, 1+eps_hi) * A) ]
              + beta * E_{x~mu}[ w_t * k(x_t) ],   rho_t = pi_theta / pi_old              (Eq. 1c)
    L_distill: the same w_t multiplies each sampled-token (k1 / k3) distillation term     (Eq. 1d)

Why this form and not the ratio taken directly against mu (rho' = pi_theta / mu, clipped):
- The trust region belongs around the policy being updated. Clipping pi_theta / mu clips a stale
  token from the start whenever pi_old / mu is already outside [1-eps, 1+eps] (it then gets no
  gradient at all, or a one-sided one), and the clip region moves with the lag. Decoupled, the clip
  stays centred on pi_old; staleness only changes the weight.
- w_t corrects the sampling distribution: E_{x~mu}[(pi_old/mu) f(x)] = E_{x~pi_old}[f(x)]. The
  truncation at C bounds its variance (no token weighs more than C) at the price of a downward bias
  on tokens the policy now likes more than the sampler did. Tokens the policy has moved away from
  (pi_old << mu), the ones that produced the spike, get weights near 0, which is exact IS.
- The KL terms need the same weight: k(x) estimates KL(pi_theta || q) only when x ~ pi_theta. With
  p = pi_theta, r = q / p, the weighted k3 term is w * k3 = min(p/mu, C) * (r - 1 - log r):
    r > 1 (the policy moved away from a token q likes): < (p/mu) * r = q/mu, and when the sampler
      was the reference (mu = q, the demo's step 2) 1 - 1/r - log(r)/r < 1 instead of r ~ 2e4;
    r < 1: < C * |log r| <= 2 * 20 (log r is clamped at +-20 before exp).
  q/mu is large only for a token the sampler found much less likely than the reference does,
  and such a token is drawn with probability mu; `kl_ref_max` reports the largest term (10.6 and
  19.7 nats on the demo's steps 2-3, against means over ~13,000 tokens). The per-token gradient of
  the unbiased surrogate is w * -log r, at most C * 20 in size, so one token cannot dominate it.
  Eq. 1's meaning is unchanged: beta * KL(pi_theta || pi_ref), estimated from samples of mu.
- With `updates_per_batch` = 1 (our default) rho_t is 1 in value and the clip never binds: the
  correction lives entirely in w_t. On-policy (S = 0) mu and pi_old are the same weights and w_t is
  1 up to the generator's numerics; `tis_cap` is None there unless set, so nothing changes.
The topk distillation estimator sums over the teacher's top-k tokens at each position (no sampled
token to reweight), so it stays unweighted. Positions' prefixes were also sampled by mu; like every
token-level method we do not correct them (the product of per-token ratios has unusable variance).

Logged per step (token means over the loss mask unless noted): is_ratio_mean / is_ratio_max
(pi_old / mu before truncation), is_weight_mean (the applied w, 1 when off), is_capped_frac (w hit C),
is_stale_frac (tokens with lag > 0), is_lag_mean / is_lag_max (the learner's version minus the
token's), is_log_ratio_abs_stale / is_log_ratio_abs_fresh (mean |log pi_old/mu| on lagged and on
lag-0 tokens: lag-0 tokens differ only by the generator's numerics), kl_ref (Eq. 1's KL estimate,
IS-weighted when the correction is on), kl_ref_unweighted (the plain token mean of k, for
comparison), kl_ref_max (the largest single token's term in kl_ref).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from actors.types import RolloutSample
from modeling.config_models import DistillConfig, LossConfig

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
    policy_lag: torch.Tensor | None = None         # [B, T] learner version minus the sampling version


@dataclass
class LossOutput:
    loss: torch.Tensor                        # scalar to backpropagate (this micro-batch's share)
    metrics: dict[str, float]                 # sums over this micro-batch (see `finalize_metrics`)


def _masked_sum(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return (x * mask).sum()


def _masked_max(x: torch.Tensor, mask: torch.Tensor) -> float:
    """Largest value on the mask; 0.0 for an empty mask (a micro-batch without generated tokens)."""
    picked = x[mask > 0]
    return float(picked.max()) if picked.numel() else 0.0


@dataclass
class BehaviourWeights:
    """Eq. 1b for one micro-batch: the truncated importance weights and what led to them."""

    ratio: torch.Tensor    # [B, T] pi_old / mu before truncation (detached)
    weight: torch.Tensor   # [B, T] min(ratio, cap), or ones when the correction is off
    capped: torch.Tensor   # [B, T] 1.0 where the cap bound


def behaviour_weights(
    old_logprobs: torch.Tensor, behaviour_logprobs: torch.Tensor, cap: float | None
) -> BehaviourWeights:
    """w_t = min(pi_old(x_t) / mu(x_t), cap) (Eq. 1b), detached; all ones when cap is None.

    The ratio is formed in log space and clamped at +-20 before exp, so a token the generator
    sampled at a log-prob far below the learner's cannot overflow (the cap truncates it anyway).

    Args:
        old_logprobs: log pi_old of the sampled tokens, as the learner recomputes them.
        behaviour_logprobs: log mu of the same tokens, as the generator sampled them.
        cap: C of Eq. 1b, or None for no correction (weights 1).
    """
    if cap is not None and cap <= 0:
        raise ValueError(f"tis_cap must be > 0, got {cap}")
    log_ratio = (old_logprobs.detach() - behaviour_logprobs.detach()).clamp(-20.0, 20.0)
    ratio = torch.exp(log_ratio)
    if cap is None:
        return BehaviourWeights(ratio=ratio, weight=torch.ones_like(ratio), capped=torch.zeros_like(ratio))
    return BehaviourWeights(ratio=ratio, weight=ratio.clamp(max=cap), capped=(ratio > cap).to(ratio.dtype))


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

    # --- Eq. 1b: the behaviour weight w_t = min(pi_old / mu, C) (ones when tis_cap is None) --------
    bw = behaviour_weights(old, inputs.rollout_logprobs, g.tis_cap)
    is_on = g.tis_cap is not None

    def reweighted(per_token: torch.Tensor) -> torch.Tensor:
        # Only multiply when on: on-policy runs keep exactly the pre-correction arithmetic.
        return per_token * bw.weight if is_on else per_token

    # --- Eq. 1 / 1c: clipped surrogate with rho = pi_theta / pi_old, weighted by w_t ---------------
    ratio = torch.exp(logp - old)
    unclipped = -adv * ratio
    clipped = -adv * ratio.clamp(1.0 - g.clip_eps_low, 1.0 + g.clip_eps_high)
    pg_per_token = reweighted(torch.maximum(unclipped, clipped))
    policy_loss = aggregate(pg_per_token)

    # --- Eq. 1 / 1c: beta * KL(pi_theta || pi_ref), each token's estimate weighted by w_t ----------
    kl_ref_loss = torch.zeros((), dtype=logp.dtype, device=logp.device)
    kl_ref_value = torch.zeros(())
    kl_ref_unweighted = torch.zeros(())
    kl_ref_max = 0.0
    if g.kl_beta > 0:
        if inputs.ref_logprobs is None:
            raise ValueError("loss.grpo.kl_beta > 0 but no reference log-probs were computed")
        kl_ref_tok = kl_surrogate(logp, old, inputs.ref_logprobs, g.kl_estimator, config.kl_grad.mode, g.kl_clamp)
        kl_ref_loss = g.kl_beta * aggregate(reweighted(kl_ref_tok))
        kl_ref_est = kl_estimate(logp.detach(), inputs.ref_logprobs, g.kl_estimator)
        kl_ref_value = _masked_sum(reweighted(kl_ref_est), mask)
        kl_ref_unweighted = _masked_sum(kl_ref_est, mask)
        kl_ref_max = _masked_max(reweighted(kl_ref_est), mask)

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
            # Eq. 1d: a sampled-token estimate, so the sampled token's behaviour weight applies.
            kl_tok = reweighted(kl_surrogate(logp, old, inputs.teacher_logprobs, d.estimator, config.kl_grad.mode))
            kl_report = reweighted(kl_estimate(logp.detach(), inputs.teacher_logprobs, d.estimator))
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
            "sum/kl_ref_unweighted": float(kl_ref_unweighted),
            "max/kl_ref": kl_ref_max,
            "sum/is_ratio": float(_masked_sum(bw.ratio, mask)),
            "max/is_ratio": _masked_max(bw.ratio, mask),
            "sum/is_weight": float(_masked_sum(bw.weight, mask)),
            "sum/is_capped": float(_masked_sum(bw.capped, mask)),
        }
        if inputs.policy_lag is not None:
            lag = inputs.policy_lag.to(mask.dtype)
            stale = mask * (lag > 0).to(mask.dtype)
            abs_log_ratio = bw.ratio.log().abs()
            metrics.update({
                "sum/is_stale": float(stale.sum()),
                "sum/is_lag": float(_masked_sum(lag, mask)),
                "max/is_lag": _masked_max(lag, mask),
                "sum/is_log_ratio_abs_stale": float(_masked_sum(abs_log_ratio, stale)),
                "sum/is_log_ratio_abs_fresh": float(_masked_sum(abs_log_ratio, mask - stale)),
            })
    return LossOutput(loss=loss, metrics=metrics)


def combine_metric_parts(parts: Sequence[dict[str, float]]) -> dict[str, float]:
    """Add up metric dicts of micro-batches (or ranks); `max/*` keys take the maximum instead."""
    total: dict[str, float] = {}
    for part in parts:
        for key, value in part.items():
            if key.startswith("max/"):
                total[key] = max(total.get(key, value), value)
            else:
                total[key] = total.get(key, 0.0) + value
    return total


def finalize_metrics(parts: Sequence[dict[str, float]]) -> dict[str, float]:
    """Combine the micro-batch metrics of one step: losses add up, `sum/*` become token means,
    `max/*` the step's maximum."""
    if not parts:
        return {}
    total = combine_metric_parts(parts)
    tokens = max(total.get("sum/tokens", 0.0), 1.0)
    distill_tokens = total.get("sum/distill_tokens", 0.0)
    out = {k: v for k, v in total.items() if not k.startswith(("sum/", "max/"))}
    out["kl_ref"] = total.get("sum/kl_ref", 0.0) / tokens
    out["kl_teacher"] = total.get("sum/kl_teacher", 0.0) / distill_tokens if distill_tokens else 0.0
    out["entropy"] = total.get("sum/entropy", 0.0) / tokens
    out["clip_frac"] = total.get("sum/clipped", 0.0) / tokens
    out["logprob_diff"] = total.get("sum/logprob_diff", 0.0) / tokens
    out["logprob_abs_diff"] = total.get("sum/logprob_abs_diff", 0.0) / tokens
    out["train_tokens"] = total.get("sum/tokens", 0.0)
    out["distill_tokens"] = distill_tokens
    # Off-policy correction (Eq. 1b): parts written before it existed simply lack these keys.
    if "sum/is_ratio" in total:
        out["kl_ref_unweighted"] = total.get("sum/kl_ref_unweighted", 0.0) / tokens
        out["kl_ref_max"] = total.get("max/kl_ref", 0.0)
        out["is_ratio_mean"] = total["sum/is_ratio"] / tokens
        out["is_ratio_max"] = total.get("max/is_ratio", 0.0)
        out["is_weight_mean"] = total.get("sum/is_weight", 0.0) / tokens
        out["is_capped_frac"] = total.get("sum/is_capped", 0.0) / tokens
    if "sum/is_stale" in total:
        stale = total["sum/is_stale"]
        fresh = total.get("sum/tokens", 0.0) - stale
        out["is_stale_frac"] = stale / tokens
        out["is_lag_mean"] = total.get("sum/is_lag", 0.0) / tokens
        out["is_lag_max"] = total.get("max/is_lag", 0.0)
        out["is_log_ratio_abs_stale"] = total.get("sum/is_log_ratio_abs_stale", 0.0) / stale if stale else 0.0
        out["is_log_ratio_abs_fresh"] = total.get("sum/is_log_ratio_abs_fresh", 0.0) / fresh if fresh else 0.0
    return out
