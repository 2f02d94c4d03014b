"""A `hcgym train` that fails before its first learner step leaves nothing half-made in the run
folder, and says exactly what it removed and what it kept."""

from __future__ import annotations

import json

import yaml

from envs.cli import main
from learner.run_folder import RunFolderSnapshot, undo_failed_start

WARD = {"ward": "tests.fixtures.ward_domain.environment"}


def _config(tmp_path, run_dir) -> str:
    # A hub id that is not in the (empty) cache: the run fails in prepare_policy, after writing
    # config.yaml and creating model/ -- the half-made state the issue found.
    data = {"name": "t", "output_dir": str(run_dir), "model": {"kind": "pretrained", "path": "hcgym-tests/not-cached"},
            "data": {"domains": ["ward"], "domain_modules": WARD, "train_split": "train", "val_split": "test"},
            "trainer": {"max_steps": 1, "val_at_start": False, "val_interval": 0}}
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return str(path)


def _isolated_hub_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "hub-cache"))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)


def test_failed_start_in_a_new_folder_removes_the_folder(tmp_path, monkeypatch, capsys):
    _isolated_hub_cache(monkeypatch, tmp_path)
    run_dir = tmp_path / "runs" / "new"
    assert main(["train", "--config", _config(tmp_path, run_dir)]) == 2
    err = capsys.readouterr().err
    assert "not in the Hugging Face cache" in err  # the cause, named by the run
    assert (f"the run failed before its first step; removed config.yaml, model/ and the folder {run_dir}, "
            f"which it had created") in err
    assert not run_dir.exists()


def test_failed_start_in_an_earlier_run_folder_restores_it(tmp_path, monkeypatch, capsys):
    _isolated_hub_cache(monkeypatch, tmp_path)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("name: the earlier run\n", encoding="utf-8")
    (run_dir / "notes.txt").write_text("mine", encoding="utf-8")
    assert main(["train", "--config", _config(tmp_path, run_dir)]) == 2
    err = capsys.readouterr().err
    assert "removed model/" in err and "config.yaml (restored to the earlier run's)" in err
    assert "left what was there before: config.yaml, notes.txt" in err
    assert sorted(p.name for p in run_dir.iterdir()) == ["config.yaml", "notes.txt"]
    assert (run_dir / "config.yaml").read_text(encoding="utf-8") == "name: the earlier run\n"


def test_a_complete_initial_policy_is_kept(tmp_path):
    run_dir = tmp_path / "run"
    before = RunFolderSnapshot.take(run_dir)
    # What a run that failed after building its policy (e.g. no task matched) leaves behind.
    policy = run_dir / "model" / "init"
    policy.mkdir(parents=True)
    (policy / "config.json").write_text("{}", encoding="utf-8")
    (run_dir / "model" / "policy.json").write_text(json.dumps({"policy_dir": str(policy)}), encoding="utf-8")
    (run_dir / "config.yaml").write_text("name: x\n", encoding="utf-8")
    (run_dir / "trajectories").mkdir()
    message = undo_failed_start(before)
    assert "removed config.yaml, trajectories/" in message and "kept model/ (the complete initial policy" in message
    assert sorted(p.name for p in run_dir.iterdir()) == ["model"]
    # A model/ without its record (the build died half-way) is half-made: removed.
    (run_dir / "model" / "policy.json").unlink()
    assert "removed model/" in undo_failed_start(before) and not run_dir.exists()


def test_only_what_a_run_writes_is_removed(tmp_path):
    # output_dir may be a shared folder: a file another program created meanwhile stays.
    run_dir = tmp_path / "shared"
    before = RunFolderSnapshot.take(run_dir)
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("name: x\n", encoding="utf-8")
    (run_dir / "tensorboard").mkdir()
    (run_dir / "someone_elses.log").write_text("x", encoding="utf-8")
    message = undo_failed_start(before)
    assert "removed config.yaml, tensorboard/" in message and "kept someone_elses.log (not written by the run)" in message
    assert sorted(p.name for p in run_dir.iterdir()) == ["someone_elses.log"]


def test_a_run_that_recorded_a_step_is_left_as_it_is(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "metrics.jsonl").write_text('{"step": 1}\n', encoding="utf-8")
    before = RunFolderSnapshot.take(run_dir)  # a resumed run: one step from before
    (run_dir / "metrics.jsonl").write_text('{"step": 1}\n{"step": 2}\n', encoding="utf-8")
    (run_dir / "checkpoints").mkdir()
    message = undo_failed_start(before)
    assert message == f"the run failed after recording 1 step(s); {run_dir} is left as it is"
    assert (run_dir / "checkpoints").is_dir()


def test_the_cluster_entry_point_cleans_up_too(tmp_path, monkeypatch, capsys):
    """`python -m learner.train` (what cluster jobs run) undoes a failed start the same way."""
    import pytest

    from learner.train import main as module_main

    _isolated_hub_cache(monkeypatch, tmp_path)
    run_dir = tmp_path / "runs" / "job"
    with pytest.raises(Exception, match="not in the Hugging Face cache"):
        module_main(["--config", _config(tmp_path, run_dir)])
    err = capsys.readouterr().err
    assert f"python -m learner.train: the run failed before its first step; removed config.yaml, model/ and the folder {run_dir}" in err
    assert not run_dir.exists()
