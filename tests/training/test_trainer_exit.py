"""A run that stops, however it stops, leaves no thread of its own behind in the driver process
(a daemon thread still waking up while the interpreter exits can crash that exit: docs/training.md,
"Faults")."""

from __future__ import annotations

import threading

from tests.training.test_train import tiny_config


def _writer_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if type(t).__name__ == "_AsyncWriterThread" and t.is_alive()]


def test_shutdown_stops_the_metrics_writer_thread_of_a_run_that_failed(tmp_path, ward_policy_dir):
    from learner.metrics import MetricsSink
    from learner.train import Trainer

    before = set(_writer_threads())
    trainer = Trainer(tiny_config(tmp_path / "run", ward_policy_dir), log=lambda line: None)
    # What `_main` has built when a step fails: the sink with its TensorBoard writer; `run()`'s
    # finally then calls `shutdown()`.
    trainer.sink = MetricsSink(trainer.run_dir, tensorboard=True, ray_metrics=False, run_name="failed")
    trainer.sink.write({"step": 1, "loss": 0.5})
    started = [t for t in _writer_threads() if t not in before]
    assert started, "the TensorBoard writer runs a thread (the test would prove nothing otherwise)"
    trainer.shutdown()
    for thread in started:
        thread.join(timeout=10)
    assert not [t for t in started if t.is_alive()]
    assert list((trainer.run_dir / "tensorboard").glob("events.out.tfevents.*"))
    trainer.shutdown()  # a second shutdown (run() after an earlier one) is harmless
