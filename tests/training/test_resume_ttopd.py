"""Resume of TT-OPD runs: the teacher's EMA weights, version and update history, the learner and the
data position come back exactly.

Staleness 0 makes a run deterministic, so 2 steps + resume + 2 steps must equal 4 straight steps bit
for bit (metrics and final learner and teacher weights). With staleness 1 no two runs are alike
(which policy version samples which token depends on timing), so the resumed run is checked against
what its checkpoint and its own recorded batches determine: the step-2 checkpoint, trained in this
process on the recorded step-3 and step-4 batches (with their recorded teacher log-probs) and
updated on the teacher's schedule, must give the resumed run's final weights exactly.
"""

from __future__ import annotations

import shutil

import pytest
import torch

from actors.types import TeacherBatch, TeacherOutput
from modeling.checkpoint import checkpoint_dir, latest_checkpoint, load_tensors, mark_latest, read_json
from learner.metrics import read_metrics, read_samples
from tests.training.test_train import final_weights as learner_weights
from tests.training.test_train import teacher_weights, ttopd_config

pytestmark = pytest.mark.ray


def deterministic(record: dict) -> dict:
    """A metrics record without wall-clock figures, without the generator's reported log-probs
    (`logprob_*`, `is_*`: they move by ~1e-7 with the composition of the generation batch, which is
    timing; the sampled tokens, the losses and the weights do not), without object-store sizes
    (`*_bytes`: Ray's framing varies by a few bytes) and without the teacher's padding share (its
    batches are samples in arrival order: timing)."""
    return {k: v for k, v in record.items()
            if not (k.endswith(("_s", "_bytes")) or k.startswith(("time_", "logprob_", "is_")) or "per_s" in k
                    or k in ("teacher_wait_frac", "teacher_padding_frac"))}


def split_and_resume(straight, run_dir, cfg_of, logs):
    """Copy a finished 4-step run up to its step-2 checkpoint and resume it to step 4."""
    from learner.train import train

    shutil.copytree(straight, run_dir, ignore=shutil.ignore_patterns("step_000004*"))
    mark_latest(run_dir, 2)
    return train(cfg_of(run_dir), resume=True, log=logs.append)


def assert_same_tensors(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys(), what
    changed = [k for k in a if not torch.equal(a[k], b[k])]
    assert not changed, f"{what} differs in {changed[:3]}"


def test_ttopd_resume_is_bit_identical_on_policy(ray_cluster, ward_policy_dir, tmp_path):
    from learner.train import train

    def cfg_of(run_dir):
        return ttopd_config(run_dir, ward_policy_dir, trainer={"max_steps": 4, "checkpoint_interval": 2},
                            teacher={"ema_interval": 1})  # EMA at steps 1, 2, 4; hard copy at 3

    logs: list[str] = []
    train(cfg_of(tmp_path / "straight"), log=logs.append)
    split_and_resume(tmp_path / "straight", tmp_path / "split", cfg_of, logs)
    assert any(line.startswith("[resume] restored step 2") for line in logs)

    straight, resumed = read_metrics(tmp_path / "straight"), read_metrics(tmp_path / "split")
    assert [r["step"] for r in resumed] == [1, 2, 3, 4]
    assert [r["teacher_action"] for r in resumed] == [1.0, 1.0, 2.0, 1.0]
    for a, b in zip(straight[2:], resumed[2:]):
        assert deterministic(a) == deterministic(b), f"step {a['step']} differs after the resume"
    assert_same_tensors(learner_weights(tmp_path / "straight"), learner_weights(tmp_path / "split"), "learner")
    assert_same_tensors(teacher_weights(tmp_path / "straight"), teacher_weights(tmp_path / "split"), "teacher")
    history = [read_json(latest_checkpoint(d) / "teacher" / "teacher_state.json")
               for d in (tmp_path / "straight", tmp_path / "split")]
    assert history[0] == history[1] and history[0]["version"] == 4
    # The test can tell: the teacher of step 2 is not the final one.
    step2 = load_tensors(checkpoint_dir(tmp_path / "split", 2) / "teacher" / "teacher.safetensors")
    assert any(not torch.equal(step2[k], v) for k, v in teacher_weights(tmp_path / "split").items())


def test_ttopd_resume_with_staleness_continues_from_the_checkpoint_exactly(ray_cluster, ward_policy_dir, tmp_path):
    from actors.teacher import Teacher
    from learner.learner_actor import Learner
    from learner.train import train

    def cfg_of(run_dir):
        return ttopd_config(run_dir, ward_policy_dir, trainer={"max_steps": 4, "max_staleness": 1,
                                                               "checkpoint_interval": 2})

    logs: list[str] = []
    train(cfg_of(tmp_path / "straight"), log=logs.append)
    summary = split_and_resume(tmp_path / "straight", tmp_path / "split", cfg_of, logs)
    assert summary["steps"] == 4
    records = read_metrics(tmp_path / "split")
    assert [r["step"] for r in records] == [1, 2, 3, 4] and max(r["policy_lag_max"] for r in records) <= 1
    assert [r["teacher_updates"] for r in records] == [0.0, 1.0, 2.0, 3.0]  # none, EMA, hard copy, EMA

    batches = []
    for step in (3, 4):
        resumed, extras = read_samples(tmp_path / "split" / "trajectories" / f"step_{step:06d}.parquet")
        straight, _ = read_samples(tmp_path / "straight" / "trajectories" / f"step_{step:06d}.parquet")
        # The same groups with the same seeds: groups admitted before the checkpoint were re-admitted.
        assert [s.sample_id for s in resumed] == [s.sample_id for s in straight]
        teacher = TeacherBatch(outputs=[
            TeacherOutput(sample_id=s.sample_id, teacher_version=int(extras[s.sample_id]["teacher_version"]),
                          hint=extras[s.sample_id]["teacher_hint"] or "none", input_length=len(s.input_ids),
                          logprobs=list(extras[s.sample_id]["teacher_logprobs"])) for s in resumed])
        batches.append((step, resumed, teacher))

    cfg = cfg_of(tmp_path / "split")
    ckpt = checkpoint_dir(tmp_path / "split", 2)
    learner = Learner(cfg.learner.model_dump(), ward_policy_dir, cfg.seed)
    teacher = Teacher(cfg.teacher.model_dump(), ward_policy_dir, cfg.seed, start_worker=False)
    try:
        assert learner.load_checkpoint(str(ckpt)) == {"step": 2, "policy_version": 2}
        teacher.load(str(ckpt))
        assert teacher.teacher_version() == 1
        for step, samples, outputs in batches:
            learner.train_step(samples, outputs, step)
            teacher.update(learner.get_state_dict(), step)
        assert_same_tensors(learner.get_state_dict(), learner_weights(tmp_path / "split"), "learner")
        assert_same_tensors(teacher.get_weights(), teacher_weights(tmp_path / "split"), "teacher")
        assert teacher.history() == read_json(latest_checkpoint(tmp_path / "split") / "teacher" /
                                              "teacher_state.json")["history"]
    finally:
        learner.shutdown()
        teacher.shutdown()
