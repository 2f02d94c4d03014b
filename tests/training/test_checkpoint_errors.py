"""Checkpoint failures name the file: truncated or non-UTF-8 JSON, missing or mistyped keys, bad
safetensors, bad optimizer state; `latest` stays inside the run folder; atomic writes never leave a
temporary file or bare NaN behind."""

from __future__ import annotations

import asyncio
import json
import os
import pickle
import random

import pytest
import torch

from modeling.checkpoint import (CheckpointError, capture_rng_state, checkpoint_dir, latest_checkpoint,
                                load_tensors, load_torch_state, mark_latest, read_json, restore_rng_state,
                                save_tensors, save_torch_state, write_json_atomic)
from learner.run_checkpoint import DRIVER_STATE, restore_run_checkpoint


def _leftovers(folder):
    """Temporary files an atomic write would leave next to its target."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


class _UntouchableActor:
    """Stands where the learner / scheduler go: a restore that fails on driver.json must fail
    before touching any of them."""

    def __getattr__(self, name):
        raise AssertionError(f"the restore reached {name!r} although driver.json is bad")


def _driver_state(**changes):
    state = {"step": 2, "teacher_version": 0, "counters": {}, "ledger": {}, "version": 2, "sampler": {"pos": 0},
             "next_seq": 4, "consume_seq": 4, "readmit": []}
    state.update(changes)
    return {k: v for k, v in state.items() if v is not ...}


def _restore(run_dir):
    return asyncio.run(restore_run_checkpoint(run_dir, _UntouchableActor(), None, _UntouchableActor(), {},
                                              log=lambda line: None))


# ---------------------------------------------------------------------------------------------- JSON


def test_truncated_json_names_the_file(tmp_path):
    path = tmp_path / "learner_state.json"
    path.write_text('{"step": 3, "policy_vers', encoding="utf-8")
    with pytest.raises(CheckpointError) as err:
        read_json(path)
    assert str(path) in str(err.value) and "truncated" in str(err.value)


def test_non_utf8_json_names_the_file(tmp_path):
    path = tmp_path / "driver.json"
    path.write_bytes(b'{"step": 3, "note": "\xff"}')
    with pytest.raises(CheckpointError) as err:
        read_json(path)
    assert str(path) in str(err.value) and "not UTF-8" in str(err.value)


def test_required_keys_name_file_and_key(tmp_path):
    path = tmp_path / "learner_state.json"
    path.write_text(json.dumps({"policy_version": 3}), encoding="utf-8")
    with pytest.raises(CheckpointError) as err:
        read_json(path, required={"step": int})
    assert str(path) in str(err.value) and "missing key 'step'" in str(err.value)
    path.write_text(json.dumps({"step": True}), encoding="utf-8")  # a bool is not a step number
    with pytest.raises(CheckpointError, match="key 'step' should be int, got bool"):
        read_json(path, required={"step": int})
    path.write_text(json.dumps([1, 2]), encoding="utf-8")
    with pytest.raises(CheckpointError, match="expected a JSON object"):
        read_json(path, required={"step": int})
    path.write_text(json.dumps({"step": 3}), encoding="utf-8")
    assert read_json(path, required={"step": int}) == {"step": 3}


def test_driver_state_without_step_fails_naming_file_before_any_actor(tmp_path):
    checkpoint_dir(tmp_path, 2).mkdir(parents=True)
    mark_latest(tmp_path, 2)
    driver = checkpoint_dir(tmp_path, 2) / DRIVER_STATE
    driver.write_text(json.dumps(_driver_state(step=...)), encoding="utf-8")
    with pytest.raises(CheckpointError) as err:
        _restore(tmp_path)
    assert str(driver) in str(err.value) and "'step'" in str(err.value)
    driver.write_text(json.dumps(_driver_state(step="2")), encoding="utf-8")
    with pytest.raises(CheckpointError, match="key 'step' should be int, got str"):
        _restore(tmp_path)
    driver.write_text(json.dumps(_driver_state(step=0)), encoding="utf-8")
    with pytest.raises(CheckpointError, match="'step' should be >= 1"):
        _restore(tmp_path)
    driver.write_text(json.dumps(_driver_state(readmit=...)), encoding="utf-8")
    with pytest.raises(CheckpointError, match="missing key 'readmit'"):
        _restore(tmp_path)
    driver.write_text(json.dumps(_driver_state())[:40], encoding="utf-8")
    with pytest.raises(CheckpointError, match=r"driver\.json: not valid JSON \(truncated\?\)"):
        _restore(tmp_path)


def test_malformed_rng_state_names_the_file(tmp_path):
    path = tmp_path / "rng_rank0.json"
    state = capture_rng_state()
    state["numpy"] = ["MT19937", [1, 2, 3], 0, 0, 0.0]  # a key of 3 words instead of 624
    write_json_atomic(path, state)
    before = random.getstate()
    with pytest.raises(CheckpointError) as err:
        restore_rng_state(read_json(path), source=path)
    assert str(path) in str(err.value) and "'numpy'" in str(err.value)
    assert random.getstate() == before, "a bad file must leave the generators as they were"
    with pytest.raises(CheckpointError, match="lacks the 'torch' entry"):
        restore_rng_state({"python": state["python"], "numpy": state["numpy"]}, source=path)


# ---------------------------------------------------------------------------------------------- tensors


def test_bad_safetensors_names_the_file(tmp_path):
    good = tmp_path / "teacher.safetensors"
    save_tensors(good, {"w": torch.arange(64, dtype=torch.float32)})
    assert torch.equal(load_tensors(good)["w"], torch.arange(64, dtype=torch.float32))
    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes(good.read_bytes()[:-100])
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"\x00\x01 not a safetensors header at all")
    for path in (truncated, garbage):
        with pytest.raises(CheckpointError) as err:
            load_tensors(path)
        assert str(path) in str(err.value) and "not a readable safetensors file" in str(err.value)


def test_bad_optimizer_state_names_the_file(tmp_path):
    good = tmp_path / "optimizer.pt"
    save_torch_state(good, {"state": {0: {"exp_avg": torch.ones(3)}}, "param_groups": [{"lr": 0.1}]})
    truncated = tmp_path / "optimizer_truncated.pt"
    truncated.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    text = tmp_path / "optimizer_text.pt"
    text.write_text("this is not a torch file", encoding="utf-8")
    evil = tmp_path / "optimizer_evil.pt"
    torch.save({"x": _Evil()}, evil)
    for path in (truncated, text, evil):
        with pytest.raises(CheckpointError) as err:
            load_torch_state(path)
        assert str(path) in str(err.value)


class _Evil:
    def __reduce__(self):
        return (print, ("unpickled arbitrary code",))


# ---------------------------------------------------------------------------------------------- latest


@pytest.mark.parametrize("pointer", ["../../etc", "/etc", "step_000002/../../..", "", "step_2", "checkpoints"])
def test_latest_pointing_outside_the_run_is_refused(tmp_path, pointer):
    checkpoint_dir(tmp_path, 2).mkdir(parents=True)
    latest = tmp_path / "checkpoints" / "latest"
    latest.write_text(pointer, encoding="utf-8")
    with pytest.raises(CheckpointError) as err:
        latest_checkpoint(tmp_path)
    assert str(latest) in str(err.value) and "step_000004" in str(err.value)


def test_latest_through_a_symlink_outside_the_run_is_refused(tmp_path):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    os.symlink(outside, run / "checkpoints" / "step_000007")
    (run / "checkpoints" / "latest").write_text("step_000007", encoding="utf-8")
    with pytest.raises(CheckpointError, match="outside"):
        latest_checkpoint(run)


def test_latest_not_utf8_names_the_file(tmp_path):
    (tmp_path / "checkpoints").mkdir()
    latest = tmp_path / "checkpoints" / "latest"
    latest.write_bytes(b"step_\xff")
    with pytest.raises(CheckpointError) as err:
        latest_checkpoint(tmp_path)
    assert str(latest) in str(err.value)


# ---------------------------------------------------------------------------------------------- atomic writes


def test_atomic_json_refuses_nan_naming_the_key_and_keeps_the_old_file(tmp_path):
    path = tmp_path / "teacher_state.json"
    write_json_atomic(path, {"version": 1, "history": []})
    with pytest.raises(CheckpointError) as err:
        write_json_atomic(path, {"version": 2, "history": [{"action": "ema"}, {"kl": float("nan")}]})
    assert str(path) in str(err.value) and "'history[1].kl'" in str(err.value)
    with pytest.raises(CheckpointError, match="'ledger.rate'"):
        write_json_atomic(path, {"ledger": {"rate": float("-inf")}})
    assert json.loads(path.read_text(encoding="utf-8")) == {"version": 1, "history": []}
    assert "NaN" not in path.read_text(encoding="utf-8")
    assert _leftovers(tmp_path) == []


def test_failed_atomic_writes_remove_their_temporary_file(tmp_path):
    path = tmp_path / "driver.json"
    write_json_atomic(path, {"step": 1})
    with pytest.raises(TypeError) as err:
        write_json_atomic(path, {"step": 2, "sampler": {"rng": object()}})  # not JSON-serialisable
    assert str(path) in str(err.value)
    assert read_json(path) == {"step": 1} and _leftovers(tmp_path) == []
    with pytest.raises((AttributeError, pickle.PicklingError)):  # which one depends on where the lambda lives
        save_torch_state(tmp_path / "optimizer.pt", {"hook": lambda: None})  # lambdas do not pickle
    assert not (tmp_path / "optimizer.pt").exists() and _leftovers(tmp_path) == []
    with pytest.raises(RuntimeError, match="share memory"):
        # Two names sharing one storage: safetensors refuses to save aliased tensors.
        shared = torch.zeros(4)
        save_tensors(tmp_path / "w.safetensors", {"a": shared, "b": shared})
    assert not (tmp_path / "w.safetensors").exists() and _leftovers(tmp_path) == []


# ---------------------------------------------------------------------------------------------- the learner's part


def test_learner_checkpoint_failures_name_the_file(tmp_path):
    from modeling.config_models import LearnerConfig
    from learner.learner_actor import Learner
    from tests.training.learner_fixtures import tiny_model_dir

    model_dir = tiny_model_dir()
    learner = Learner(LearnerConfig(), model_dir)
    directory = checkpoint_dir(tmp_path, 1)
    learner.save_checkpoint(str(directory))
    state_file = directory / "learner" / "learner_state.json"
    saved = read_json(state_file)
    assert {"step", "policy_version", "backend", "world_size"} <= set(saved)

    write_json_atomic(state_file, {k: v for k, v in saved.items() if k != "step"})
    with pytest.raises(CheckpointError) as err:
        Learner(LearnerConfig(), model_dir).load_checkpoint(str(directory))
    assert str(state_file) in str(err.value) and "missing key 'step'" in str(err.value)

    write_json_atomic(state_file, saved)
    optimizer = directory / "learner" / "optimizer.pt"
    good_optimizer = optimizer.read_bytes()
    optimizer.write_bytes(good_optimizer[:200])
    with pytest.raises(CheckpointError) as err:
        Learner(LearnerConfig(), model_dir).load_checkpoint(str(directory))
    assert str(optimizer) in str(err.value)
    optimizer.write_bytes(good_optimizer)

    # The policy weights (sharded safetensors + index, read by modeling.hf_checkpoint).
    policy = directory / "learner" / "policy"
    shard = sorted(policy.glob("*.safetensors"))[0]
    good_shard = shard.read_bytes()
    for broken in (good_shard[:300], good_shard[:-64]):  # header cut, data cut
        shard.write_bytes(broken)
        with pytest.raises(CheckpointError) as err:
            Learner(LearnerConfig(), model_dir).load_checkpoint(str(directory))
        assert str(shard) in str(err.value)
    shard.write_bytes(good_shard)
    index = policy / "model.safetensors.index.json"
    index.write_bytes(b'{"weight_map": {"a": "\xff')
    with pytest.raises(CheckpointError) as err:
        Learner(LearnerConfig(), model_dir).load_checkpoint(str(directory))
    assert str(index) in str(err.value)
