"""Publishing the learner's new weights after every step: to the generators (every step) through the
object store or the collective group, and to the teacher at its EMA / hard-copy steps.

`object_store`: the learner returns a CPU state dict once (an `ObjectRef`); every generator gets the
ref, and so does the teacher when it updates. `collective`: the learner's rank 0, the generators and
the teacher form one private process group (modeling/weight_sync.py) and the weights travel in
buckets; nothing passes through the object store. The teacher receives every broadcast and applies
its schedule bucket by bucket (`Teacher.receive_update`; at steps without an update it drops the
stream). A group broken by a restarted member is re-formed once and the sync retried; a teacher
that cannot join (dead, restarting) is left out and updated through the object store instead
(`TeacherClient.update`, counted as `teacher_sync_object_store`).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any, Awaitable, Callable

from actors.generator import GeneratorClient
from learner.config import RunConfig


@dataclass(frozen=True)
class GroupLayout:
    """Ranks of one weight-sync group: 0 is the learner's rank 0; generator i owns `ranks_per_generator`
    consecutive ranks from `generator_ranks[i]` (a vLLM engine's tensor-parallel workers each join as
    `generator_ranks[i] + tp_rank`); the teacher, when present, is last."""

    names: list[str]
    generator_ranks: list[int]
    teacher_rank: int | None

    @property
    def world_size(self) -> int:
        return len(self.names)


def weight_sync_layout(num_generators: int, ranks_per_generator: int, with_teacher: bool) -> GroupLayout:
    """The group's ranks and a readable name per rank (`generator-1-tp0`, ... with tensor parallelism)."""
    if ranks_per_generator < 1:
        raise ValueError(f"ranks_per_generator must be >= 1, got {ranks_per_generator}")
    names = ["learner-rank0"]
    firsts = []
    for i in range(num_generators):
        firsts.append(len(names))
        names += ([f"generator-{i}"] if ranks_per_generator == 1
                  else [f"generator-{i}-tp{r}" for r in range(ranks_per_generator)])
    teacher_rank = None
    if with_teacher:
        teacher_rank = len(names)
        names.append("teacher")
    return GroupLayout(names=names, generator_ranks=firsts, teacher_rank=teacher_rank)


@dataclass
class Published:
    """Where one version's weights went: the object-store ref (None with the collective transport)
    and the teacher's `receive_update` result when the teacher received them in the group."""

    weights_ref: Any = None
    teacher_result: dict[str, Any] | None = None


class WeightPublisher:
    """Moves weights from the learner to the generators after each step.

    Args:
        cfg: The run config (`weight_sync` section).
        learner: The learner actor.
        generators: The generator actors.
        gen_client: The generators' client (it remembers the latest version for restarted generators).
        log: Where notices go.
        teacher_member: Collective transport with a teacher: returns the teacher's handle when it may
            join the group (alive, at the driver's version), or None to leave it out this time.
    """

    def __init__(self, cfg: RunConfig, learner, generators: list, gen_client: GeneratorClient,
                 log: Callable[[str], None] = print,
                 teacher_member: Callable[[], Awaitable[Any]] | None = None) -> None:
        self.cfg = cfg
        self.learner = learner
        self.generators = generators
        self.gen_client = gen_client
        self.log = log
        self.collective = cfg.weight_sync.transport == "collective"
        self.formations = 0
        self.teacher_member = teacher_member if self.collective else None
        self.teacher_in_group = None  # the teacher's handle while it is a member of the current group

    async def start(self) -> None:
        """Form the collective group (no-op for the object store)."""
        if self.collective:
            await self.form_group()

    async def form_group(self) -> None:
        """The learner's rank 0, every generator and (when it can join) the teacher form one group."""
        config = self.cfg.weight_sync.model_dump()
        # The group's store is served by learner rank 0: members on any node connect to its node,
        # at a port free there. Every (re-)formation needs a fresh port: the old store may still hold it.
        address = await self.learner.rendezvous_address.remote()
        config["master_addr"] = address["ip"]
        config["master_port"] = address["port"] if self.formations or not config["master_port"] else config["master_port"]
        self.formations += 1
        self.teacher_in_group = None
        teacher = await self.teacher_member() if self.teacher_member is not None else None
        layout = weight_sync_layout(len(self.generators), self.cfg.generator.ranks_per_generator(),
                                    teacher is not None)
        names, world = layout.names, layout.world_size
        joins = [self.learner.join_weight_sync.remote(config, world, names),
                 *[g.join_weight_sync.remote(config, first, world, names)
                   for g, first in zip(self.generators, layout.generator_ranks)]]
        if teacher is not None:
            joins.append(teacher.join_weight_sync.remote(config, layout.teacher_rank, world, names))
        await asyncio.wait_for(asyncio.gather(*joins), self.cfg.weight_sync.timeout_s + 30)
        self.teacher_in_group = teacher

    async def publish(self, version: int) -> Published:
        """Send the learner's weights of `version` (= the learner step) to every generator, and in the
        collective group to the teacher too (it applies that step's EMA / hard copy as they arrive)."""
        if self.collective:
            if self.teacher_member is not None and self.teacher_in_group is None:
                await self.form_group()  # the teacher was left out last time: let it back in
            return Published(teacher_result=await self._broadcast(version))
        weights_ref = self.learner.get_weights.remote()
        await self.gen_client.sync_all(weights_ref, version)
        return Published(weights_ref=weights_ref)

    async def sync_object_store(self, version: int) -> None:
        """Push the learner's current weights through the object store whatever the transport (resume)."""
        await self.gen_client.sync_all(self.learner.get_weights.remote(), version)

    async def _broadcast(self, version: int) -> dict[str, Any] | None:
        """One collective sync of the new weights; a broken group (a generator or the teacher restarted)
        is re-formed once and the sync retried, and a generator that still fails catches up via the
        object store. Returns the teacher's `receive_update` result (None when it was not a member)."""
        timeout = self.cfg.weight_sync.timeout_s + 30
        for attempt in range(2):
            teacher = self.teacher_in_group
            calls = [self.learner.broadcast_weights.remote(),
                     *[g.receive_weights.remote(version) for g in self.generators]]
            if teacher is not None:
                calls.append(teacher.receive_update.remote(version, version))
            try:
                results = await asyncio.wait_for(asyncio.gather(*calls), timeout)
                break
            except Exception as exc:
                if attempt == 1:
                    raise RuntimeError(f"collective weight sync of version {version} failed twice: {exc}") from exc
                self.log(f"[weight sync] {type(exc).__name__}: {exc}; re-forming the group")
                await self.form_group()
        self.gen_client.publish(None, version)
        return results[-1] if teacher is not None else None
