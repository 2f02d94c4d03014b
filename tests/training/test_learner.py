"""The torch learner backend end to end on the tiny model: GRPO and TT-OPD steps, weights, errors."""

from __future__ import annotations

import pytest
import torch

from actors.teacher import Teacher
from actors.types import TeacherBatch
from modeling.config_models import LearnerConfig, TeacherConfig
from learner.learner_actor import Learner
from modeling.model import load_policy, pad_batch, per_token_logprobs
from tests.training.learner_fixtures import make_batch, tiny_model_dir

REQUIRED_KEYS = {"policy_loss", "distill_loss", "kl_ref", "kl_teacher", "entropy", "grad_norm", "logprob_diff",
                 "turns_truncated", "policy_version", "loss", "clip_frac"}


@pytest.fixture(scope="module")
def model_dir():
    return tiny_model_dir()


@pytest.fixture(scope="module")
def batch(model_dir):
    return make_batch(seed=0, groups=2, group_size=3, model_dir=model_dir)


def _logprobs(weights, model_dir, samples):
    model, tok = load_policy(model_dir)
    model.load_state_dict(weights)
    ids, mask = pad_batch([s.input_ids for s in samples], tok.pad_token_id)
    with torch.no_grad():
        return per_token_logprobs(model, ids, mask)


def test_grpo_step_moves_probability_toward_positive_advantages(model_dir, batch):
    learner = Learner(LearnerConfig(optim={"lr": 2e-3}), model_dir)
    before = learner.get_state_dict()
    m = learner.train_step(batch, step=1)
    assert REQUIRED_KEYS <= set(m)
    assert m["policy_version"] == 1.0 and learner.policy_version() == 1
    assert abs(m["logprob_diff"]) < 1e-5  # the samples' log-probs came from these weights
    assert m["kl_ref"] == pytest.approx(0.0, abs=1e-6) and m["grad_norm"] > 0 and m["entropy"] > 0
    after = learner.get_state_dict()
    lp0, lp1 = _logprobs(before, model_dir, batch), _logprobs(after, model_dir, batch)
    rewards = {}
    for s in batch:
        rewards.setdefault(s.group_id, []).append(s.reward)
    for i, s in enumerate(batch):
        mask = torch.tensor(s.loss_mask, dtype=torch.bool)
        delta = float((lp1[i, : len(s.input_ids)] - lp0[i, : len(s.input_ids)])[mask].mean())
        mean = sum(rewards[s.group_id]) / len(rewards[s.group_id])
        if s.reward > mean:
            assert delta > 0, s.sample_id
        elif s.reward < mean:
            assert delta < 0, s.sample_id
    # The second step sees a moved policy: positive KL to the frozen reference.
    m2 = learner.train_step(batch, step=2)
    assert m2["kl_ref"] > 0 and m2["policy_version"] == 2.0 and abs(m2["logprob_diff"]) > 0


def test_micro_batch_size_does_not_change_the_update(model_dir, batch):
    results = []
    for mbs in (1, 4, 6):
        learner = Learner(LearnerConfig(optim={"lr": 1e-3, "micro_batch_size": mbs}), model_dir)
        learner.train_step(batch)
        learner.train_step(batch)
        results.append(learner.get_state_dict())
    initial = load_policy(model_dir)[0].state_dict()
    moved = max(float((results[0][k] - initial[k]).abs().max()) for k in initial)
    assert moved > 1e-3
    # Equal up to float noise that Adam's normalisation amplifies on near-zero gradients (< 1 % of a step).
    for other in results[1:]:
        for k, v in results[0].items():
            assert torch.allclose(v, other[k], atol=2e-5), k


def test_packing_and_token_budget_micro_batches_do_not_change_the_update(model_dir, batch):
    """The same batch through padded micro-batches of 6, packed ones of 6 and packed ones cut by a token
    budget (so the batch is split differently) gives the same weights after two steps; packed, no
    decoder position is padding."""
    lengths = [len(s.input_ids) for s in batch]
    budget = max(lengths) + min(lengths)  # every micro-batch holds one or two samples, never all six
    results, padding = [], []
    for pack, optim in ((False, {"micro_batch_size": 6}), (True, {"micro_batch_size": 6}),
                        (True, {"micro_batch_size": 6, "max_tokens_per_micro_batch": budget})):
        learner = Learner(LearnerConfig(pack_sequences=pack, optim={"lr": 1e-3, **optim}), model_dir)
        metrics = learner.train_step(batch)
        learner.train_step(batch)
        results.append(learner.get_state_dict())
        padding.append(metrics["learner_padding_frac"])
    # padded: each of the six rows is padded to the longest (lengths differ in the fixture)
    assert padding[0] == pytest.approx(1 - sum(lengths) / (6 * max(lengths))) and padding[0] > 0.1
    assert padding[1] == padding[2] == 0.0
    for other in results[1:]:
        for k, v in results[0].items():
            assert torch.allclose(v, other[k], atol=2e-5), k


def _gradient_and_metrics(learner: Learner, batch) -> tuple[dict[str, torch.Tensor], dict[str, float]]:
    """One train step's gradient before clipping: each parameter's gradients summed over the
    micro-batches' backward passes (read by hooks as they arrive), and the step's metrics."""
    params = dict(learner._local.backend.policy.named_parameters())
    total = {k: torch.zeros_like(p) for k, p in params.items()}

    def add(name):
        def hook(grad):
            total[name].add_(grad)  # returns None: the gradient itself is left as it is
        return hook

    hooks = [p.register_hook(add(k)) for k, p in params.items()]
    try:
        metrics = learner.train_step(batch)
    finally:
        for h in hooks:
            h.remove()
    return total, metrics


def test_length_sorted_micro_batches_give_the_index_order_gradient(model_dir, batch):
    """Micro-batches of 2 cut in batch order and cut after sorting by length hold different pairs; the
    gradient and the loss are the same (every loss term is a share of the whole batch), and sorted,
    fewer of the decoder's positions are padding."""
    from modeling.model import split_by_budget, split_by_length

    lengths = [len(s.input_ids) for s in batch]
    by_index, by_length = split_by_budget(list(range(6)), lengths, 2), split_by_length(list(range(6)), lengths, 2)
    assert sorted(map(sorted, by_index)) != sorted(map(sorted, by_length))
    runs = {order: _gradient_and_metrics(Learner(LearnerConfig(  # padded: the padding share is compared
        pack_sequences=False, optim={"lr": 1e-3, "micro_batch_size": 2, "micro_batch_order": order}), model_dir), batch)
        for order in ("index", "length")}
    (g_index, m_index), (g_length, m_length) = runs["index"], runs["length"]
    scale = max(float(g.abs().max()) for g in g_index.values())
    assert scale > 1e-3
    for k, g in g_index.items():
        assert torch.allclose(g, g_length[k], rtol=1e-4, atol=1e-6 * scale), k
    assert m_length["loss"] == pytest.approx(m_index["loss"], rel=1e-5, abs=1e-7)
    assert m_length["grad_norm"] == pytest.approx(m_index["grad_norm"], rel=1e-5)

    def padding(groups):
        return 1 - sum(lengths) / sum(len(g) * max(lengths[i] for i in g) for g in groups)

    assert m_index["learner_padding_frac"] == pytest.approx(padding(by_index))
    assert m_length["learner_padding_frac"] == pytest.approx(padding(by_length))
    assert m_length["learner_padding_frac"] < m_index["learner_padding_frac"]


def test_auto_packing_packs_a_long_tail_and_pads_even_lengths(model_dir):
    """Under the sdpa_varlen attention the learner and teacher load with, a packed sequence attends
    on its own (sum of L^2): "auto" always packs. Plain sdpa masks a packed row densely: there "auto"
    packs a micro-batch only when its packed attention area N^2 is at most the padded B*T^2
    (docs/benchmarks.md, "Sequence packing")."""
    from modeling.attention import decoder_config
    from modeling.model import packs_sequences

    model, _ = load_policy(model_dir)
    long_tail = pad_batch([[5] * n for n in (96, 128, 160, 192, 256, 384, 1024, 2048)], 0)[1]
    even = pad_batch([[5] * n for n in (480, 496, 512, 512, 512, 528, 528, 544)], 0)[1]
    assert packs_sequences("auto", model, long_tail) and packs_sequences("auto", model, even)
    assert not packs_sequences(False, model, long_tail)
    decoder_config(model)._attn_implementation = "sdpa"
    assert packs_sequences("auto", model, long_tail) and not packs_sequences("auto", model, even)
    assert packs_sequences(True, model, even) and not packs_sequences(False, model, long_tail)


def test_token_budget_split_keeps_order_counts_and_a_long_sample_alone():
    from modeling.model import split_by_budget

    lengths = [10, 50, 30, 5, 5, 100]
    assert split_by_budget(list(range(6)), lengths, 3, 60) == [[0, 1], [2, 3, 4], [5]]
    assert split_by_budget(list(range(6)), lengths, 2) == [[0, 1], [2, 3], [4, 5]]
    assert split_by_budget([], lengths, 2, 10) == []


def test_length_split_groups_neighbours_longest_first_within_the_budget():
    from modeling.model import split_batches, split_by_length

    lengths = [10, 50, 30, 5, 5, 100]
    assert split_by_length(list(range(6)), lengths, 2) == [[5, 1], [2, 0], [3, 4]]
    assert split_by_length(list(range(6)), lengths, 3, 60) == [[5], [1], [2, 0, 3], [4]]
    assert split_by_length([0, 2, 4], lengths, 2) == [[2, 0], [4]]  # one rank's share
    assert split_batches("index", list(range(6)), lengths, 2) == [[0, 1], [2, 3], [4, 5]]
    with pytest.raises(ValueError, match="'length' or 'index'"):
        split_batches("random", list(range(6)), lengths, 2)


def test_multi_update_batches_use_a_fixed_old_policy_and_clip(model_dir, batch):
    learner = Learner(LearnerConfig(optim={"lr": 5e-2, "updates_per_batch": 3},
                                    loss={"grpo": {"clip_eps_low": 0.05, "clip_eps_high": 0.05}}), model_dir)
    m = learner.train_step(batch)
    # By the last of three large updates against a fixed pi_old some ratios leave [0.95, 1.05].
    assert m["clip_frac"] > 0
    assert learner.policy_version() == 1


def _teacher_outputs(model_dir, samples, drift: float = 0.0, **cfg):
    """Teacher outputs; `drift` perturbs the teacher's weights (a teacher the student has moved away from)."""
    t = Teacher(TeacherConfig(**cfg), model_dir, start_worker=False)
    if drift:
        gen = torch.Generator().manual_seed(7)
        t.hard_copy({k: v + drift * torch.randn(v.shape, generator=gen) for k, v in t.get_weights().items()})
    return TeacherBatch(outputs=t.compute(samples))


def test_teacher_packs_by_default_and_equals_its_padded_forward(model_dir, batch):
    """teacher.pack_sequences defaults to "auto", which packs under the sdpa_varlen attention the teacher
    loads with: none of its decoder positions are padding, its log-probs and top-k equal the padded
    forward's within 1e-5, and a sample's values are the same batched with the others or alone."""
    packed = Teacher(TeacherConfig(serve_topk=4), model_dir, start_worker=False)
    padded = Teacher(TeacherConfig(serve_topk=4, pack_sequences=False), model_dir, start_worker=False)
    a, b = packed.compute(batch), padded.compute(batch)
    assert all(o.padded_positions == 0 for o in a) and sum(o.padded_positions for o in b) > 0
    for x, y in zip(a, b):
        assert max(abs(u - v) for u, v in zip(x.logprobs, y.logprobs)) <= 1e-5
        assert max(abs(u - v) for p, q in zip(x.topk_logprobs, y.topk_logprobs) for u, v in zip(p, q)) <= 1e-5
    alone = packed.compute(batch[-1:])[0]
    assert max(abs(u - v) for u, v in zip(alone.logprobs, a[-1].logprobs)) <= 1e-6


def test_ttopd_step_reports_truncation_and_pulls_toward_the_teacher(model_dir, batch):
    outs = _teacher_outputs(model_dir, batch)
    cfg = LearnerConfig(optim={"lr": 5e-3},
                        loss={"grpo": {"kl_beta": 0.0}, "distill": {"enabled": True, "max_turn_tokens": 20}})
    learner = Learner(cfg, model_dir)
    total_turns = sum(len(s.turns) for s in batch)
    m = learner.train_step(batch, outs)
    assert m["turns_truncated"] > 0 and m["turns_truncated"] + m["turns_kept"] == total_turns
    assert m["kl_teacher"] != 0 and m["distill_loss"] != 0
    # With equal rewards (no policy gradient) repeated steps shrink KL(student || hinted teacher).
    flat = [s.model_copy(update={"reward": 0.0}) for s in batch]
    far = _teacher_outputs(model_dir, batch, drift=0.05)
    learner2 = Learner(cfg.model_copy(update={"loss": cfg.loss.model_copy(
        update={"distill": cfg.loss.distill.model_copy(update={"max_turn_tokens": 10_000, "estimator": "k3"})})}),
        model_dir)
    kls = [learner2.train_step(flat, far)["kl_teacher"] for _ in range(6)]
    assert kls[0] > 0.05 and kls[-1] < kls[0] * 0.7, kls


def test_topk_estimator_step(model_dir, batch):
    outs = _teacher_outputs(model_dir, batch, drift=0.05, serve_topk=8)
    cfg = LearnerConfig(optim={"lr": 5e-3},
                        loss={"grpo": {"kl_beta": 0.0}, "distill": {"enabled": True, "estimator": "topk", "topk": 8}})
    learner = Learner(cfg, model_dir)
    flat = [s.model_copy(update={"reward": 0.0}) for s in batch]
    kls = [learner.train_step(flat, outs)["kl_teacher"] for _ in range(6)]
    # Over 8 of 2048 tokens of a near-uniform tiny model the coarsened KL is small, but it must shrink.
    assert kls[0] > 1e-3 and kls[-1] < kls[0] * 0.7, kls
    too_big = cfg.model_copy(update={"loss": cfg.loss.model_copy(
        update={"distill": cfg.loss.distill.model_copy(update={"topk": 16})})})
    with pytest.raises(ValueError, match="top-8"):
        Learner(too_big, model_dir).train_step(flat, outs)


def test_weights_roundtrip_and_evaluate_does_not_update(model_dir, batch):
    learner = Learner(LearnerConfig(optim={"lr": 1e-3}), model_dir)
    w0 = learner.get_state_dict()
    model, _ = load_policy(model_dir)
    assert set(w0) == set(model.state_dict())
    m = learner.evaluate_loss(batch)
    assert "policy_loss" in m and learner.policy_version() == 0
    assert all(torch.equal(w0[k], v) for k, v in learner.get_state_dict().items())
    shifted = {k: v + 0.01 for k, v in w0.items()}
    learner.set_weights(shifted)
    assert all(torch.equal(shifted[k], v) for k, v in learner.get_state_dict().items())


def test_bad_inputs_fail_with_named_errors(model_dir, batch):
    cfg = LearnerConfig(loss={"distill": {"enabled": True}})
    learner = Learner(cfg, model_dir)
    with pytest.raises(ValueError, match=batch[0].sample_id):
        learner.train_step(batch, teacher=None)
    outs = _teacher_outputs(model_dir, batch)
    wrong = TeacherBatch(outputs=[o.model_copy(update={"input_length": o.input_length + 1, "logprobs": o.logprobs + [0.0]})
                                  for o in outs.outputs])
    with pytest.raises(ValueError, match="positions"):
        learner.train_step(batch, wrong)
    with pytest.raises(ValueError, match="empty"):
        learner.train_step([])
    with pytest.raises(ValueError, match="duplicate"):
        learner.train_step(batch + batch[:1], outs)
    with pytest.raises(ValueError, match="world_size"):
        LearnerConfig(backend="torch", deepspeed={"world_size": 2})
    with pytest.raises(ValueError, match="lr"):
        LearnerConfig(optim={"lr": -1})
    with pytest.raises(ValueError, match="extra|learning_rate"):
        LearnerConfig(optim={"learning_rate": 1e-3})


def test_entropy_bonus_raises_entropy(model_dir, batch):
    flat = [s.model_copy(update={"reward": 0.0}) for s in batch]  # no policy gradient, no KL: only the bonus
    learner = Learner(LearnerConfig(optim={"lr": 1e-2}, loss={"grpo": {"kl_beta": 0.0}, "entropy_coef": 1.0}),
                      model_dir)
    ent = [learner.train_step(flat)["entropy"] for _ in range(3)]
    assert ent[-1] > ent[0], ent
    # Without the bonus the same batch leaves the weights untouched (zero advantages, zero gradient).
    idle = Learner(LearnerConfig(optim={"lr": 1e-2}, loss={"grpo": {"kl_beta": 0.0}}), model_dir)
    w0 = idle.get_state_dict()
    assert idle.train_step(flat)["grad_norm"] == 0.0
    assert all(torch.equal(w0[k], v) for k, v in idle.get_state_dict().items())


@pytest.mark.parametrize("weight", [0.0, 0.25])
def test_negative_advantage_weight_scales_only_failures(model_dir, batch, weight):
    from learner.losses import group_advantages

    adv = group_advantages([s.reward for s in batch], [s.group_id for s in batch])
    assert bool((adv < 0).any()) and bool((adv > 0).any())
    expected = float(torch.where(adv < 0, adv * weight, adv).abs().mean())
    learner = Learner(LearnerConfig(optim={"lr": 2e-3}, loss={"grpo": {"negative_advantage_weight": weight}}),
                      model_dir)
    before = learner.get_state_dict()
    m = learner.train_step(batch, step=1)
    assert m["advantage_abs_mean"] == pytest.approx(expected, rel=1e-5)
    if weight == 0.0:  # only successes are reinforced: each of them becomes more likely
        lp0, lp1 = _logprobs(before, model_dir, batch), _logprobs(learner.get_state_dict(), model_dir, batch)
        for i, s in enumerate(batch):
            if adv[i] > 0:
                mask = torch.tensor(s.loss_mask, dtype=torch.bool)
                assert float((lp1[i, : len(s.input_ids)] - lp0[i, : len(s.input_ids)])[mask].mean()) > 0
