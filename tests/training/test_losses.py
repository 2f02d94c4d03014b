"""The losses against hand-computed values and closed forms (no model needed)."""

from __future__ import annotations

import math

import pytest
import torch

from actors.types import RolloutSample, TurnSpan
from modeling.config_models import DistillConfig, LossConfig
from learner.losses import (
    BatchNorms,
    LossInputs,
    behaviour_weights,
    compute_loss,
    finalize_metrics,
    group_advantages,
    kl_estimate,
    kl_surrogate,
    topk_kl,
    turn_weights,
)

# ----------------------------------------------------------------------------------------------
# Advantages
# ----------------------------------------------------------------------------------------------


def test_group_advantages_hand_computed():
    # group a: rewards 1, 0, 0.5 -> mean 0.5, sample std 0.5 -> (1, -1, 0)
    # group b: rewards 2, 2 -> no contrast -> 0, 0; group c: a single sample -> 0
    adv = group_advantages([1.0, 0.0, 0.5, 2.0, 2.0, 3.0], ["a", "a", "a", "b", "b", "c"], eps=0.0)
    assert adv.tolist() == pytest.approx([1.0, -1.0, 0.0, 0.0, 0.0, 0.0])
    # Interleaved groups are matched by id, not by position.
    adv2 = group_advantages([1.0, 4.0, 0.0, 0.0], ["a", "b", "a", "b"], eps=0.0)
    s = math.sqrt(0.5)  # sample std of {1, 0}
    assert adv2.tolist() == pytest.approx([0.5 / s, 2.0 / math.sqrt(8.0), -0.5 / s, -2.0 / math.sqrt(8.0)])
    # Dr.GRPO: centred only.
    assert group_advantages([1.0, 0.0, 0.5], ["a"] * 3, scale=False).tolist() == pytest.approx([0.5, -0.5, 0.0])


def test_group_advantages_rejects_mismatched_lengths():
    with pytest.raises(ValueError, match="group_ids"):
        group_advantages([1.0, 2.0], ["a"])


# ----------------------------------------------------------------------------------------------
# GRPO clipped surrogate (Eq. 1)
# ----------------------------------------------------------------------------------------------


def _grpo_only(**grpo) -> LossConfig:
    return LossConfig(grpo={"kl_beta": 0.0, **grpo})


def test_grpo_clipped_surrogate_hand_computed():
    # Four tokens of one sample with advantage +1 and four of one with -1; ratios 1.5, 0.5, 1.0, 1.1.
    ratios = torch.tensor([[1.5, 0.5, 1.0, 1.1], [1.5, 0.5, 1.0, 1.1]])
    old = torch.zeros(2, 4)
    logp = ratios.log().requires_grad_(True)
    mask = torch.tensor([[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 0.0]])  # last token of row 2 is a tool token
    inputs = LossInputs(logprobs=logp, old_logprobs=old, rollout_logprobs=old, loss_mask=mask,
                        advantages=torch.tensor([1.0, -1.0]))
    out = compute_loss(inputs, _grpo_only(clip_eps_low=0.2, clip_eps_high=0.2), BatchNorms(7.0, 2.0))
    # A=+1: max(-r, -clip(r)) -> -1.2, -0.5, -1.0, -1.1 ; A=-1: max(r, clip(r)) -> 1.5, 0.8, 1.0 (masked 1.1)
    expected = (-1.2 - 0.5 - 1.0 - 1.1 + 1.5 + 0.8 + 1.0) / 7.0
    assert out.loss.item() == pytest.approx(expected, abs=1e-6)
    assert out.metrics["policy_loss"] == pytest.approx(expected, abs=1e-6)
    out.loss.backward()
    grad = logp.grad
    # Clipped tokens carry no gradient: (A=+1, r=1.5) and (A=-1, r=0.5); so does the masked token.
    assert grad[0, 0] == 0 and grad[1, 1] == 0 and grad[1, 3] == 0
    # d/dlogp of -A*r = -A*r / 7 for the unclipped ones.
    assert float(grad[0, 1]) == pytest.approx(-0.5 / 7.0)
    assert float(grad[1, 0]) == pytest.approx(1.5 / 7.0)
    assert out.metrics["sum/clipped"] == 2.0


def test_grpo_sequence_mean_aggregation():
    logp = torch.zeros(2, 3, requires_grad=True)
    mask = torch.tensor([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])
    inputs = LossInputs(logprobs=logp, old_logprobs=logp.detach(), rollout_logprobs=logp.detach(), loss_mask=mask,
                        advantages=torch.tensor([2.0, -1.0]))
    tok = compute_loss(inputs, _grpo_only(), BatchNorms(4.0, 2.0))
    seq = compute_loss(inputs, _grpo_only(loss_aggregation="sequence_mean"), BatchNorms(4.0, 2.0))
    assert tok.loss.item() == pytest.approx((-2 * 3 + 1) / 4.0)   # token mean
    assert seq.loss.item() == pytest.approx((-2.0 + 1.0) / 2.0)   # mean of per-sample means


def test_tis_weight_caps_rollout_mismatch():
    logp = torch.zeros(1, 2, requires_grad=True)
    rollout = torch.tensor([[math.log(0.25), 0.0]])  # the generator was 4x less likely on token 0
    inputs = LossInputs(logprobs=logp, old_logprobs=logp.detach(), rollout_logprobs=rollout,
                        loss_mask=torch.ones(1, 2), advantages=torch.tensor([1.0]))
    out = compute_loss(inputs, _grpo_only(tis_cap=2.0), BatchNorms(2.0, 1.0))
    assert out.loss.item() == pytest.approx(-(2.0 + 1.0) / 2.0)  # weight min(4, 2) = 2 on token 0
    assert out.metrics["sum/logprob_diff"] == pytest.approx(-math.log(0.25))


# ----------------------------------------------------------------------------------------------
# Off-policy correction (Eq. 1b-1d)
# ----------------------------------------------------------------------------------------------


def test_behaviour_weights_hand_computed():
    # pi_old / mu = 4, 1, 0.5, e^25 (clamped in log space at e^20 before the cap)
    old = torch.tensor([[math.log(0.4), math.log(0.3), math.log(0.1), 0.0]])
    mu = torch.tensor([[math.log(0.1), math.log(0.3), math.log(0.2), -25.0]])
    w = behaviour_weights(old, mu, 2.0)
    assert w.ratio.tolist()[0][:3] == pytest.approx([4.0, 1.0, 0.5])
    assert float(w.ratio[0, 3]) == pytest.approx(math.exp(20.0), rel=1e-5)
    assert w.weight.tolist() == [pytest.approx([2.0, 1.0, 0.5, 2.0])]
    assert w.capped.tolist() == [[1.0, 0.0, 0.0, 1.0]]
    off = behaviour_weights(old, mu, None)  # no correction: weight 1, nothing capped, the ratio still known
    assert off.weight.tolist() == [[1.0] * 4] and off.capped.sum() == 0 and float(off.ratio[0, 0]) == pytest.approx(4.0)
    with pytest.raises(ValueError, match="tis_cap"):
        behaviour_weights(old, mu, 0.0)


def _offpolicy_inputs():
    """Two tokens of one sample (advantage +1) sampled by a stale mu: pi_old / mu = 4 and 1/2.

    pi_theta = pi_old (first update); the reference likes token 0 much more than pi_theta does:
    r = q / p = e^4 on token 0 (the k3 outlier), e^-0.5 on token 1.
    """
    old = torch.tensor([[math.log(0.4), math.log(0.2)]])
    logp = old.clone().requires_grad_(True)
    mu = torch.tensor([[math.log(0.1), math.log(0.4)]])
    ref = old + torch.tensor([[4.0, -0.5]])
    return LossInputs(logprobs=logp, old_logprobs=old, rollout_logprobs=mu, loss_mask=torch.ones(1, 2),
                      advantages=torch.tensor([1.0]), ref_logprobs=ref, policy_lag=torch.tensor([[1.0, 0.0]]))


def _k3(log_r):
    return math.exp(log_r) - 1 - log_r


def test_capped_offpolicy_loss_hand_computed():
    inputs = _offpolicy_inputs()
    cfg = LossConfig(grpo={"kl_beta": 0.1, "kl_estimator": "k3", "tis_cap": 2.0})
    out = compute_loss(inputs, cfg, BatchNorms(2.0, 1.0))
    w = [2.0, 0.5]  # min(4, 2), min(0.5, 2)
    pg = (-w[0] * 1.0 - w[1] * 1.0) / 2.0  # rho = 1: -A * rho * w per token, token mean
    kl_tok = [_k3(4.0), _k3(-0.5)]
    kl = (w[0] * kl_tok[0] + w[1] * kl_tok[1]) / 2.0
    assert out.metrics["policy_loss"] == pytest.approx(pg, rel=1e-6)
    assert out.metrics["kl_ref_loss"] == pytest.approx(0.1 * kl, rel=1e-6)
    assert out.loss.item() == pytest.approx(pg + 0.1 * kl, rel=1e-6)
    # Gradient per token (unbiased KL surrogate): w * (-A * rho + beta * -log r) / 2
    out.loss.backward()
    expected = [w[0] * (-1.0 + 0.1 * -4.0) / 2.0, w[1] * (-1.0 + 0.1 * 0.5) / 2.0]
    assert inputs.logprobs.grad.tolist()[0] == pytest.approx(expected, rel=1e-6)
    m = finalize_metrics([out.metrics])
    assert m["kl_ref"] == pytest.approx(kl, rel=1e-6)
    assert m["kl_ref_unweighted"] == pytest.approx(sum(kl_tok) / 2.0, rel=1e-6)
    assert m["kl_ref_max"] == pytest.approx(w[0] * kl_tok[0], rel=1e-6)
    assert m["is_ratio_mean"] == pytest.approx((4.0 + 0.5) / 2.0) and m["is_ratio_max"] == pytest.approx(4.0)
    assert m["is_weight_mean"] == pytest.approx(1.25) and m["is_capped_frac"] == pytest.approx(0.5)
    assert m["is_stale_frac"] == pytest.approx(0.5) and m["is_lag_max"] == 1.0 and m["is_lag_mean"] == 0.5
    assert m["is_log_ratio_abs_stale"] == pytest.approx(math.log(4.0))
    assert m["is_log_ratio_abs_fresh"] == pytest.approx(math.log(2.0))


def test_offpolicy_weight_off_keeps_the_uncorrected_loss():
    inputs = _offpolicy_inputs()
    out = compute_loss(inputs, LossConfig(grpo={"kl_beta": 0.1, "kl_estimator": "k3"}), BatchNorms(2.0, 1.0))
    kl = (_k3(4.0) + _k3(-0.5)) / 2.0
    assert out.loss.item() == pytest.approx(-1.0 + 0.1 * kl, rel=1e-6)
    m = finalize_metrics([out.metrics])
    assert m["kl_ref"] == pytest.approx(m["kl_ref_unweighted"]) and m["is_weight_mean"] == 1.0
    assert m["is_capped_frac"] == 0.0 and m["is_ratio_max"] == pytest.approx(4.0)  # the mismatch is still logged


def test_offpolicy_weight_applies_to_sampled_token_distillation():
    # k1 distillation, teacher 1 nat below the student on both tokens: per token w * 1.
    inputs = _offpolicy_inputs()
    inputs.teacher_logprobs = inputs.old_logprobs - 1.0
    inputs.distill_weights = torch.tensor([[0.5, 0.5]])  # one turn of two tokens
    cfg = LossConfig(grpo={"kl_beta": 0.0, "tis_cap": 2.0}, distill={"enabled": True, "estimator": "k1",
                                                                   "lambda_distill": 1.0})
    out = compute_loss(inputs, cfg, BatchNorms(2.0, 1.0))
    assert out.metrics["distill_loss"] == pytest.approx(0.5 * 2.0 + 0.5 * 0.5)
    assert finalize_metrics([out.metrics])["kl_teacher"] == pytest.approx((2.0 + 0.5) / 2.0)


def test_offpolicy_weight_removes_the_stale_token_kl_spike():
    # The demo's step-2 situation: a lag-1 token sampled by mu = pi_ref that one update made 1e5 times
    # less likely. Uncorrected its k3 term is ~1e5; weighted by pi/mu it is below 1 (losses.py Eq. 1c).
    ref = torch.tensor([[math.log(0.5)] * 3])
    mu = ref.clone()
    old = torch.tensor([[math.log(0.5e-5), math.log(0.5), math.log(0.5)]])
    base = dict(logprobs=old.clone().requires_grad_(True), old_logprobs=old, rollout_logprobs=mu,
                loss_mask=torch.ones(1, 3), advantages=torch.tensor([0.0]), ref_logprobs=ref)
    raw = finalize_metrics([compute_loss(LossInputs(**base), LossConfig(grpo={"kl_estimator": "k3"}),
                                         BatchNorms(3.0, 1.0)).metrics])
    fixed = compute_loss(LossInputs(**base), LossConfig(grpo={"kl_estimator": "k3", "tis_cap": 2.0}), BatchNorms(3.0, 1.0))
    m = finalize_metrics([fixed.metrics])
    assert raw["kl_ref"] == pytest.approx(_k3(math.log(1e5)) / 3.0, rel=1e-4) and raw["kl_ref"] > 3e4
    assert m["kl_ref"] < 1.0 / 3.0 and m["kl_ref_max"] < 1.0
    fixed.loss.backward()
    assert abs(float(base["logprobs"].grad[0, 0])) < 1e-4  # the stale outlier no longer drives the gradient


def test_max_metrics_combine_by_maximum():
    parts = [{"sum/tokens": 2.0, "sum/is_ratio": 2.0, "max/is_ratio": 3.0, "loss": 1.0},
             {"sum/tokens": 2.0, "sum/is_ratio": 4.0, "max/is_ratio": 1.5, "loss": 2.0}]
    m = finalize_metrics(parts)
    assert m["is_ratio_max"] == 3.0 and m["is_ratio_mean"] == 1.5 and m["loss"] == 3.0
    assert not any(k.startswith(("sum/", "max/")) for k in m)


# ----------------------------------------------------------------------------------------------
# KL estimators
# ----------------------------------------------------------------------------------------------

P = torch.tensor([0.5, 0.3, 0.15, 0.05])
Q = torch.tensor([0.25, 0.25, 0.25, 0.25])


def _kl(p, q):
    return float((p * (p / q).log()).sum())


@pytest.mark.parametrize("estimator", ["k1", "k3"])
def test_kl_estimators_are_unbiased_exactly(estimator):
    # E_{x~p}[k(x)] computed exactly over the support equals the closed-form KL(p || q).
    values = kl_estimate(P.log(), Q.log(), estimator)
    assert float((P * values).sum()) == pytest.approx(_kl(P, Q), rel=1e-6)


def test_kl_estimator_properties_and_monte_carlo():
    gen = torch.Generator().manual_seed(0)
    x = torch.multinomial(P, 200_000, replacement=True, generator=gen)
    lp, lq = P.log()[x], Q.log()[x]
    k1, k3 = (kl_estimate(lp, lq, e) for e in ("k1", "k3"))
    assert float(k1.mean()) == pytest.approx(_kl(P, Q), abs=0.01)
    assert float(k3.mean()) == pytest.approx(_kl(P, Q), abs=0.01)
    assert bool((k3 >= 0).all()) and bool((k1 < 0).any())  # k3 never negative, k1 can be
    assert float(k3.var()) < float(k1.var())  # the point of k3: lower variance
    assert float((P * kl_estimate(P.log(), Q.log(), "k2")).sum()) == pytest.approx(
        float((P * 0.5 * (P / Q).log() ** 2).sum()))
    with pytest.raises(ValueError, match="k4"):
        kl_estimate(lp, lq, "k4")


@pytest.mark.parametrize("estimator", ["k1", "k3"])
def test_unbiased_surrogate_gradient_equals_reverse_kl_gradient(estimator):
    # For p_theta = softmax(theta), sum_x p(x) * grad surrogate(x) must be grad KL(p_theta || q).
    theta = torch.tensor([0.3, -0.2, 1.0, 0.1], requires_grad=True)
    logq = torch.log_softmax(torch.tensor([0.0, 0.5, -0.5, 0.2]), -1)
    logp = torch.log_softmax(theta, -1)
    surr = kl_surrogate(logp, logp.detach(), logq, estimator, "unbiased")
    (logp.detach().exp() * surr).sum().backward()
    expected_theta = theta.detach().clone().requires_grad_(True)
    lp = torch.log_softmax(expected_theta, -1)
    (lp.exp() * (lp - logq)).sum().backward()
    assert torch.allclose(theta.grad, expected_theta.grad, atol=1e-6)


def test_kl_clamp_bounds_an_outlier_tokens_gradient():
    # A sampled token the policy finds unlikely (p = 1e-5) but the reference likes (q = 0.9): k3 ~ 9e4.
    logp = torch.tensor([math.log(1e-5), math.log(0.5)])
    logq = torch.tensor([math.log(0.9), math.log(0.5)])

    def grad(mode, clamp):
        lp = logp.clone().requires_grad_(True)
        kl_surrogate(lp, lp.detach(), logq, "k3", mode, clamp).sum().backward()
        return lp.grad[0].item()

    log_r = math.log(0.9 / 1e-5)
    assert grad("unbiased", None) == pytest.approx(-log_r, rel=1e-3)  # bounded by |log r| already
    assert grad("pathwise", None) == pytest.approx(1 - 0.9 / 1e-5, rel=1e-3)  # 1 - r: the outlier rules
    assert grad("pathwise", 10.0) == 0.0 and abs(grad("unbiased", 10.0)) <= 10.0
    ordinary = kl_surrogate(logp, logp, logq, "k3", "unbiased", 10.0)[1]
    assert float(ordinary) == pytest.approx(0.0, abs=1e-6)  # within the bound nothing changes


def test_pathwise_k3_gradient_is_the_forward_kl_gradient():
    # Documented difference: differentiating k3's value gives grad KL(q || p_theta), not the reverse KL.
    theta = torch.tensor([0.3, -0.2, 1.0, 0.1], requires_grad=True)
    logq = torch.log_softmax(torch.tensor([0.0, 0.5, -0.5, 0.2]), -1)
    logp = torch.log_softmax(theta, -1)
    (logp.detach().exp() * kl_surrogate(logp, logp.detach(), logq, "k3", "pathwise")).sum().backward()
    ref = theta.detach().clone().requires_grad_(True)
    (logq.exp() * (logq - torch.log_softmax(ref, -1))).sum().backward()
    assert torch.allclose(theta.grad, ref.grad, atol=1e-6)


def test_topk_kl_exact_with_full_support_and_lower_bound_otherwise():
    p = torch.tensor([0.5, 0.3, 0.15, 0.05])
    q = torch.tensor([0.1, 0.6, 0.2, 0.1])
    full = topk_kl(p.log(), q.log())
    assert float(full) == pytest.approx(_kl(p, q), rel=1e-5)
    top2 = torch.tensor([1, 2])  # the teacher's two most likely tokens
    partial = topk_kl(p.log()[top2], q.log()[top2])
    coarse_p = torch.tensor([0.3, 0.15, 0.55])
    coarse_q = torch.tensor([0.6, 0.2, 0.2])
    assert float(partial) == pytest.approx(_kl(coarse_p, coarse_q), rel=1e-5)
    assert 0 <= float(partial) <= _kl(p, q)
    with pytest.raises(ValueError, match="shapes"):
        topk_kl(p.log()[:2], q.log()[:3])


# ----------------------------------------------------------------------------------------------
# TT-OPD turn truncation and the distillation sum (Eq. 2)
# ----------------------------------------------------------------------------------------------


def _sample(turn_lens, prompt=4, tool=3, truncated=()):
    ids, mask, turns = [1] * prompt, [0] * prompt, []
    for t, n in enumerate(turn_lens):
        start = len(ids)
        ids += [2] * n
        mask += [1] * n
        turns.append(TurnSpan(start=start, end=len(ids), truncated=t in truncated))
        if t < len(turn_lens) - 1:
            ids += [3] * tool
            mask += [0] * tool
    n = len(ids)
    return RolloutSample(sample_id="s", task_id="t", domain="d", group_id="g", seed=0, prompt_length=prompt,
                         input_ids=ids, loss_mask=mask, sampling_logprobs=[0.0] * n,
                         policy_versions=[0 if m else -1 for m in mask], turns=turns)


def test_turn_truncation_drops_turns_beyond_lmax():
    # Turns of 2, 4, 3 generated tokens with 3 tool tokens between: they end 2, 9 and 15 tokens
    # after the prompt (response basis); cumulative generated tokens 2, 6, 9.
    s = _sample([2, 4, 3])
    tw = turn_weights(s, DistillConfig(enabled=True, max_turn_tokens=10))
    assert tw.kept_turns == [0, 1] and tw.dropped_turns == [2]
    w = tw.weights
    assert w[4:6] == [0.5, 0.5]                                   # turn 0: 1/|a_0| = 1/2
    assert w[6:9] == [0.0] * 3                                    # tool tokens
    assert w[9:13] == [0.25] * 4                                  # turn 1: 1/4
    assert w[16:19] == [0.0] * 3                                  # turn 2 dropped
    assert sum(w) == pytest.approx(2.0)                           # one per kept turn
    # Generated-tokens basis: 9 <= 10 keeps all three.
    assert turn_weights(s, DistillConfig(enabled=True, max_turn_tokens=10, truncation_basis="generated")).dropped_turns == []
    # Context basis counts the prompt too: turn 1 ends at position 13 > 12.
    assert turn_weights(s, DistillConfig(enabled=True, max_turn_tokens=12, truncation_basis="context")).kept_turns == [0]
    # A turn the generator cut at its token limit is dropped even within L_max, unless configured off.
    cut = _sample([2, 4, 3], truncated=(1,))
    assert turn_weights(cut, DistillConfig(enabled=True)).dropped_turns == [1]
    assert turn_weights(cut, DistillConfig(enabled=True, drop_length_truncated_turns=False)).dropped_turns == []
    # "mean" divides by the number of kept turns.
    assert sum(turn_weights(s, DistillConfig(enabled=True, turn_reduction="mean")).weights) == pytest.approx(1.0)


def test_distillation_loss_hand_computed():
    s = _sample([2, 4])  # prompt 4, turn 0 at 4-5, tools 6-8, turn 1 at 9-12
    d = DistillConfig(enabled=True, lambda_distill=4.0, estimator="k1")
    w = torch.tensor([turn_weights(s, d).weights])
    logp = torch.full((1, len(s.input_ids)), -1.0, requires_grad=True)
    teacher = torch.full((1, len(s.input_ids)), -1.0)
    teacher[0, 4:6] = torch.tensor([-2.0, -3.0])       # k1 = 1, 2 -> turn mean 1.5
    teacher[0, 9:13] = torch.tensor([-1.5, -1.0, -1.0, -0.5])  # k1 = 0.5, 0, 0, -0.5 -> mean 0
    mask = torch.tensor([s.loss_mask], dtype=torch.float32)
    cfg = LossConfig(grpo={"kl_beta": 0.0}, distill=d)
    inputs = LossInputs(logprobs=logp, old_logprobs=logp.detach(), rollout_logprobs=logp.detach(), loss_mask=mask,
                        advantages=torch.zeros(1), teacher_logprobs=teacher, distill_weights=w)
    out = compute_loss(inputs, cfg, BatchNorms(6.0, 2.0))  # batch of 2 trajectories, the other contributes 0
    assert out.metrics["distill_loss"] == pytest.approx((1.5 + 0.0) / 2.0)
    assert out.loss.item() == pytest.approx(4.0 * 0.75)
    m = finalize_metrics([out.metrics])
    assert m["kl_teacher"] == pytest.approx((1 + 2 + 0.5 + 0 + 0 - 0.5) / 6.0)


def test_micro_batches_sum_to_the_full_batch_loss_and_gradient():
    gen = torch.Generator().manual_seed(1)
    B, T = 4, 7
    base = torch.randn(B, T, generator=gen) - 2.0
    mask = (torch.rand(B, T, generator=gen) > 0.3).float()
    ref = base + 0.1 * torch.randn(B, T, generator=gen)
    teacher = base + 0.2 * torch.randn(B, T, generator=gen)
    weights = mask / mask.sum(-1, keepdim=True).clamp(min=1)
    adv = torch.tensor([1.0, -0.5, 0.2, -0.7])
    cfg = LossConfig(grpo={"kl_beta": 0.05}, distill={"enabled": True, "estimator": "k3"})
    norms = BatchNorms(float(mask.sum()), float(B))

    def run(rows):
        logp = base[rows].clone().requires_grad_(True)
        inputs = LossInputs(logprobs=logp, old_logprobs=base[rows] - 0.05, rollout_logprobs=base[rows],
                            loss_mask=mask[rows], advantages=adv[rows], ref_logprobs=ref[rows],
                            teacher_logprobs=teacher[rows], distill_weights=weights[rows])
        out = compute_loss(inputs, cfg, norms)
        out.loss.backward()
        return out.loss.item(), logp.grad

    full_loss, full_grad = run([0, 1, 2, 3])
    l1, g1 = run([0, 1])
    l2, g2 = run([2, 3])
    assert l1 + l2 == pytest.approx(full_loss, rel=1e-6)
    assert torch.allclose(torch.cat([g1, g2]), full_grad, atol=1e-7)


def test_missing_inputs_raise_named_errors():
    logp = torch.zeros(1, 2, requires_grad=True)
    base = {"logprobs": logp, "old_logprobs": logp.detach(), "rollout_logprobs": logp.detach(),
            "loss_mask": torch.ones(1, 2), "advantages": torch.zeros(1)}
    with pytest.raises(ValueError, match="kl_beta"):
        compute_loss(LossInputs(**base), LossConfig(), BatchNorms(2.0, 1.0))
    with pytest.raises(ValueError, match="distill"):
        compute_loss(LossInputs(**base), LossConfig(grpo={"kl_beta": 0}, distill={"enabled": True}), BatchNorms(2.0, 1.0))
