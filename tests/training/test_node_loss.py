"""Node loss on a simulated multi-node cluster (ray.cluster_utils: separate raylets on this host).

    head     CPU 1                                           the driver
    learner  CPU 1, learner_node 1                           the learner (world size 1: it holds the model)
    rollout  CPU 1, rollout_node 1, env_node 1               the generator and the env actor
    spare    CPU 1, learner_node 1, rollout_node 1, env_node 1   joins during the run

One run goes through the cases, so the cluster starts the run's actors as few times as possible:
losing the node of the generator and the env actor lets the run go on (Ray restarts them on the
spare, the episodes they held are re-run, every step is recorded once); losing the learner's node
stops the run with an error naming the node; `--resume` continues from the last checkpoint on the
spare; with no learner node left, a resume is refused at start naming the missing resource.

The cluster is this module's own: the session-wide `ray_cluster` (conftest) is shut down first and
started again when the module ends, as in test_placement.py.
"""

from __future__ import annotations

import threading
import time
from collections import Counter

import pytest

from learner import faults
from learner.metrics import read_metrics, read_samples
from learner.placement import PlacementError
from learner.run_actors import LearnerNodeLost
from learner.tasks import episode_specs
from modeling.checkpoint import checkpoint_dir, latest_checkpoint
from tests.training.conftest import SESSION_RAY_INIT
from tests.training.test_faults import training_in_background, wait_for
from tests.training.test_train import tiny_config

pytestmark = pytest.mark.ray

NODES = {
    "learner": {"num_cpus": 1, "resources": {"learner_node": 1}},
    "rollout": {"num_cpus": 1, "resources": {"rollout_node": 1, "env_node": 1}},
}
SPARE = {"num_cpus": 1, "resources": {"learner_node": 1, "rollout_node": 1, "env_node": 1}}


@pytest.fixture(autouse=True)
def no_fault_action_left_behind():
    yield
    faults.clear_actions()  # a test that failed before its point must not leave the action to a later run


@pytest.fixture(scope="module")
def cluster():
    """The simulated cluster; yields (the `Cluster`, {name: its `Node`})."""
    import ray
    from ray.cluster_utils import Cluster

    session_was_up = ray.is_initialized()
    if session_was_up:
        ray.shutdown()
    # A node killed outright (no goodbye to the GCS) is found dead by the GCS's health checks:
    # 3 missed checks 1 s apart here, instead of Ray's default 5 x 3 s.
    health = {"health_check_period_ms": 1000, "health_check_timeout_ms": 1000, "health_check_failure_threshold": 3}
    from envs._runtime import later_session_system_config

    sim = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                        "_system_config": {**health, **later_session_system_config()}})
    try:
        nodes = {name: sim.add_node(**args) for name, args in NODES.items()}
        ray.init(address=sim.address, namespace="hcgym-node-loss-tests", log_to_driver=False)
        yield sim, nodes
    finally:
        ray.shutdown()
        sim.shutdown()
        if session_was_up:
            from envs._runtime import init_ray

            init_ray(**SESSION_RAY_INIT)


def node_of(handle) -> str:
    import ray

    return ray._private.state.actors(handle._actor_id.hex())["Address"]["NodeID"]


def run_config(tmp_path, policy_dir, **trainer):
    # One env actor, no TensorBoard: the fewest processes to start on each node.
    return tiny_config(
        tmp_path / "run", policy_dir,
        trainer={"keep_checkpoints": 5, **trainer},
        rollout={"num_env_actors": 1},
        ray={"learner_num_cpus": 0, "learner_resources": {"learner_node": 1},
             "generator_resources": {"rollout_node": 1}, "env_resources": {"env_node": 1}},
        metrics={"tensorboard": False, "ray_metrics": False, "progress": False})


def test_rollout_node_lost_run_goes_on_learner_node_lost_run_stops_naming_it_resume_moves_on(
        cluster, ward_policy_dir, tmp_path):
    from learner.train import Trainer, train

    sim, nodes = cluster
    run = tmp_path / "run"
    steps = 5
    cfg = run_config(tmp_path, ward_policy_dir, max_steps=steps, checkpoint_interval=1, max_staleness=1)
    trainer = Trainer(cfg, log=lambda line: None)
    seen: dict[str, object] = {}

    paused, go_on = threading.Event(), threading.Event()

    def pause():  # in the driver's thread: the run waits while the spare node joins
        paused.set()
        assert go_on.wait(300)

    def lose_learner_node():
        seen["rollout actors"] = {node_of(a) for a in [*trainer.generators, *trainer.pool.actors]}
        seen["learner nodes"] = dict(trainer.learner_nodes)
        sim.remove_node(nodes.pop("learner"))

    faults.at("latest_marked:1", pause)
    with pytest.raises(LearnerNodeLost) as info:
        with training_in_background(trainer):
            wait_for(paused.is_set, what="step 1")
            try:
                seen["first rollout actors"] = {node_of(a) for a in [*trainer.generators, *trainer.pool.actors]}
                seen["rollout node"] = nodes["rollout"].node_id
                nodes["spare"] = sim.add_node(**SPARE)
            finally:
                go_on.set()  # never leave the driver waiting
            # While an episode is on the env actor and a request on the generator.
            wait_for(lambda: sum(trainer.pool.loads()) > 0 and trainer.gen_client.outstanding[0] > 0,
                     what="episodes and generation in flight")
            # Killed outright, as a crashed machine goes: the episode's turn in flight cannot finish first.
            # (Copies of the driver thread's dicts and sets are taken in one C call each, under the GIL.)
            seen["rollout lost at"] = trainer.step
            seen["status at the kill"] = dict(trainer.scheduler.group_status)
            # The episodes on the node while it goes: sampled until the removal returns, since a short
            # episode seen before the kill may finish, and the next one be leased, before the node is gone.
            on_node: set[str] = set()
            removed = threading.Event()

            def sample_on_node():
                while not removed.is_set():
                    on_node.update(key.split("#")[0] for key in set(trainer.pool.in_flight[0]))
                    time.sleep(0.001)

            sampler = threading.Thread(target=sample_on_node, daemon=True)
            sampler.start()
            seen["killed at"] = time.monotonic()
            try:
                sim.remove_node(nodes.pop("rollout"), allow_graceful=False)
            finally:
                removed.set()
                sampler.join()
            seen["on the node"] = on_node
            rollout_actors = [*trainer.generators, *trainer.pool.actors]
            wait_for(lambda: {node_of(a) for a in rollout_actors} == {nodes["spare"].node_id},
                     what="the generator and the env actor restarted on the spare")
            # The learner's node goes right after the next step becomes `latest` (its `latest_marked`
            # comes after `trainer.step` counts it, so that point is still ahead).
            seen["lost at"] = lost_at = trainer.step + 1
            assert lost_at < steps
            faults.at(f"latest_marked:{lost_at}", lose_learner_node)

    # The rollout node's loss: Ray restarted the generator and the env actor on the spare, the
    # episodes they held were re-run, and the steps so far were recorded once each, full batches.
    spare, lost_at = nodes["spare"], seen["lost at"]
    assert seen["first rollout actors"] == {seen["rollout node"]}
    assert seen["rollout actors"] == {spare.node_id}
    # Requests to the lost generator failed and waited for its restart on the spare (within
    # generator.restart_wait_s): no request gave up, no episode failed, no group was replaced.
    gen = trainer.gen_client
    assert gen.failures >= 1 and gen.gave_up == 0, (gen.failures, gen.metrics())
    outages = [o for o in gen.outages if o.down_at >= seen["killed at"]]
    assert outages and all(o.back_at is not None for o in gen.outages), gen.outages
    restart_s = outages[0].back_at - seen["killed at"]   # the kill to the generator answering again
    ledger = trainer.rollouts.ledger
    balance, status = ledger.balance(), dict(trainer.scheduler.group_status)
    assert balance["failed"] == 0 and not ledger.failed, ledger.failed
    assert trainer.scheduler.counters["groups_failed"] == 0 and "failed" not in status.values(), status
    # The episodes on the lost node were re-run once each, from their start (one that was closing
    # when the node went may have finished there); no episode of a group delivered before the kill
    # was re-run (nothing doubled), and each in-flight group finished without being replaced.
    reruns = Counter(sample_id for sample_id, _ in ledger.lost_attempts)
    assert balance["reruns"] >= 1 and max(reruns.values()) == 1, reruns
    assert seen["on the node"] & set(reruns), (seen["on the node"], reruns)
    episodes = {seq: {s.sample_id for s in episode_specs(cfg.seed, seq, task, 0, cfg.rollout.group_size)}
                for seq, task in trainer.scheduler.group_tasks.items()}
    at_kill = seen["status at the kill"]
    delivered = {seq for seq, state in at_kill.items() if state != "in_flight"}
    in_flight = {seq for seq, state in at_kill.items() if state == "in_flight"}
    assert delivered and not any(episodes[seq] & set(reruns) for seq in delivered), (delivered, reruns)
    rerun_groups = {seq for seq, ids in episodes.items() if ids & set(reruns)}
    assert rerun_groups and rerun_groups <= in_flight | (set(status) - set(at_kill)), (rerun_groups, at_kill)
    assert all(status[seq] != "failed" for seq in rerun_groups | in_flight), status
    # Accounting: every episode of a group that was not cancelled by the learner node's loss
    # completed exactly once; the ones still in flight belong to cancelled groups.
    assert balance["admitted"] == balance["completed"] + balance["in_flight"], balance
    for seq, state in status.items():
        if state != "cancelled":
            assert episodes[seq] <= ledger.completed, (seq, state)
    ids = [[s.sample_id for s in read_samples(run / "trajectories" / f"step_{step:06d}.parquet")[0]]
           for step in range(1, lost_at + 1)]
    assert all(len(batch) == 4 for batch in ids) and len({i for batch in ids for i in batch}) == 4 * lost_at

    # The learner node's loss stops the run, naming the node, the checkpoint and what a resume needs.
    message = str(info.value)
    (learner_node,) = seen["learner nodes"]
    assert f"learner rank 0 on node {learner_node}" in message, message
    assert f"left the Ray cluster during step {lost_at + 1}" in message, message
    assert f"the last complete checkpoint is {checkpoint_dir(run, lost_at)}" in message, message
    assert "--resume" in message and "learner_node 1" in message, message
    assert latest_checkpoint(run) == checkpoint_dir(run, lost_at)
    rows = read_metrics(run)
    assert [r["step"] for r in rows] == list(range(1, lost_at + 1))
    assert rows[-1]["generator_gave_up"] == 0 and rows[-1]["generator_outages"] >= 1, rows[-1]

    # The spare holds what the learner needs: the resume continues there.
    logs: list[str] = []
    summary = train(cfg, resume=True, log=logs.append)
    assert summary["steps"] == steps
    assert any(line.startswith(f"[resume] restored step {lost_at}") for line in logs), logs[-5:]
    placed = next(line for line in logs if "learner rank nodes" in line)
    assert spare.node_id[:8] in placed, placed
    assert [r["step"] for r in read_metrics(run)] == list(range(1, steps + 1))
    assert latest_checkpoint(run) == checkpoint_dir(run, steps)
    print(f"[figures] rollout node lost after step {seen['rollout lost at']}: generator back {restart_s:.1f} s after "
          f"the kill (outages {[round(o.seconds, 1) for o in outages]} s from the first failed call), generator "
          f"failures {gen.failures}, {len(seen['on the node'])} episodes on the node, re-run groups "
          f"{sorted(rerun_groups)}, ledger {balance}, groups {trainer.scheduler.status_counts()}; learner node lost "
          f"after step {lost_at}; resumed from step {lost_at} to {steps}")

    # No learner node left: a resume is refused before any actor starts, naming what is missing.
    sim.remove_node(nodes.pop("spare"))
    with pytest.raises(PlacementError, match=r"learner_node: the run needs 1 \(1 x learner at 1 each\), "
                                             r"the cluster has 0"):
        train(cfg, resume=True, log=lambda line: None)
    assert latest_checkpoint(run) == checkpoint_dir(run, steps)
