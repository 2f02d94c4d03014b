"""Starting a run's Ray cluster connection and actors (generators, learner, teacher, KB service)
from the run config. The driver calls these once; placement of actors on nodes is decided here.

Placement (learner/placement.py): `check_run_fits` first, so a run the cluster cannot hold fails
naming the missing resources; generators and the teacher are placed by resources (CPUs, GPUs and
the custom resources of `ray.generator_resources` / `ray.teacher_resources`); the learner places its
DeepSpeed ranks in a placement group itself; `wait_started` waits for every actor's constructor
(model loading) before any rendezvous clock starts.

Node loss: generators, env actors and the teacher are restarted by Ray on another node that has
their resources (`max_restarts`), and the run goes on; the learner's state (weights, optimizer) has
no second copy outside its checkpoints, so losing a learner node stops the run with
`LearnerNodeLost` naming the node, and `--resume` continues from the last checkpoint.
"""

from __future__ import annotations

import os
from typing import Any, Callable

from actors.generator import start_generator_actors
from learner.config import RunConfig
from learner.placement import check_cluster_fits, learner_world_size, rank_placement, run_demands, wait_all_ready


def init_ray(cfg: RunConfig, log: Callable[[str], None] | None = None) -> None:
    """Connect to `ray.address`, or start a local cluster with `ray.num_cpus` (no-op if connected).

    A local cluster listens on 127.0.0.1 only (envs._runtime.init_ray). Before starting one, the
    agents a killed driver's local cluster left behind are stopped (`reap_orphaned_ray_agents`)."""
    import ray

    from envs._runtime import init_ray as start_or_connect_ray

    if ray.is_initialized():
        return
    rc = cfg.ray
    kwargs: dict[str, Any] = {"namespace": rc.namespace, "include_dashboard": rc.include_dashboard,
                              "log_to_driver": True}
    # `ray job submit` runs the driver with RAY_ADDRESS set: a config without `ray.address` joins that
    # cluster instead of failing on `num_cpus` (which Ray refuses when connecting).
    address = rc.address or os.environ.get("RAY_ADDRESS")
    if not address:
        # A fresh local cluster, never a head some other process left running on this machine.
        address = "local"
        kwargs["num_cpus"] = rc.num_cpus
        reaped = reap_orphaned_ray_agents()
        if reaped and log is not None:
            log(f"[setup] stopped {len(reaped)} Ray agent process(es) whose node was gone (left by a killed "
                f"driver): pids {reaped}")
    start_or_connect_ray(address, **kwargs)


# A Ray node's agents are children of its raylet. When a driver that started a local cluster is
# SIGKILLed, its GCS and raylet exit within a second, but these two are re-parented to init and
# linger for a minute or more (docs/benchmarks.md, "Figures behind code defaults"), holding loopback
# ports.
ORPHAN_AGENT_TITLES = ("ray::DashboardAgent", "ray::RuntimeEnvAgent")


def orphaned_ray_agents() -> list[int]:
    """Pids of this user's Ray agent processes whose raylet is gone (re-parented to init, or to a
    subreaper such as `systemd --user`).

    An agent of a live node always has its raylet as parent, so no running cluster's agent matches."""
    if not os.path.isdir("/proc"):
        return []
    found = []
    uid = os.getuid()
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            if entry.stat().st_uid != uid:
                continue
            with open(f"/proc/{entry.name}/stat", "rb") as handle:
                stat = handle.read()
            with open(f"/proc/{entry.name}/cmdline", "rb") as handle:
                title = handle.read().replace(b"\0", b" ").decode("utf-8", "replace").strip()
            if title.split(" ")[0] not in ORPHAN_AGENT_TITLES:
                continue
            ppid = int(stat[stat.rindex(b")") + 2:].split()[1])
            with open(f"/proc/{ppid}/comm", "rb") as handle:
                parent = handle.read().strip()
        except (OSError, ValueError, IndexError):
            continue  # exited meanwhile, or not ours to read
        if parent != b"raylet":
            found.append(int(entry.name))
    return found


def reap_orphaned_ray_agents() -> list[int]:
    """SIGKILL the agents `orphaned_ray_agents` finds; returns their pids. SIGKILL: their SIGTERM
    handler runs on their event loop, and an orphan can outlive SIGTERM by tens of seconds;
    with no node left they hold nothing worth a clean exit. The shell equivalent:

        ps -eo pid=,ppid=,args= | awk '$2 == 1 && ($3 == "ray::DashboardAgent" || $3 == "ray::RuntimeEnvAgent") {print $1}' | xargs -r kill -9

    (`$2 == 1`: where orphans go to init; under a subreaper, its pid.)
    """
    import signal

    pids = orphaned_ray_agents()
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            continue
    return pids


def check_run_fits(cfg: RunConfig) -> None:
    """Raise `PlacementError` naming every resource the cluster lacks for this run's actors
    (skipped with `ray.check_resources: false`, e.g. on autoscaling clusters)."""
    if cfg.ray.check_resources:
        check_cluster_fits(run_demands(cfg), {"learner rank": cfg.ray.learner_placement_strategy})


def start_generators(cfg: RunConfig, policy_dir: str, stop_ids: list[int]) -> list:
    g = cfg.generator
    return start_generator_actors(g.backend, policy_dir, g.sampling, stop_ids, g.num_generators, options=g.options,
                                  python_executable=g.python_executable, max_batch_size=g.max_batch_size,
                                  batch_wait_s=g.batch_wait_s, num_cpus=g.num_cpus, num_gpus=g.num_gpus,
                                  max_restarts=g.max_restarts, resources=dict(cfg.ray.generator_resources) or None,
                                  max_task_retries=0, max_concurrency=1000)


def start_learner(cfg: RunConfig, policy_dir: str):
    from learner.learner_actor import LearnerActor

    rc = cfg.ray
    # At world size 1 the learner actor holds the model, so it takes the learner's custom resources;
    # with more ranks it only fans calls out, and the ranks' placement group takes them.
    custom = dict(rc.learner_resources) if learner_world_size(cfg.learner) == 1 else {}
    return LearnerActor.options(num_cpus=rc.learner_num_cpus, num_gpus=rc.learner_num_gpus, resources=custom or None) \
        .remote(cfg.learner.model_dump(), policy_dir, cfg.seed, rank_placement(cfg).model_dump())


def start_teacher(cfg: RunConfig, policy_dir: str):
    from actors.teacher import TeacherActor

    rc = cfg.ray
    return TeacherActor.options(num_cpus=rc.teacher_num_cpus, num_gpus=rc.teacher_num_gpus,
                                resources=dict(rc.teacher_resources) or None,
                                max_restarts=rc.teacher_max_restarts, max_task_retries=0) \
        .remote(cfg.teacher.model_dump(), policy_dir, cfg.seed)


def wait_started(cfg: RunConfig, learner, generators: list, teacher=None,
                 log: Callable[[str], None] | None = None) -> dict[str, list]:
    """Block until every actor's constructor has finished (`ray.startup_timeout_s` for all together).

    The first actor that fails to start fails the run at once with its error (`StartupError`), and
    rendezvous timeouts (the weight-sync group's) count from here, not from actor creation.

    Returns:
        The learner's `placement_report()` (Ray node id of each rank and of each bundle), also logged.
    """
    import time

    import ray

    started = time.perf_counter()
    members = {"learner": learner.policy_version.remote()}
    members.update({f"generator-{i}": g.version.remote() for i, g in enumerate(generators)})
    if teacher is not None:
        members["teacher"] = teacher.teacher_version.remote()
    wait_all_ready(members, cfg.ray.startup_timeout_s, "run actors")
    report = ray.get(learner.placement_report.remote())
    if log is not None:
        log(f"[setup] {len(members)} actors started in {time.perf_counter() - started:.1f}s; learner rank nodes "
            f"{[n[:8] for n in report['rank_nodes']]}")
    return report


def start_kb_service(cfg: RunConfig):
    """The shared knowledge-base service, or None when `kb.service` is off."""
    if not cfg.kb.service:
        return None
    from kb_service.service import start_kb_service as start

    return start(cfg.kb.replicas, cfg.kb.path, cfg.kb.name, cfg.kb.num_cpus, shards=cfg.kb.shards)


class LearnerNodeLost(RuntimeError):
    """A node that held the learner (or one of its ranks) left the cluster; the message names the
    node, the checkpoint a resume starts from and what the learner needs to be placed again."""


def dead_nodes(node_ids: list[str]) -> list[dict[str, Any]]:
    """The entries of `ray.nodes()` among `node_ids` that Ray reports dead."""
    import ray

    wanted = set(node_ids)
    return [n for n in ray.nodes() if n.get("NodeID") in wanted and not n.get("Alive", True)]


def learner_node_lost(error: BaseException, learner_nodes: dict[str, str], needs: Callable[[], str],
                      kept: Callable[[], str], step: int, wait_s: float = 3.0) -> LearnerNodeLost | None:
    """`LearnerNodeLost` when the run failed because a node of the learner died, else None.

    Args:
        error: What stopped the run.
        learner_nodes: Ray node id -> what ran there ("learner rank 0", "learner actor").
        needs: What the learner asks Ray for, in words (named in the message, for the resume).
        kept: The checkpoint a resume starts from, in words.
        step: The last finished learner step.
        wait_s: How long to wait for Ray to report the node dead after an actor error (the death
            of an actor can reach the driver before the node's own).
    """
    import time

    from ray.exceptions import RayActorError

    if not learner_nodes:
        return None
    actor_error = any(isinstance(e, RayActorError) for e in _error_chain(error))
    deadline = time.monotonic() + (wait_s if actor_error else 0.0)
    while True:
        dead = dead_nodes(list(learner_nodes))
        if dead or time.monotonic() >= deadline:
            break
        time.sleep(0.2)
    if not dead:
        return None
    where = "; ".join(f"{learner_nodes[n['NodeID']]} on node {n['NodeID']} ({n.get('NodeManagerAddress', '?')})"
                      for n in dead)
    return LearnerNodeLost(
        f"lost the learner's node: {where} left the Ray cluster during step {step + 1}, and the learner's "
        f"weights and optimizer state live only there and in checkpoints, so the run stopped. {kept()}. "
        f"Rerun with --resume: it continues from that checkpoint on the remaining nodes if they hold what the "
        f"learner needs ({needs()}); the resource check at start names anything missing")


def _error_chain(error: BaseException):
    seen: set[int] = set()
    todo: list[BaseException | None] = [error]
    while todo:
        current = todo.pop()
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        yield current
        todo.extend([getattr(current, "cause", None), current.__cause__, current.__context__])


def stop_learner(learner, timeout_s: float = 30.0) -> None:
    """Shut the learner down (its ranks' process groups, the ranks, their placement group), then kill it.

    A placement group lives as long as the job that created it, not as long as the actor that
    created it: killing the learner actor alone would hold the ranks' resources until the driver
    process exits (a second run in the same process could not be placed).
    """
    import contextlib

    import ray

    with contextlib.suppress(Exception):  # a dead or hung learner: killing it is all that is left
        ray.get(learner.shutdown.remote(), timeout=timeout_s)
    with contextlib.suppress(Exception):
        ray.kill(learner)
