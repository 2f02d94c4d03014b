"""Where a run's actors go on a Ray cluster, and how the run learns that they all started.

Four jobs, each a plain function the driver and the learner call:

* **Check before creating anything.** `run_demands` lists what every actor of a run asks Ray for
  (CPUs, GPUs, custom resources such as `{"rollout_node": 1}`); `check_cluster_fits` compares it
  with `ray.cluster_resources()` and, per actor, with each alive node (`ray.nodes()`), and raises
  `PlacementError` naming every missing resource. Without it a 2-rank DeepSpeed config on a
  2-CPU cluster waits for Ray's scheduler in silence until some later timeout.
* **Learner ranks in one placement group.** `create_placement_group` reserves one bundle per rank
  (strategy PACK by default: as few nodes as possible, so the ranks' collectives stay local when
  they can) and waits for it with a timeout whose error names the bundles that could not be placed.
  `bundle_scheduling` puts rank r into bundle r; `bundle_nodes` says which node each bundle got.
* **Rendezvous on the right node.** `node_address`, called inside an actor, returns that actor's
  node IP (`ray.util.get_node_ip_address()`) and a port free on that node: torch.distributed's
  store is served by rank 0, so `MASTER_ADDR` must be rank 0's node, never the driver's 127.0.0.1.
* **Start-up that fails fast.** `wait_all_ready` waits on every member's readiness ref together:
  the first member that raises fails the whole start within a scheduling round trip, with that
  member's name and error, instead of the others waiting out their rendezvous timeout; members
  still missing at the deadline are named. Timeouts of later phases (the weight-sync group's
  rendezvous) start after this returns, so slow model loading does not eat into them.

Example (inside a connected Ray driver):
    >>> check_cluster_fits(run_demands(cfg))                   # PlacementError if the cluster lacks something
    >>> pg = create_placement_group([{"CPU": 1}] * 2, "PACK", timeout_s=60, what="learner ranks")
    >>> workers = [Rank.options(scheduling_strategy=bundle_scheduling(pg, r)).remote(r) for r in range(2)]
    >>> wait_all_ready({f"rank {r}": w.ready.remote() for r, w in enumerate(workers)}, 600, "learner ranks")
"""

from __future__ import annotations

import socket
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

if TYPE_CHECKING:  # the run config imports actors; this module stays importable without them
    from learner.config import RunConfig
    from modeling.config_models import LearnerConfig

Strategy = Literal["PACK", "SPREAD", "STRICT_PACK", "STRICT_SPREAD"]

# Ray's own bookkeeping resources: not something a user asks for or a cluster "lacks".
_INTERNAL_PREFIXES = ("node:", "memory", "object_store_memory", "accelerator_type:")


class PlacementError(RuntimeError):
    """The cluster cannot hold what the run asks for; the message names the missing resources."""


class StartupError(RuntimeError):
    """A member of a group failed or did not become ready in time; the message names it."""


class ActorDemand(BaseModel):
    """`count` actors of one kind, each asking Ray for `resources` (e.g. {"CPU": 1, "GPU": 1, "rollout_node": 1})."""

    model_config = ConfigDict(extra="forbid")
    name: str
    count: int = Field(ge=0)
    resources: dict[str, float] = Field(default_factory=dict)


class RankPlacement(BaseModel):
    """How the learner places its DeepSpeed rank actors (the run config's `ray` section fills it).

    `resources` are custom resources every rank's bundle requests in addition to the CPUs and GPUs
    of `learner.deepspeed` (e.g. {"learner_node": 1} to keep ranks on the training nodes).
    """

    model_config = ConfigDict(extra="forbid")
    strategy: Strategy = "PACK"
    resources: dict[str, float] = Field(default_factory=dict)
    placement_timeout_s: float = Field(default=60.0, gt=0)
    startup_timeout_s: float = Field(default=900.0, gt=0)
    check_resources: bool = True


class NodeAddress(BaseModel):
    """Where an actor runs and a TCP port that was free there when asked."""

    model_config = ConfigDict(extra="forbid")
    node_id: str
    ip: str
    port: int


# ----------------------------------------------------------------------------------------------
# What a run needs
# ----------------------------------------------------------------------------------------------


def actor_resources(num_cpus: float = 0.0, num_gpus: float = 0.0,
                    custom: Mapping[str, float] | None = None) -> dict[str, float]:
    """One actor's Ray resource request as a dict, without zero entries (Ray ignores them anyway)."""
    out = {"CPU": float(num_cpus), "GPU": float(num_gpus)}
    out.update({k: float(v) for k, v in (custom or {}).items()})
    return {k: v for k, v in out.items() if v > 0}


def rank_bundle(learner: LearnerConfig, custom: Mapping[str, float] | None = None) -> dict[str, float]:
    """The placement-group bundle of one DeepSpeed rank."""
    ds = learner.deepspeed
    return actor_resources(ds.num_cpus_per_rank, ds.num_gpus_per_rank, custom)


def learner_world_size(learner: LearnerConfig) -> int:
    return learner.deepspeed.world_size if learner.backend == "deepspeed" else 1


def run_demands(cfg: RunConfig) -> list[ActorDemand]:
    """Every actor a training run creates, with what each asks Ray for."""
    rc, g = cfg.ray, cfg.generator
    ws = learner_world_size(cfg.learner)
    demands = [
        ActorDemand(name="generator", count=g.num_generators,
                    resources=actor_resources(g.num_cpus, g.num_gpus, rc.generator_resources)),
        # Env actors are scheduled with num_cpus=0 (tools are light), on nodes with `ray.env_resources`.
        ActorDemand(name="env actor", count=cfg.rollout.num_env_actors, resources=dict(rc.env_resources)),
    ]
    if ws == 1:
        demands.append(ActorDemand(name="learner", count=1, resources=actor_resources(
            rc.learner_num_cpus, rc.learner_num_gpus, rc.learner_resources)))
    else:
        # The learner actor only fans calls out to its ranks; the ranks hold the model.
        demands.append(ActorDemand(name="learner", count=1,
                                   resources=actor_resources(rc.learner_num_cpus, rc.learner_num_gpus)))
        demands.append(ActorDemand(name="learner rank", count=ws,
                                   resources=rank_bundle(cfg.learner, rc.learner_resources)))
    if cfg.teacher.enabled:
        demands.append(ActorDemand(name="teacher", count=1, resources=actor_resources(
            rc.teacher_num_cpus, rc.teacher_num_gpus, rc.teacher_resources)))
    if cfg.kb.service:
        demands.append(ActorDemand(name="knowledge-base replica", count=cfg.kb.replicas,
                                   resources=actor_resources(cfg.kb.num_cpus)))
    return demands


def rank_placement(cfg: RunConfig) -> RankPlacement:
    """The learner's rank placement from the run config's `ray` section."""
    rc = cfg.ray
    return RankPlacement(strategy=rc.learner_placement_strategy, resources=dict(rc.learner_resources),
                         placement_timeout_s=rc.placement_timeout_s, startup_timeout_s=rc.startup_timeout_s,
                         check_resources=rc.check_resources)


# ----------------------------------------------------------------------------------------------
# Does it fit?
# ----------------------------------------------------------------------------------------------


def _user_resources(resources: Mapping[str, float]) -> dict[str, float]:
    return {k: float(v) for k, v in resources.items() if not k.startswith(_INTERNAL_PREFIXES)}


def _fmt(amount: float) -> str:
    return f"{amount:g}"


def _fits(request: Mapping[str, float], capacity: Mapping[str, float]) -> bool:
    return all(capacity.get(k, 0.0) + 1e-9 >= v for k, v in request.items())


def missing_resources(demands: Sequence[ActorDemand], totals: Mapping[str, float],
                      nodes: Sequence[Mapping[str, float]], strategy_groups: Mapping[str, Strategy] | None = None
                      ) -> list[str]:
    """What the demands need that the cluster lacks, one readable line per problem (empty: it fits).

    Checks, in order: the cluster's totals per resource; that each single actor fits on some node
    (a request is never split across nodes); for demands placed as one group (named in
    `strategy_groups`), that one node holds all of them (STRICT_PACK) or that enough nodes hold one
    each (STRICT_SPREAD). A best-effort check: actors of different kinds may still compete for one
    node; the placement-group wait covers that.

    Args:
        demands: What the run creates.
        totals: `ray.cluster_resources()`.
        nodes: Each alive node's total resources (`ray.nodes()[i]["Resources"]`).
        strategy_groups: Demand name -> placement strategy, for demands placed as one group.
    """
    problems: list[str] = []
    need: dict[str, float] = {}
    who: dict[str, list[str]] = {}
    for d in demands:
        for key, amount in d.resources.items():
            if d.count and amount > 0:
                need[key] = need.get(key, 0.0) + amount * d.count
                who.setdefault(key, []).append(f"{d.count} x {d.name} at {_fmt(amount)} each")
    have = _user_resources(totals)
    for key in sorted(need):
        if need[key] > have.get(key, 0.0) + 1e-9:
            problems.append(f"{key}: the run needs {_fmt(need[key])} ({', '.join(who[key])}), "
                            f"the cluster has {_fmt(have.get(key, 0.0))}")
    node_caps = [_user_resources(n) for n in nodes]
    for d in demands:
        if not d.count or not d.resources:
            continue
        if not any(_fits(d.resources, cap) for cap in node_caps):
            problems.append(f"no node can hold one {d.name} ({_describe(d.resources)}); "
                            f"nodes have: {'; '.join(_describe(c) for c in node_caps) or 'none'}")
        elif (strategy_groups or {}).get(d.name) == "STRICT_PACK":
            together = {k: v * d.count for k, v in d.resources.items()}
            if not any(_fits(together, cap) for cap in node_caps):
                problems.append(f"STRICT_PACK: no node can hold all {d.count} {d.name}s together "
                                f"({_describe(together)})")
        elif (strategy_groups or {}).get(d.name) == "STRICT_SPREAD":
            able = sum(_fits(d.resources, cap) for cap in node_caps)
            if able < d.count:
                problems.append(f"STRICT_SPREAD: {d.count} {d.name}s need {d.count} nodes that can each hold "
                                f"one ({_describe(d.resources)}), the cluster has {able}")
    return problems


def _describe(resources: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {_fmt(v)}" for k, v in sorted(resources.items())) or "nothing"


def alive_node_resources() -> list[dict[str, float]]:
    import ray

    return [dict(n["Resources"]) for n in ray.nodes() if n.get("Alive", n.get("alive", False))]


def check_cluster_fits(demands: Sequence[ActorDemand], strategy_groups: Mapping[str, Strategy] | None = None) -> None:
    """Raise `PlacementError` naming every resource the connected cluster lacks for `demands`.

    Autoscaling clusters start nodes on demand, so their current resources understate what they
    can hold: disable the check there (`ray.check_resources: false`).
    """
    import ray

    problems = missing_resources(demands, ray.cluster_resources(), alive_node_resources(), strategy_groups)
    if problems:
        raise PlacementError("the Ray cluster cannot hold this run's actors:\n  " + "\n  ".join(problems))


# ----------------------------------------------------------------------------------------------
# Placement groups
# ----------------------------------------------------------------------------------------------


def create_placement_group(bundles: Sequence[Mapping[str, float]], strategy: Strategy, timeout_s: float,
                           what: str):
    """Reserve `bundles` with `strategy`; wait up to `timeout_s` for every bundle to be placed.

    Raises:
        PlacementError: naming the bundles, the strategy and what the cluster has free, after
            removing the half-placed group (so it does not hold resources).
        ValueError: for an empty bundle (Ray cannot reserve nothing).
    """
    import ray
    from ray.util.placement_group import placement_group, remove_placement_group

    bundles = [dict(b) for b in bundles]
    for i, b in enumerate(bundles):
        if not b:
            raise ValueError(f"{what}: bundle {i} asks for no resources; give the ranks CPUs, GPUs or a "
                             "custom resource (learner.deepspeed.num_cpus_per_rank / num_gpus_per_rank, "
                             "ray.learner_resources)")
    pg = placement_group(bundles, strategy=strategy)
    ready, _ = ray.wait([pg.ready()], timeout=timeout_s)
    if ready:
        ray.get(ready[0])
        return pg
    placed = bundle_nodes(pg)
    remove_placement_group(pg)
    unplaced = [i for i, node in enumerate(placed) if not node]
    raise PlacementError(
        f"{what}: placement group of {len(bundles)} bundle(s) {bundles} with strategy {strategy} was not placed "
        f"within {timeout_s:g}s (bundles not placed: {unplaced or 'all'}); free now: "
        f"{_describe(_user_resources(ray.available_resources()))}"
    )


def bundle_nodes(pg) -> list[str | None]:
    """The node id each bundle of a placement group was placed on (None: not placed)."""
    from ray.util import placement_group_table

    table = placement_group_table(pg)
    mapping = table.get("bundles_to_node_id", {}) or {}
    return [mapping.get(i) or None for i in range(len(table.get("bundles", {})))]


def bundle_scheduling(pg, index: int):
    """A scheduling strategy that puts an actor into bundle `index` (its own child tasks are not captured)."""
    from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

    return PlacementGroupSchedulingStrategy(placement_group=pg, placement_group_bundle_index=index,
                                            placement_group_capture_child_tasks=False)


def remove_placement_group_quietly(pg) -> None:
    """Release a placement group at teardown (it may already be gone with the cluster)."""
    import contextlib

    from ray.util.placement_group import remove_placement_group

    with contextlib.suppress(Exception):
        remove_placement_group(pg)


# ----------------------------------------------------------------------------------------------
# Rendezvous address and start-up
# ----------------------------------------------------------------------------------------------


def node_address(port: int | None = None) -> NodeAddress:
    """This process's Ray node (id and IP) and a TCP port free on it (or `port` when given).

    Call it inside the actor that will serve a torch.distributed store (learner rank 0): the
    address other members connect to must be that actor's node, and only that node can tell
    which of its ports are free.
    """
    import ray

    ip = ray.util.get_node_ip_address()
    if port is None:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            # Bound on all interfaces, as the store will be: free for every peer's route to it.
            sock.bind(("", 0))
            port = sock.getsockname()[1]
    return NodeAddress(node_id=current_node_id(), ip=ip, port=int(port))


def current_node_id() -> str:
    """The Ray node id of this process ("" outside Ray)."""
    import ray

    return ray.get_runtime_context().get_node_id() if ray.is_initialized() else ""


def wait_all_ready(members: Mapping[str, Any], timeout_s: float, what: str) -> dict[str, Any]:
    """Wait for every member's readiness ref; fail on the first error or at the deadline.

    Args:
        members: Readable member name -> ObjectRef that resolves when the member is ready
            (e.g. `actor.ready.remote()`).
        timeout_s: Deadline for all of them together, counted from this call.
        what: The group, for messages ("learner ranks").

    Returns:
        Member name -> the value its ref resolved to.

    Raises:
        StartupError: naming the first member that raised (with its error, chained) or the
            members not ready at the deadline.
    """
    import ray

    name_of = {ref: name for name, ref in members.items()}
    pending = list(name_of)
    results: dict[str, Any] = {}
    deadline = time.monotonic() + timeout_s
    started = time.monotonic()
    while pending:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            missing = sorted(name_of[r] for r in pending)
            raise StartupError(f"{what}: {', '.join(missing)} not ready within {timeout_s:g}s "
                               f"({len(results)} of {len(members)} ready)")
        done, pending = ray.wait(pending, num_returns=1, timeout=remaining)
        for ref in done:
            try:
                results[name_of[ref]] = ray.get(ref)
            except Exception as exc:
                raise StartupError(f"{what}: {name_of[ref]} failed after {time.monotonic() - started:.1f}s: "
                                   f"{_root_message(exc)}") from exc
    return results


def _root_message(exc: BaseException) -> str:
    """The innermost error of a Ray task failure, on one line (Ray wraps it with its traceback)."""
    cause = getattr(exc, "cause", None) or exc.__cause__
    inner = cause if isinstance(cause, BaseException) else exc
    return f"{type(inner).__name__}: {' | '.join(line.strip() for line in str(inner).strip().splitlines())}"
