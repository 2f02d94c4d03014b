"""A full disk is an error, not a loss: writes that meet ENOSPC stop with an error naming the file
and saying that the disk is full, keep what was complete (no half file, no torn line, the previous
checkpoint), and a run resumes after space is freed with nothing lost or doubled.

The disk is a real 48 MiB tmpfs (tests/small_disk.py) filled by a ballast file, so every error is
the kernel's own ENOSPC as each library reports it (torch.save and pyarrow lose the errno on the
way up); the training run fills it at an exact point of the write sequence (learner.faults.at).
"""

from __future__ import annotations

import re

import pytest
import torch

from envs.core.files import DiskFullError
from learner import faults
from learner.metrics import MetricsSink, read_metrics, read_samples, write_samples
from modeling.checkpoint import checkpoint_dir, latest_checkpoint, save_torch_state, temp_files, write_json_atomic
from tests.small_disk import small_disk
from tests.training.test_train import tiny_config


@pytest.fixture(autouse=True)
def no_fault_action_left_behind():
    yield
    faults.clear_actions()  # a test that failed before its point must not leave the action to a later run


@pytest.fixture(scope="module")
def disk():
    with small_disk(48) as mounted:
        yield mounted


@pytest.fixture
def empty_disk(disk):
    disk.free()
    disk.clear()
    yield disk
    disk.free()
    disk.clear()


def full_disk_error(path) -> str:
    return rf"{re.escape(str(path))}: the disk is full \(\d[\d,]* bytes free"


def test_writes_on_a_full_disk_name_the_file_and_leave_nothing_half_written(empty_disk):
    import random

    from tests.training.learner_fixtures import make_sample

    run = empty_disk.root / "run"
    sink = MetricsSink(run, tensorboard=False, ray_metrics=False)
    sink.write({"step": 1, "reward_mean": 0.5})
    rows_before = sink.path.read_bytes()
    rng = random.Random(0)
    samples = [make_sample(rng, group_id="g", index=i, prompt_len=2000, turn_lens=[500, 500]) for i in range(4)]
    empty_disk.fill()

    # A metrics row larger than what is left: the append is cut back, no torn line stays.
    with pytest.raises(DiskFullError, match=full_disk_error(sink.path)):
        sink.write({"step": 2, "note": "x" * 50_000})
    assert sink.path.read_bytes() == rows_before
    # pyarrow says "[Errno 28] Error writing bytes to file" with no path; the file is named, and no
    # half file stays under the step's name.
    trajectories = run / "trajectories" / "step_000002.parquet"
    with pytest.raises(DiskFullError, match=full_disk_error(trajectories)):
        write_samples(samples, trajectories, step=2)
    # torch.save says "basic_ios::clear" / "file write failed" with no errno: the disk is checked.
    optimizer = run / "checkpoints" / "step_000002" / "learner" / "optimizer.pt"
    with pytest.raises(DiskFullError, match=full_disk_error(optimizer)):
        save_torch_state(optimizer, {"exp_avg": torch.zeros(200_000)})
    state = run / "checkpoints" / "step_000002" / "driver.json"
    with pytest.raises(DiskFullError, match=full_disk_error(state)):
        write_json_atomic(state, {"readmit": ["x" * 100] * 1000})
    assert not trajectories.exists() and not optimizer.exists() and not state.exists()
    assert temp_files(run) == []

    empty_disk.free()  # the same writes succeed once there is room
    sink.write({"step": 2, "note": "x" * 50_000})
    assert [r["step"] for r in read_metrics(run)] == [1, 2]
    write_samples(samples, trajectories, step=2)
    assert len(read_samples(trajectories)[0]) == 4


def test_a_checkpoint_on_a_full_disk_stops_the_run_naming_it_and_resume_after_freeing_space_loses_nothing(
        ray_cluster, ward_policy_dir, empty_disk):
    from learner.train import train

    run = empty_disk.root / "run"
    cfg = tiny_config(run, ward_policy_dir, rollout={"num_env_actors": 1},
                      trainer={"max_steps": 2, "checkpoint_interval": 1, "keep_checkpoints": 5},
                      metrics={"tensorboard": False, "ray_metrics": False, "progress": False})
    # Step 1 is complete (checkpoint `latest`, metrics row, trajectories); then the disk fills, so
    # step 2's checkpoint is the first write to fail.
    faults.at("latest_marked:1", empty_disk.fill)
    with pytest.raises(DiskFullError) as info:
        train(cfg, log=lambda line: None)
    message = str(info.value)
    print(f"[figures] {message}")
    # The file of step 2's checkpoint that met the full disk (the learner's first write there).
    assert re.search(rf"{re.escape(str(checkpoint_dir(run, 2)))}/\S+: the disk is full", message), message
    assert "`latest` still names step_000001" in message, message
    assert f"the last complete checkpoint is {checkpoint_dir(run, 1)}" in message and "--resume" in message, message
    # What was complete is kept; nothing of step 2 is.
    assert latest_checkpoint(run) == checkpoint_dir(run, 1)
    assert not checkpoint_dir(run, 2).exists() and temp_files(run) == []
    assert [r["step"] for r in read_metrics(run)] == [1]
    assert sorted(p.name for p in (run / "trajectories").iterdir()) == ["step_000001.parquet"]

    empty_disk.free()
    logs: list[str] = []
    summary = train(cfg, resume=True, log=logs.append)
    assert summary["steps"] == 2
    assert any(line.startswith("[resume] restored step 1") for line in logs), logs[-5:]
    assert [r["step"] for r in read_metrics(run)] == [1, 2]
    assert sorted(p.name for p in (run / "trajectories").iterdir()) == [f"step_{s:06d}.parquet" for s in (1, 2)]
    assert latest_checkpoint(run) == checkpoint_dir(run, 2) and temp_files(run) == []
