"""One learner step's record in metrics.jsonl (rollout, learner, batch and timing figures) and its
progress line."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from actors.types import RolloutSample
from learner.metrics import rollout_metrics

TEACHER_ACTION_CODES = {"none": 0.0, "ema": 1.0, "hard_copy": 2.0}


@dataclass
class StepTimes:
    """Seconds of one step's phases (validation excluded from `step`)."""

    step: float
    batch_wait: float
    learner: float
    weight_sync: float


def step_record(step: int, samples: list[RolloutSample], learner_metrics: dict[str, Any], batch_info: dict[str, float],
                times: StepTimes, *, max_response_tokens: int, teacher_action: str, teacher_version: int,
                generator_failures: int, episode_reruns: int, batch_groups: int,
                teacher_sync: dict[str, float] | None = None,
                generator: dict[str, float] | None = None) -> dict[str, Any]:
    """The metrics of step `step` (REQUIRED_KEYS and more); `teacher_sync` adds the teacher's
    cumulative weight-sync figures (`TeacherClient.sync_metrics`), `generator` the generators'
    cumulative outage figures (`GeneratorClient.metrics`)."""
    record: dict[str, Any] = {"step": step}
    record.update(rollout_metrics(samples, max_response_tokens))
    record.update({k: float(v) for k, v in learner_metrics.items()})
    lags = [step - 1 - v for s in samples for v, m in zip(s.policy_versions, s.loss_mask) if m]
    tokens = sum(len(s.input_ids) - s.prompt_length for s in samples)
    wait_s = float(learner_metrics.get("teacher_wait_s", 0.0))
    record.update(batch_info)
    record.update({
        "policy_lag_max": float(max(lags) if lags else 0), "policy_lag_mean": float(np.mean(lags) if lags else 0),
        # The share of the learner step spent blocked on the teacher (the fetch overlap hides the rest).
        "teacher_wait_s": wait_s, "teacher_wait_frac": wait_s / max(times.learner, 1e-9),
        "time_step_s": times.step, "time_batch_wait_s": times.batch_wait, "time_learner_s": times.learner,
        "time_weight_sync_s": times.weight_sync,
        "time_generation_s": float(sum(s.metadata.get("generate_s", 0.0) for s in samples)),
        "time_env_s": float(sum(s.metadata.get("env_s", 0.0) for s in samples)),
        "trajectories_per_s": len(samples) / times.step, "tokens_per_s": tokens / times.step,
        "teacher_updates": float(teacher_version),
        "generator_failures": float(generator_failures), "episode_reruns": float(episode_reruns),
        "batch_size_groups": float(batch_groups),
    })
    record.update(teacher_sync or {})
    record.update(generator or {})
    record["teacher_action"] = TEACHER_ACTION_CODES[teacher_action]
    if "grad_norm" not in record:
        raise RuntimeError("learner.train_step returned no grad_norm")
    record.setdefault("kl_teacher", 0.0)
    return record


def progress_line(r: dict[str, Any], max_steps: int) -> str:
    val = f" | val acc {r['val_accuracy']:.3f} reward {r['val_reward_mean']:.3f}" if "val_accuracy" in r else ""
    return (f"step {r['step']}/{max_steps} | reward {r['reward_mean']:.3f} "
            f"acc {r['accuracy']:.2f} | len {r['response_length_mean']:.0f} turns {r['turns_mean']:.2f} "
            f"tools {r['tool_calls_mean']:.2f} | kl_t {r.get('kl_teacher', 0):.4f} kl_ref {r.get('kl_ref', 0):.4f} "
            f"| filtered {r['filtered_groups_frac']:.2f} | {r['time_step_s']:.1f}s "
            f"(learner {r['time_learner_s']:.1f}s, teacher wait {r['teacher_wait_s']:.1f}s){val}")
