"""Kill an env actor, a generator and the teacher mid-run: training continues and every
trajectory is accounted for exactly once."""

from __future__ import annotations

import contextlib
import threading
import time

import pytest

from learner.metrics import read_metrics, read_samples
from tests.training.test_train import tiny_config

pytestmark = pytest.mark.ray


def wait_for(predicate, timeout=120.0, what="condition"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


@contextlib.contextmanager
def training_in_background(trainer, join_timeout: float = 600.0):
    """Run `trainer.run()` on a thread while the body kills actors; afterwards re-raise the run's
    error, or put its summary in the yielded dict under "summary"."""
    outcome: dict = {}

    def run():
        try:
            outcome["summary"] = trainer.run()
        except BaseException as exc:  # surfaced below
            outcome["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield outcome
    finally:
        thread.join(timeout=join_timeout)
    if thread.is_alive():
        raise AssertionError(f"training did not finish within {join_timeout:.0f} s")
    if "error" in outcome:
        raise outcome["error"]


def test_training_survives_env_generator_and_teacher_deaths(ray_cluster, ward_policy_dir, tmp_path):
    from learner.train import Trainer

    steps = 5
    cfg = tiny_config(
        tmp_path / "faults", ward_policy_dir,
        trainer={"max_steps": steps, "max_staleness": 1, "checkpoint_interval": 0},
        teacher={"enabled": True, "ema_interval": 1, "hard_copy_interval": 0},
        learner={"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01, "distill": {"enabled": True, "lambda_distill": 1.0,
                                                                       # a random policy's turns all hit the
                                                                       # token limit; keep them in the KL
                                                                       "drop_length_truncated_turns": False}}},
    )
    trainer = Trainer(cfg, log=lambda line: None)
    with training_in_background(trainer) as outcome:
        wait_for(lambda: trainer.step >= 1, what="step 1")
        # An env actor while it hosts episodes.
        wait_for(lambda: trainer.pool.loads()[0] > 0, what="episodes on env actor 0")
        ray_cluster.kill(trainer.pool.actors[0], no_restart=False)
        wait_for(lambda: trainer.step >= 2, what="step 2")
        # A generator while requests are outstanding on it.
        wait_for(lambda: trainer.gen_client.outstanding[0] > 0, what="requests on the generator")
        ray_cluster.kill(trainer.generators[0], no_restart=False)
        wait_for(lambda: trainer.step >= 3, what="step 3")
        # The teacher, with EMA state to lose (it has been updated at every step).
        ray_cluster.kill(trainer.teacher, no_restart=False)
    summary = outcome["summary"]

    assert summary["steps"] == steps
    assert [r["step"] for r in read_metrics(cfg.output_dir)] == list(range(1, steps + 1))
    assert summary["ledger"]["reruns"] >= 1, "the killed env actor's episodes were not re-run"
    assert summary["generator_failures"] >= 1
    # The killed generator was waited for: no request gave up, no group was replaced for it.
    assert summary["generator"]["generator_gave_up"] == 0 and summary["generator"]["generator_outages"] >= 1
    assert summary["counters"]["groups_failed"] == 0
    assert summary["counters"]["teacher_recoveries"] >= 1
    # Accounting: every episode completed once; every admitted group ended in exactly one state.
    ledger = summary["ledger"]
    assert ledger["in_flight"] == 0 and ledger["admitted"] == ledger["completed"] + ledger["failed"]
    assert ledger["attempts"] == ledger["admitted"] + ledger["reruns"]
    status = summary["group_status"]
    assert sum(status.values()) == summary["counters"]["groups_admitted"]
    assert status.get("in_flight", 0) == 0 and status.get("cancelled", 0) == 0
    # No trajectory trained on twice, each step a full batch of whole groups.
    seen: set[str] = set()
    for step in range(1, steps + 1):
        samples, extras = read_samples(tmp_path / "faults" / "trajectories" / f"step_{step:06d}.parquet")
        ids = [s.sample_id for s in samples]
        assert len(ids) == 4 and not (seen & set(ids))
        seen.update(ids)
        assert all(extras[i]["teacher_logprobs"] is not None for i in ids)
    consumed_groups = status.get("consumed", 0) + status.get("filled", 0)
    assert consumed_groups * 2 == len(seen)


def test_collective_weight_sync_survives_a_teacher_death(ray_cluster, ward_policy_dir, tmp_path):
    """With the collective transport the teacher is a member of the weight-sync group: killed, it breaks
    the group; the group is re-formed with the restarted teacher, which first adopts the student's
    weights at the driver's teacher version (no EMA snapshot is kept in this mode)."""
    from learner.train import Trainer

    steps = 4
    cfg = tiny_config(
        tmp_path / "collective_faults", ward_policy_dir,
        trainer={"max_steps": steps, "checkpoint_interval": 0},
        teacher={"enabled": True, "ema_interval": 1, "hard_copy_interval": 0},
        weight_sync={"transport": "collective", "backend": "gloo", "bucket_mb": 0.05, "timeout_s": 15},
        learner={"optim": {"lr": 1e-3}, "loss": {"entropy_coef": 0.01, "distill": {"enabled": True, "lambda_distill": 1.0,
                                                                       "drop_length_truncated_turns": False}}},
    )
    trainer = Trainer(cfg, log=lambda line: None)
    with training_in_background(trainer) as outcome:
        # Once it holds EMA state that a restart loses (killed earlier, its initial weights are exact).
        wait_for(lambda: trainer.teacher_client is not None and trainer.teacher_client.version >= 1,
                 what="the first teacher update")
        ray_cluster.kill(trainer.teacher, no_restart=False)
    summary = outcome["summary"]
    assert summary["steps"] == steps
    counters = summary["counters"]
    assert counters["teacher_recoveries"] >= 1 and counters.get("teacher_recoveries_inexact", 0) >= 1, counters
    records = read_metrics(cfg.output_dir)
    assert [r["teacher_updates"] for r in records] == [1.0, 2.0, 3.0, 4.0]  # no update lost or repeated
    # The adoption went through the object store (counted), the other updates through the group.
    assert records[-1]["teacher_sync_object_store"] >= counters["teacher_recoveries_inexact"]
    assert records[-1]["teacher_sync_collective_bytes"] > records[0]["teacher_sync_collective_bytes"] > 0
    for step in range(1, steps + 1):
        samples, extras = read_samples(tmp_path / "collective_faults" / "trajectories" / f"step_{step:06d}.parquet")
        assert all(extras[s.sample_id]["teacher_logprobs"] is not None for s in samples)


def test_a_generator_back_too_late_fails_its_requests_naming_it_and_a_dead_one_stops_them(ray_cluster,
                                                                                         ward_policy_dir):
    """Past `generator.restart_wait_s` a request whose generator died raises GeneratorUnavailableError
    naming the generator and the wait (its group is then replaced); one warning per outage, each
    request that gave up counted. A generator Ray will not restart is not waited for:
    GeneratorDeadError names it. (A generator back in time: test_node_loss.py and the test above.)"""
    import asyncio

    from actors.generator import (GenerationRequest, GeneratorClient, GeneratorDeadError, GeneratorUnavailableError,
                                  start_generator_actors)
    from modeling.model import ENDOFTEXT, IM_END, load_tokenizer

    tokenizer = load_tokenizer(ward_policy_dir)
    stop_ids = [tokenizer.convert_tokens_to_ids(IM_END), tokenizer.convert_tokens_to_ids(ENDOFTEXT)]
    # A batch waits 2 s for company, so a request is surely on the actor when it is killed.
    (actor,) = start_generator_actors("hf", ward_policy_dir, {}, stop_ids, 1, python_executable=None,
                                      batch_wait_s=2.0, num_cpus=0, max_restarts=1)
    logs: list[str] = []
    # Far shorter than the actor's restart (a new worker process importing torch and loading the model).
    client = GeneratorClient([actor], restart_wait_s=0.1, log=logs.append, poll_s=0.05)
    prompt = tokenizer.encode("<|im_start|>assistant\n", add_special_tokens=False)

    def calls(*names: str):
        return asyncio.gather(*[client(GenerationRequest(request_id=n, prompt_ids=prompt, max_new_tokens=4, seed=7))
                                for n in names], return_exceptions=True)

    async def scenario():
        await actor.version.remote()  # started
        pending = asyncio.ensure_future(calls("a", "b"))
        await asyncio.sleep(0.5)
        ray_cluster.kill(actor, no_restart=False)  # Ray restarts it (max_restarts=1)
        too_late = await pending
        # Killed again while it restarts, now for good; a request arriving meanwhile is told at once.
        client.restart_wait_s = 60.0
        ray_cluster.kill(actor, no_restart=True)
        started = time.monotonic()
        dead = await calls("c")
        return too_late, dead, time.monotonic() - started

    too_late, dead, told_s = asyncio.run(scenario())
    name = f"generator 0 (actor {actor._actor_id.hex()})"
    assert all(isinstance(o, GeneratorUnavailableError) for o in too_late), too_late
    assert all(name in str(o) and "restart_wait_s = 0.1 s" in str(o) for o in too_late), too_late[0]
    warnings = [line for line in logs if "warning" in line]
    assert len(warnings) == 1 and name in warnings[0] and "did not answer for" in warnings[0], logs
    assert client.gave_up == 2 and client.metrics()["generator_gave_up"] == 2.0
    (error,) = dead
    assert isinstance(error, GeneratorDeadError) and name in str(error) and "will not restart" in str(error), error
    assert told_s < 30 and client.dead == {0}, told_s
    assert len(client.outages) == 1 and client.outages[0].back_at is None, client.outages


def test_a_generator_back_too_late_fails_its_groups_and_the_run_trains_on_replacements(ray_cluster, ward_policy_dir,
                                                                                      tmp_path):
    """The generator is killed while a request waits on it, and restarts far slower than
    `generator.restart_wait_s`: the requests give up, their episodes end failed, their groups are
    dropped and replaced by new ones, and the run trains full batches of whole groups, none of them
    a failed one and no sample twice."""
    from learner.train import Trainer

    steps = 2
    cfg = tiny_config(
        tmp_path / "replaced", ward_policy_dir,
        # An inspection budget of one batch: a failed group that used it would leave the step short.
        trainer={"max_steps": steps, "checkpoint_interval": 0,
                 "dynamic_sampling": {"enabled": False, "max_admissions_factor": 1.0}},
        # Every batch waits 1 s for company, so a request is surely on the generator when it is
        # killed; its restart (a new worker importing torch, loading the model) takes seconds.
        generator={"batch_wait_s": 1.0, "restart_wait_s": 0.5},
    )
    logs: list[str] = []
    trainer = Trainer(cfg, log=logs.append)
    with training_in_background(trainer, join_timeout=180.0) as outcome:
        wait_for(lambda: trainer.step >= 1, what="step 1")
        wait_for(lambda: trainer.gen_client.outstanding[0] > 0, what="requests on the generator")
        ray_cluster.kill(trainer.generators[0], no_restart=False)
    summary = outcome["summary"]

    assert summary["steps"] == steps
    records = read_metrics(cfg.output_dir)
    assert [r["step"] for r in records] == list(range(1, steps + 1))
    counters, status = summary["counters"], summary["group_status"]
    # The replacement is counted: the step's own figure, the run's counter and the requests that gave up.
    assert records[1]["groups_failed"] >= 1 and records[0]["groups_failed"] == 0, records
    assert counters["groups_failed"] == status["failed"] == sum(r["groups_failed"] for r in records) >= 1
    assert records[-1]["generator_gave_up"] >= 1 and summary["generator"]["generator_outages"] >= 1
    assert any("did not answer for" in line for line in logs), logs
    # Every failed group ended failed in the ledger, with the generator's error; none was trained.
    ledger = trainer.rollouts.ledger
    failed_seqs = {seq for seq, state in trainer.scheduler.group_status.items() if state == "failed"}
    assert ledger.failed and all("GeneratorUnavailableError" in why for why in ledger.failed.values()), ledger.failed
    balance = summary["ledger"]
    assert balance["failed"] == len(ledger.failed) and balance["reruns"] == 0, balance
    assert balance["in_flight"] == 0 and balance["admitted"] == balance["completed"] + balance["failed"], balance
    assert sum(status.values()) == counters["groups_admitted"] and status.get("in_flight", 0) == 0, status
    seen: set[str] = set()
    for step in range(1, steps + 1):
        samples, _ = read_samples(tmp_path / "replaced" / "trajectories" / f"step_{step:06d}.parquet")
        ids = [s.sample_id for s in samples]
        assert len(ids) == 4 and len(set(ids)) == 4 and not (seen & set(ids)), ids  # a full batch, nothing twice
        seen.update(ids)
        seqs = {int(s.group_id.split(":")[0][1:]) for s in samples}
        assert len(seqs) == 2 and not (seqs & failed_seqs), (seqs, failed_seqs)
    assert not (seen & set(ledger.failed)), "a failed episode was trained on"
