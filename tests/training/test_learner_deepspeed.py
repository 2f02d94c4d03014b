"""DeepSpeed ZeRO-3 on CPU (gloo), 2 ranks as Ray actors, against the torch backend; and the actors over Ray."""

from __future__ import annotations

import pytest
import torch

from actors.types import PendingTeacherBatch, TeacherBatch
from modeling.checkpoint import checkpoint_dir
from modeling.config_models import LearnerConfig, TeacherConfig
from learner.learner_actor import Learner, LearnerActor
from tests.training.learner_fixtures import make_batch, tiny_model_dir

pytestmark = pytest.mark.ray

COMPARED = ("loss", "policy_loss", "kl_ref_loss", "distill_loss", "kl_ref", "kl_teacher", "entropy", "grad_norm",
            "logprob_diff")


def _cfg(backend: str) -> LearnerConfig:
    # GRPO + KL to the reference + TT-OPD distillation with turn truncation: every loss term is compared.
    return LearnerConfig(backend=backend, optim={"lr": 1e-3, "micro_batch_size": 2},
                         loss={"distill": {"enabled": True, "estimator": "k3", "max_turn_tokens": 20}},
                         deepspeed={"world_size": 2 if backend == "deepspeed" else 1, "num_cpus_per_rank": 1})


def _teacher_outputs(model_dir, batches):
    from actors.teacher import Teacher

    teacher = Teacher(TeacherConfig(), model_dir, start_worker=False)
    gen = torch.Generator().manual_seed(3)
    teacher.hard_copy({k: v + 0.03 * torch.randn(v.shape, generator=gen) for k, v in teacher.get_weights().items()})
    return [TeacherBatch(outputs=teacher.compute(b)) for b in batches]


def test_zero3_two_ranks_match_the_torch_backend_and_resume(ray_cluster, tmp_path):
    model_dir = tiny_model_dir()
    # 7 samples: the ranks get 4 and 3, so one rank runs a padding micro-batch (2+2 vs 2+1).
    batches = [make_batch(seed=s, groups=2, group_size=3, model_dir=model_dir) for s in range(3)]
    extra = make_batch(seed=9, groups=1, group_size=1, model_dir=model_dir)[0]
    batches[0] = batches[0] + [extra.model_copy(update={"sample_id": "g9:0", "group_id": "g9"})]
    teacher = _teacher_outputs(model_dir, batches)
    torch_learner = Learner(_cfg("torch"), model_dir)
    ds = Learner(_cfg("deepspeed"), model_dir)
    try:
        for step in (1, 2):
            a = ds.train_step(batches[step - 1], teacher[step - 1], step=step)
            b = torch_learner.train_step(batches[step - 1], teacher[step - 1], step=step)
            assert a["distill_loss"] > 0 and a["turns_truncated"] == b["turns_truncated"] > 0
            # Both backends load with sdpa_varlen, so "auto" packs every micro-batch (and the teacher's).
            assert a["learner_padding_frac"] == b["learner_padding_frac"] == a["teacher_padding_frac"] == 0.0
            for key in COMPARED:
                assert a[key] == pytest.approx(b[key], rel=1e-4, abs=1e-6), (step, key, a[key], b[key])
        wa, wb = ds.get_state_dict(), torch_learner.get_state_dict()
        assert set(wa) == set(wb) and all(v.shape == wb[k].shape for k, v in wa.items())
        # Adam amplifies float noise on near-zero gradients; 2 steps of lr 1e-3 move weights ~2e-3.
        assert max(float((wa[k] - wb[k]).abs().max()) for k in wb) < 5e-5

        # Resume under ZeRO-3: our per-rank fp32 partitions + weights-only optimizer states.
        ckpt = checkpoint_dir(tmp_path, 2)
        ds.save_checkpoint(str(ckpt))
        assert (ckpt / "learner" / "fp32_partition_rank1.safetensors").exists()
        ds.train_step(batches[2], teacher[2], step=3)
        straight = ds.get_state_dict()
        ds.load_checkpoint(str(ckpt))
        assert ds.policy_version() == 2
        restored = ds.get_state_dict()
        assert all(torch.equal(restored[k], wa[k]) for k in wa)
        ds.train_step(batches[2], teacher[2], step=3)
        again = ds.get_state_dict()
        assert all(torch.equal(again[k], straight[k]) for k in straight)
    finally:
        ds.shutdown()


def test_zero3_with_offload_and_gradient_checkpointing_matches_the_torch_backend(ray_cluster):
    """Parameter and optimizer offload with a client torch optimizer, and gradient checkpointing: the
    settings `hcgym plan` names when a config does not fit its GPUs, which the shipped 9B configs do
    not use. They change where tensors live and when activations are recomputed, not the update."""
    model_dir = tiny_model_dir()
    batches = [make_batch(seed=s, groups=2, group_size=3, model_dir=model_dir) for s in range(2)]
    teacher = _teacher_outputs(model_dir, batches)
    # Both padded: this compares offload and checkpointing with the torch backend, at the float noise
    # (amplified by Adam on near-zero gradients) its 5e-5 bound was set for; packing has its own
    # equality tests (test_learner.py, test_hf_checkpoint.py) and the other ZeRO-3 tests here pack.
    # Both in batch order too: length-ordered micro-batches have their own gradient test (test_learner.py), and
    # regrouping the samples draws another realisation of the same float noise (1.2e-4 here by length).
    offloaded = _cfg("deepspeed").model_copy(update={"gradient_checkpointing": True, "pack_sequences": False})
    offloaded.optim = offloaded.optim.model_copy(update={"micro_batch_order": "index"})
    offloaded.deepspeed = offloaded.deepspeed.model_copy(update={"offload_param": True, "offload_optimizer": True})
    reference = _cfg("torch").model_copy(update={"pack_sequences": False})
    reference.optim = reference.optim.model_copy(update={"micro_batch_order": "index"})
    torch_learner = Learner(reference, model_dir)
    ds = Learner(offloaded, model_dir)
    try:
        for step in (1, 2):
            a = ds.train_step(batches[step - 1], teacher[step - 1], step=step)
            b = torch_learner.train_step(batches[step - 1], teacher[step - 1], step=step)
            for key in COMPARED:
                assert a[key] == pytest.approx(b[key], rel=1e-4, abs=1e-6), (step, key, a[key], b[key])
        wa, wb = ds.get_state_dict(), torch_learner.get_state_dict()
        assert max(float((wa[k] - wb[k]).abs().max()) for k in wb) < 5e-5
    finally:
        ds.shutdown()


def test_learner_and_teacher_actors_exchange_weights_through_the_object_store(ray_cluster):
    import ray

    from actors.teacher import TeacherActor

    model_dir = tiny_model_dir()
    batch = make_batch(seed=1, groups=2, group_size=3, model_dir=model_dir)
    learner = LearnerActor.options(num_cpus=0).remote(
        LearnerConfig(optim={"lr": 1e-2}, loss={"distill": {"enabled": True}}), model_dir, 0)
    teacher = TeacherActor.options(num_cpus=0).remote(TeacherConfig(ema_interval=1, hard_copy_interval=3), model_dir)
    try:
        ray.get(teacher.submit.remote(batch))
        # The fetch's ref goes to the learner unresolved (PendingTeacherBatch); it blocks on it after its
        # reference forward.
        fetch_ref = teacher.fetch.remote([s.sample_id for s in batch], 60.0)
        metrics = ray.get(learner.train_step.remote(batch, PendingTeacherBatch(fetch_ref), 1))
        assert metrics["policy_version"] == 1.0 and metrics["distill_tokens"] > 0
        assert metrics["teacher_wait_s"] >= 0 and metrics["kl_teacher"] != 0
        got = ray.get(fetch_ref)
        weights_ref = learner.get_weights.remote()  # passed on as a ref: never through this process
        first = ray.get(teacher.update.remote(weights_ref, 1))
        assert first["action"] == "ema" and first["teacher_version"] == 1
        ray.get(learner.train_step.remote(batch, got, 2))
        ray.get(teacher.update.remote(learner.get_weights.remote(), 2))
        ray.get(learner.train_step.remote(batch, got, 3))
        copy = ray.get(teacher.update.remote(learner.get_weights.remote(), 3))
        assert copy["action"] == "hard_copy"
        student, taught = ray.get(learner.get_weights.remote()), ray.get(teacher.get_weights.remote())
        assert all(torch.equal(student[k], taught[k]) for k in student)
        # A teacher failure surfaces from train_step before any update: the step can be retried.
        missing = teacher.fetch.remote(["never-submitted"], 5.0)
        with pytest.raises(KeyError, match="never-submitted"):
            ray.get(learner.train_step.remote(batch, PendingTeacherBatch(missing), 4))
        assert ray.get(learner.policy_version.remote()) == 3
        after = ray.get(learner.get_weights.remote())
        assert all(torch.equal(student[k], after[k]) for k in student)
    finally:
        ray.kill(learner)
        ray.kill(teacher)
