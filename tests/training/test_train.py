"""The driver end to end on local Ray with the tiny model and the ward test domain."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
import torch

from modeling.checkpoint import load_tensors
from learner.config import validate_config
from modeling.hf_checkpoint import read_checkpoint_tensors
from learner.metrics import REQUIRED_KEYS, read_metrics, read_samples
from tests.training.conftest import NO_EMBEDDINGS

pytestmark = pytest.mark.ray
WARD = {"ward": "tests.fixtures.ward_domain.environment"}


def tiny_config(run_dir, policy_dir, **sections):
    """A run config small enough for a test: 2 groups of 2 episodes per step, 2 turns of 8 tokens."""
    data = {
        "name": "test", "seed": 3, "output_dir": str(run_dir),
        "model": {"kind": "pretrained", "path": policy_dir},
        "data": {"domains": ["ward"], "domain_modules": WARD, "train_split": "train", "val_split": "test"},
        "rollout": {"group_size": 2, "max_turns": 2, "max_new_tokens_per_turn": 8, "max_response_tokens": 200,
                    "num_env_actors": 2, "slots_per_env_actor": 4, "env_vars": NO_EMBEDDINGS},
        "generator": {"num_cpus": 0, "max_batch_size": 8, "batch_wait_s": 0.005},
        "trainer": {"batch_size": 2, "max_steps": 4, "max_staleness": 0, "checkpoint_interval": 2,
                    "val_interval": 0, "val_at_start": False, "dynamic_sampling": {"enabled": False}},
        # A random policy rarely varies its reward within a group; the entropy bonus keeps every
        # step's gradient non-zero, so the resume test compares weights that really moved.
        "learner": {"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01}},
        "ray": {"learner_num_cpus": 0},
        "metrics": {"tensorboard": True, "ray_metrics": True},
    }
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value} if isinstance(value, dict) else value
    return validate_config(data)


def final_weights(run_dir):
    from modeling.checkpoint import latest_checkpoint

    return read_checkpoint_tensors(latest_checkpoint(run_dir) / "learner" / "policy")


def test_grpo_runs_streams_on_policy_and_resumes_exactly(ray_cluster, ward_policy_dir, tmp_path):
    from learner.train import replay_loss, train

    logs: list[str] = []
    cfg = tiny_config(tmp_path / "straight", ward_policy_dir,
                      trainer={"val_interval": 2, "val_at_start": True, "keep_checkpoints": 2})
    summary = train(cfg, log=logs.append)
    assert summary["steps"] == 4

    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == [1, 2, 3, 4]
    for r in records:
        missing = [k for k in REQUIRED_KEYS if k not in r]
        assert not missing, f"step {r['step']} lacks {missing}"
        assert all(math.isfinite(r[k]) for k in REQUIRED_KEYS)
        assert r["policy_lag_max"] == 0  # staleness 0: strictly on-policy
        assert r["grad_norm"] > 0 and r["trajectories_per_s"] > 0
        # The generators sampled with exactly the learner's weights of the previous step.
        assert r["logprob_abs_diff"] < 1e-3, r["logprob_abs_diff"]
    assert sum(1 for line in logs if line.startswith("step ")) == 4  # one progress line per step
    val = [json.loads(line) for line in (tmp_path / "straight" / "validation.jsonl").read_text().splitlines()]
    assert [v["step"] for v in val] == [0, 2, 4] and all("val_accuracy" in v for v in val)
    assert "val_reward_mean" in records[1] and "val_reward_mean" not in records[0]

    # Every token of step s was sampled by policy version s - 1; trajectories replay into the loss.
    for step in range(1, 5):
        samples, extras = read_samples(tmp_path / "straight" / "trajectories" / f"step_{step:06d}.parquet")
        assert len(samples) == 4
        versions = {v for s in samples for v, m in zip(s.policy_versions, s.loss_mask) if m}
        assert versions == {step - 1}
    replayed = replay_loss(tmp_path / "straight" / "trajectories" / "step_000001.parquet", ward_policy_dir, cfg)
    assert math.isfinite(replayed["loss"])
    assert replayed["logprob_abs_diff"] < 1e-3  # step 1 was sampled by exactly these weights

    # 2 steps + resume + 2 steps ends with identical weights. The first two steps of the straight
    # run are the "2 steps": its step-2 checkpoint is all that a run stopped there leaves behind.
    from modeling.checkpoint import mark_latest

    split = tmp_path / "split"
    shutil.copytree(tmp_path / "straight", split, ignore=shutil.ignore_patterns("step_000004*"))
    mark_latest(split, 2)
    train(tiny_config(split, ward_policy_dir), resume=True, log=logs.append)
    assert any(line.startswith("[resume] restored step 2") for line in logs)
    assert [r["step"] for r in read_metrics(split)] == [1, 2, 3, 4]
    a, b = final_weights(tmp_path / "straight"), final_weights(split)
    assert a.keys() == b.keys()
    changed = [k for k in a if not (a[k] == b[k]).all()]
    assert not changed, f"resumed run differs in {changed[:3]}"
    first = read_checkpoint_tensors(split / "checkpoints" / "step_000002" / "learner" / "policy")
    assert any(not (first[k] == a[k]).all() for k in a), "steps 3-4 did not change the weights"

    from learner.plot import plot_runs

    png = plot_runs([tmp_path / "straight", tmp_path / "split"])
    assert png.exists() and png.stat().st_size > 10_000


def test_ttopd_streams_with_staleness_and_updates_the_teacher(ray_cluster, ward_policy_dir, tmp_path):
    from learner.train import train

    cfg = tiny_config(
        tmp_path / "ttopd", ward_policy_dir,
        trainer={"max_steps": 3, "max_staleness": 1, "checkpoint_interval": 0},
        reward={"kind": "cosine", "max_length": 100},
        teacher={"enabled": True, "ema_interval": 1, "hard_copy_interval": 3, "ema_alpha": 0.5},
        learner={"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01, "distill": {"enabled": True, "lambda_distill": 1.0,
                                                                       # a random policy's turns all hit the
                                                                       # token limit; keep them in the KL
                                                                       "drop_length_truncated_turns": False}}},
    )
    summary = train(cfg, log=lambda line: None)
    records = read_metrics(cfg.output_dir)
    assert [r["teacher_action"] for r in records] == [1.0, 1.0, 2.0]  # ema, ema, hard copy
    assert [r["teacher_updates"] for r in records] == [1.0, 2.0, 3.0]
    assert all(r["kl_teacher"] != 0 for r in records)  # the hint alone moves the teacher
    assert max(r["policy_lag_max"] for r in records) <= 1
    # Rollouts for the next step ran while the learner trained: some step used version-lagged tokens.
    assert summary["counters"]["groups_admitted"] > 3 * 2
    for step in (1, 2, 3):
        samples, extras = read_samples(tmp_path / "ttopd" / "trajectories" / f"step_{step:06d}.parquet")
        for s in samples:
            assert extras[s.sample_id]["teacher_logprobs"] is not None
            assert -0.5 - 1e-9 <= s.reward <= 1.1 + 1e-9  # Eq. 4's range
    status = summary["group_status"]
    assert status.get("cancelled", 0) == 0 and status.get("in_flight", 0) == 0
    assert summary["ledger"]["in_flight"] == 0


def test_collective_weight_sync_over_gloo(ray_cluster, ward_policy_dir, tmp_path):
    """The GPU transport's code path on CPU: learner rank 0 broadcasts to the generators in buckets."""
    from learner.train import train

    cfg = tiny_config(tmp_path / "collective", ward_policy_dir,
                      generator={"num_generators": 2},
                      trainer={"max_steps": 3, "checkpoint_interval": 0},
                      weight_sync={"transport": "collective", "backend": "gloo", "bucket_mb": 0.05, "timeout_s": 60})
    train(cfg, log=lambda line: None)
    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == [1, 2, 3]
    for r in records:
        assert r["logprob_abs_diff"] < 1e-3, r  # generators hold the learner's weights of step - 1
        assert r["policy_lag_max"] == 0


def ttopd_config(run_dir, policy_dir, **sections):
    """TT-OPD on the tiny config: teacher schedule none, EMA, hard copy over steps 1-3, repeating."""
    teacher = {"enabled": True, "ema_interval": 2, "hard_copy_interval": 3, "ema_alpha": 0.5, **sections.pop("teacher", {})}
    return tiny_config(
        run_dir, policy_dir, teacher=teacher,
        learner={"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01, "distill": {"enabled": True, "lambda_distill": 1.0,
                                                                       "drop_length_truncated_turns": False}}},
        **sections,
    )


def teacher_weights(run_dir):
    from modeling.checkpoint import latest_checkpoint

    return load_tensors(latest_checkpoint(run_dir) / "teacher" / "teacher.safetensors")


# The object-store run is the session fixture `ttopd_store_run` (tests/conftest.py), which the viewer
# tests serve too; the collective run here differs from it only in `weight_sync`.
STORE_VS_GROUP_STEPS = {"max_steps": 3, "checkpoint_interval": 0, "val_at_start": True}


def test_teacher_updates_over_the_collective_group_equal_the_object_store_path(ray_cluster, ward_policy_dir,
                                                                               ttopd_store_run, tmp_path):
    """Collective weight sync: the teacher is a member of the group and applies EMA / hard copy bucket
    by bucket; nothing goes through the object store, and the result is bit-identical to the
    object-store path (staleness 0 makes both runs deterministic)."""
    from learner.train import train

    by_group = ttopd_config(tmp_path / "group", ward_policy_dir, trainer=STORE_VS_GROUP_STEPS,
                            weight_sync={"transport": "collective", "backend": "gloo", "bucket_mb": 0.05,
                                         "timeout_s": 60})
    summary = train(by_group, log=lambda line: None)
    store, group = read_metrics(ttopd_store_run), read_metrics(by_group.output_dir)
    assert [r["teacher_action"] for r in group] == [0.0, 1.0, 2.0]  # none, EMA, hard copy
    assert [r["teacher_updates"] for r in group] == [0.0, 1.0, 2.0]
    # The object-store path counts every update it carried; the collective run used it for none.
    assert [r["teacher_sync_object_store"] for r in store] == [0.0, 1.0, 2.0]
    assert store[-1]["teacher_sync_object_store_bytes"] > 0 and store[-1]["teacher_sync_collective_bytes"] == 0
    assert all(r["teacher_sync_object_store"] == 0 and r["teacher_sync_object_store_bytes"] == 0 for r in group)
    # The teacher received every broadcast (also step 1's, whose stream it dropped): the model's bytes
    # each time, about what one object-store update moves (its size in the store: tensors + framing).
    per_sync = group[0]["teacher_sync_collective_bytes"]
    assert [r["teacher_sync_collective_bytes"] for r in group] == [per_sync, 2 * per_sync, 3 * per_sync]
    assert per_sync <= store[-1]["teacher_sync_object_store_bytes"] / 2 < 1.05 * per_sync
    assert summary["counters"]["teacher_sync_object_store"] == 0
    for a, b in zip(store, group):
        assert (a["kl_teacher"], a["loss"], a["grad_norm"]) == (b["kl_teacher"], b["loss"], b["grad_norm"]), a["step"]
        assert b["logprob_abs_diff"] < 1e-3  # the generators hold the learner's weights too
    ta, tb = teacher_weights(ttopd_store_run), teacher_weights(tmp_path / "group")
    assert ta.keys() == tb.keys()
    assert not [k for k in ta if not torch.equal(ta[k], tb[k])], "collective teacher update differs"
    initial = {}
    for shard in Path(ward_policy_dir).glob("*.safetensors"):
        initial.update(load_tensors(shard))
    assert any(not torch.equal(initial[k], tb[k]) for k in tb if k in initial), "the teacher never moved"
