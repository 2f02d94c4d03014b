"""Collective weight sync (the GPU transport) run with gloo on CPU: buckets, streaming into models, timeouts."""

from __future__ import annotations

import threading

import pytest
import torch

from actors.teacher import Teacher
from modeling.config_models import LearnerConfig, TeacherConfig, WeightSyncConfig
from learner.learner_actor import Learner, free_port
from modeling.model import load_policy
from modeling.weight_sync import (
    TensorSpec,
    WeightSyncError,
    WeightSyncGroup,
    load_state_dict_into,
    manifest_from_tensors,
    plan_buckets,
)
from tests.training.learner_fixtures import make_batch, tiny_model_dir


def _cfg(**kw) -> WeightSyncConfig:
    return WeightSyncConfig(transport="collective", backend="gloo", master_port=free_port(), **kw)


def _run_all(fns: list) -> list:
    """Run group members concurrently (they block on each other); re-raise the first error."""
    results, errors = [None] * len(fns), [None] * len(fns)

    def wrap(i, fn):
        try:
            results[i] = fn()
        except BaseException as exc:  # noqa: BLE001
            errors[i] = exc

    threads = [threading.Thread(target=wrap, args=(i, fn), daemon=True) for i, fn in enumerate(fns)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    for e in errors:
        if e is not None:
            raise e
    return results


def test_bucket_plan_respects_cap_dtype_and_order():
    specs = [TensorSpec(name=f"t{i}", shape=[n], dtype=d) for i, (n, d) in enumerate(
        [(10, "torch.float32"), (10, "torch.float32"), (30, "torch.float32"), (5, "torch.bfloat16"),
         (5, "torch.bfloat16"), (100, "torch.float32")])]
    buckets = plan_buckets(specs, bucket_bytes=100)  # 25 float32 per bucket
    assert buckets == [[0, 1], [2], [3, 4], [5]]     # t2 and t5 exceed the cap alone; dtype change splits
    assert [i for b in buckets for i in b] == list(range(len(specs)))
    with pytest.raises(ValueError):
        plan_buckets(specs, 0)


def test_learner_streams_weights_to_a_model_and_the_ema_teacher():
    model_dir = tiny_model_dir()
    learner = Learner(LearnerConfig(optim={"lr": 1e-2}), model_dir)
    learner.train_step(make_batch(seed=2, model_dir=model_dir))
    generator_model, _ = load_policy(model_dir)
    teacher = Teacher(TeacherConfig(ema_alpha=0.5, ema_interval=1, hard_copy_interval=0), model_dir, start_worker=False)
    teacher_before = teacher.get_weights()
    cfg = _cfg(bucket_mb=0.25)  # 256 KiB buckets: the ~1.3 MB tiny model travels in several
    names = ["learner-rank0", "generator-0", "teacher"]
    rx_gen = {}

    def gen_side():
        group = WeightSyncGroup(1, 3, cfg, names)
        rx_gen["n"] = group.receive_into(generator_model, version=1)

    def teacher_side():
        teacher.join_weight_sync(cfg.model_dump(), 2, 3, names)
        return teacher.receive_update(version=1, step=1)

    def learner_side():
        learner.join_weight_sync(cfg.model_dump(), 3, names)
        return learner.broadcast_weights()

    sent, _, t_out = _run_all([learner_side, gen_side, teacher_side])
    student = learner.get_state_dict()
    assert sent["buckets"] > 3 and sent["version"] == 1.0
    assert rx_gen["n"] == len(student)
    assert all(torch.equal(generator_model.state_dict()[k], v) for k, v in student.items())
    assert t_out["action"] == "ema" and teacher.teacher_version() == 1
    got = teacher.get_weights()
    for k, v in student.items():
        assert torch.allclose(got[k], 0.5 * teacher_before[k] + 0.5 * v, atol=1e-6)


def test_a_receiver_that_never_joins_is_named_in_the_error():
    cfg = _cfg(timeout_s=1.0)
    names = ["learner-rank0", "generator-0", "generator-1"]

    def sender():
        WeightSyncGroup(0, 3, cfg, names)

    def present():
        try:
            WeightSyncGroup(1, 3, cfg, names)
        except WeightSyncError:
            pass  # it times out too; the sender's message is what the test checks

    with pytest.raises(WeightSyncError, match="generator-1") as info:
        _run_all([sender, present])
    assert "generator-0" not in str(info.value)


def test_a_receiver_names_the_sender_that_never_publishes():
    cfg = _cfg(timeout_s=1.0)
    names = ["learner-rank0", "generator-0"]
    groups = _run_all([lambda: WeightSyncGroup(0, 2, cfg, names), lambda: WeightSyncGroup(1, 2, cfg, names)])
    with pytest.raises(WeightSyncError, match="learner-rank0"):
        list(groups[1].receive(version=7))  # the sender never starts sync v7


def test_sender_checks_the_stream_against_the_manifest_and_receivers_check_shapes():
    cfg = _cfg(timeout_s=2.0)
    names = ["learner-rank0", "generator-0"]
    groups = _run_all([lambda: WeightSyncGroup(0, 2, cfg, names), lambda: WeightSyncGroup(1, 2, cfg, names)])
    manifest = manifest_from_tensors([("a", [2, 2], torch.float32)], version=1, bucket_bytes=1 << 20)
    with pytest.raises(WeightSyncError, match="manifest expects 'a'"):
        groups[0].send(manifest, iter([("b", torch.zeros(2, 2))]))
    with pytest.raises(WeightSyncError, match="missing"):
        load_state_dict_into(torch.nn.Linear(2, 2), {"weight": torch.zeros(2, 2)})
