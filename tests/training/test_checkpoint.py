"""Checkpoints: exact resume, RNG states, no unpickling of arbitrary objects, directory layout."""

from __future__ import annotations

import random

import numpy as np
import pytest
import torch

from modeling.checkpoint import (
    capture_rng_state,
    checkpoint_dir,
    latest_checkpoint,
    load_torch_state,
    mark_latest,
    prune_checkpoints,
    restore_rng_state,
    save_torch_state,
)
from modeling.config_models import LearnerConfig
from modeling.hf_checkpoint import read_checkpoint_tensors
from learner.learner_actor import Learner
from tests.training.learner_fixtures import make_batch, tiny_model_dir


def _batches(model_dir):
    return [make_batch(seed=s, groups=2, group_size=3, model_dir=model_dir) for s in range(4)]


def test_resume_gives_identical_weights_torch_backend(tmp_path):
    model_dir = tiny_model_dir()
    batches = _batches(model_dir)
    cfg = LearnerConfig(optim={"lr": 1e-3, "weight_decay": 0.01})

    straight = Learner(cfg, model_dir)
    for step, b in enumerate(batches, 1):
        straight.train_step(b, step=step)

    first = Learner(cfg, model_dir)
    first.train_step(batches[0], step=1)
    first.train_step(batches[1], step=2)
    ckpt = checkpoint_dir(tmp_path, 2)
    first.save_checkpoint(str(ckpt))
    mark_latest(tmp_path, 2)
    del first

    resumed = Learner(cfg, model_dir)
    info = resumed.load_checkpoint(str(latest_checkpoint(tmp_path)))
    assert info == {"step": 2, "policy_version": 2}
    resumed.train_step(batches[2], step=3)
    resumed.train_step(batches[3], step=4)

    a, b = straight.get_state_dict(), resumed.get_state_dict()
    assert set(a) == set(b)
    assert all(torch.equal(a[k], b[k]) for k in a), "resume diverged from the straight run"
    assert resumed.policy_version() == straight.policy_version() == 4
    # Without the optimizer state the run would differ: the test can tell.
    no_opt = Learner(cfg, model_dir)
    no_opt.set_weights(read_checkpoint_tensors(ckpt / "learner" / "policy"))
    no_opt.train_step(batches[2])
    no_opt.train_step(batches[3])
    c = no_opt.get_state_dict()
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_checkpoint_of_another_backend_is_refused(tmp_path):
    model_dir = tiny_model_dir()
    learner = Learner(LearnerConfig(), model_dir)
    learner.save_checkpoint(str(tmp_path))
    meta = tmp_path / "learner" / "learner_state.json"
    meta.write_text(meta.read_text().replace('"torch"', '"deepspeed"'))
    with pytest.raises(ValueError, match="deepspeed"):
        learner.load_checkpoint(str(tmp_path))


def test_rng_state_roundtrip():
    random.seed(1), np.random.seed(1), torch.manual_seed(1)
    state = capture_rng_state()
    expected = (random.random(), float(np.random.rand()), float(torch.rand(1)))
    random.seed(99), np.random.seed(99), torch.manual_seed(99)
    restore_rng_state(state)
    assert (random.random(), float(np.random.rand()), float(torch.rand(1))) == expected
    with pytest.raises(ValueError, match="numpy"):
        restore_rng_state({"python": state["python"], "torch": state["torch"]})


class _Evil:
    def __reduce__(self):
        return (print, ("unpickled arbitrary code",))


def test_loading_refuses_arbitrary_pickles(tmp_path):
    good = {"state": {0: {"exp_avg": torch.ones(2), "step": torch.tensor(3.0)}}, "param_groups": [{"lr": 0.1, "betas": (0.9, 0.99)}]}
    save_torch_state(tmp_path / "ok.pt", good)
    loaded = load_torch_state(tmp_path / "ok.pt")
    assert torch.equal(loaded["state"][0]["exp_avg"], torch.ones(2))
    torch.save({"x": _Evil()}, tmp_path / "evil.pt")
    with pytest.raises(Exception, match="(?i)weights.only|unsupported|global"):
        load_torch_state(tmp_path / "evil.pt")


def test_latest_marker_and_pruning(tmp_path):
    assert latest_checkpoint(tmp_path) is None
    for step in (1, 2, 3):
        checkpoint_dir(tmp_path, step).mkdir(parents=True)
    with pytest.raises(FileNotFoundError):
        mark_latest(tmp_path, 9)
    mark_latest(tmp_path, 2)
    assert latest_checkpoint(tmp_path).name == "step_000002"
    removed = prune_checkpoints(tmp_path, keep_last=1)
    assert [p.name for p in removed] == ["step_000001"]  # step 2 is `latest`, kept
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir() if p.is_dir()) == ["step_000002", "step_000003"]
