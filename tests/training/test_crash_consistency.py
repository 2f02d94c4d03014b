"""Nothing lost, nothing doubled across a crash of the training driver.

The driver is killed (SIGKILL, through the `HCGYM_FAULT_AT` hook of learner/faults.py) at the last
point before a checkpoint becomes `latest`, its last metrics line is torn as a full disk tears it,
and a learner's interrupted write leaves a temporary file in the unfinished checkpoint; `--resume`
must then end with contiguous metrics steps, one trajectory file per step, one validation row per
validation step, and no temporary file in any checkpoint. The resumed run (in this process) also
checks the order of the write sequence at every step: `latest` moves last.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from learner.config import dump_config
from learner.metrics import MetricsSink, read_jsonl_rows, read_metrics
from learner.run_actors import orphaned_ray_agents, reap_orphaned_ray_agents
from modeling.checkpoint import checkpoint_dir, latest_checkpoint, temp_files
from tests.training.test_train import tiny_config


def running(pid: int) -> bool:
    """The process exists and is not a zombie (a killed orphan stays one until init reaps it)."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            stat = handle.read()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def write_rows(path, steps, width=0):
    path.write_text("".join(json.dumps({"step": s, "pad": "x" * width}) + "\n" for s in steps), encoding="utf-8")


def test_a_torn_last_line_is_cut_on_resume_naming_the_file_and_line(tmp_path):
    metrics, validation = tmp_path / "metrics.jsonl", tmp_path / "validation.jsonl"
    write_rows(metrics, [1, 2, 3], width=2400)
    torn = json.dumps({"step": 4, "pad": "x" * 2400})[:249]  # a full disk wrote 249 characters
    with metrics.open("a") as handle:
        handle.write(torn)
    write_rows(validation, [2])
    with validation.open("a") as handle:
        handle.write('{"step": 4, "val_acc')
    logs: list[str] = []
    MetricsSink(tmp_path, tensorboard=False, ray_metrics=False, resume=True).truncate_after(3, log=logs.append)
    assert [r["step"] for r in read_metrics(tmp_path)] == [1, 2, 3]
    assert [r["step"] for r in read_jsonl_rows(validation)] == [2]
    assert metrics.read_text().endswith("}\n") and validation.read_text().endswith("}\n")
    assert any(f"{metrics} line 4 (249 bytes)" in line for line in logs), logs
    assert any(f"{validation} line 2" in line for line in logs), logs

    # A bad line before the last is no crash's doing: refused, naming the file and the line.
    metrics.write_text('{"step": 1}\n{"step": 2, "lo\n{"step": 3}\n', encoding="utf-8")
    with pytest.raises(ValueError, match=rf"{metrics} line 2 "):
        MetricsSink(tmp_path, tensorboard=False, ray_metrics=False, resume=True).truncate_after(3)


def test_driver_killed_before_latest_moves_resumes_with_nothing_lost_or_doubled(ray_cluster, ward_policy_dir,
                                                                                 tmp_path):
    from learner import faults
    from learner.train import train

    run = tmp_path / "run"
    cfg = tiny_config(run, ward_policy_dir,
                      trainer={"max_steps": 3, "checkpoint_interval": 1, "val_interval": 2, "keep_checkpoints": 5},
                      metrics={"tensorboard": False, "ray_metrics": False, "progress": False})
    config = tmp_path / "run.yaml"
    dump_config(cfg, config)
    killed = subprocess.run([sys.executable, "-m", "learner.train", "--config", str(config)],
                            env={**os.environ, faults.FAULT_ENV: "metrics_written:2"},
                            capture_output=True, text=True, timeout=300)
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-3000:]
    # The killed driver's local cluster: its GCS and raylet exit, its two agents would linger a
    # minute (re-parented to init); a run starting a local cluster stops them first.
    deadline = time.monotonic() + 10
    while len(orphaned_ray_agents()) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    orphans = orphaned_ray_agents()
    assert len(orphans) >= 2, orphans
    assert set(reap_orphaned_ray_agents()) >= set(orphans)
    deadline = time.monotonic() + 5
    while any(map(running, orphans)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [pid for pid in orphans if running(pid)]
    # Step 2 wrote its checkpoint, validation, trajectories and metrics row, but `latest` still
    # names step 1: a resume redoes step 2 rather than skipping what it recorded.
    assert latest_checkpoint(run) == checkpoint_dir(run, 1)
    assert (checkpoint_dir(run, 2) / "driver.json").is_file()
    assert [r["step"] for r in read_metrics(run)] == [1, 2]
    # The disk filled during that append (the line is torn), and a learner rank killed mid-save
    # left a temporary file in the unfinished checkpoint.
    metrics = run / "metrics.jsonl"
    lines = metrics.read_text().splitlines(keepends=True)
    metrics.write_text(lines[0] + lines[1][:120])
    (checkpoint_dir(run, 2) / "learner" / ".optimizer_rank0.pt.tmp").write_bytes(b"\0" * 100)

    logs: list[str] = []
    faults.REACHED.clear()
    train(cfg, resume=True, log=logs.append)
    assert any(line.startswith("[resume] restored step 1") for line in logs), logs[-5:]
    assert any(f"{metrics} line 2 (120 bytes)" in line for line in logs), logs
    assert [r["step"] for r in read_metrics(run)] == [1, 2, 3]
    assert [r["step"] for r in read_jsonl_rows(run / "validation.jsonl")] == [2, 3]
    assert sorted(p.name for p in (run / "trajectories").iterdir()) == [f"step_{s:06d}.parquet" for s in (1, 2, 3)]
    assert sorted(p.name for p in (run / "validation").iterdir()) == [f"step_{s:06d}.parquet" for s in (2, 3)]
    assert latest_checkpoint(run) == checkpoint_dir(run, 3)
    assert temp_files(run / "checkpoints") == []
    # The write sequence of every step: `latest` moves after everything the step produced.
    assert faults.REACHED == [
        "checkpoint_saved:2", "validation_written:2", "trajectories_written:2", "metrics_written:2",
        "latest_marked:2",
        "checkpoint_saved:3", "trajectories_written:3", "metrics_written:3", "latest_marked:3",
        "validation_written:3",  # the last validation of a run ending off the interval; a resume
    ]                            # from step 3 redoes it when validation.jsonl has no row for step 3
