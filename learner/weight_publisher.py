"""Publishing the learner's new weights after every step: to the generators (every step) through the
object store or the collective group, and to the teacher at its EMA / hard-copy steps.

`object_store`: the learner returns a CPU state dict once (an `ObjectRef`); every generator gets the
ref, and so does the teacher when it updates. `collective`: the learner's rank 0 and the generators
form a private process group (learner/weight_sync.py) and the weights travel in buckets; a group
broken by a restarted generator is re-formed once and the sync retried.
"""

from __future__ import annotations

import asyncio
from typing import Callable

from actors.generator import GeneratorClient
from learner.config import RunConfig


class WeightPublisher:
    """Moves weights from the learner to the generators after each step.

    Args:
        cfg: The run config (`weight_sync` section).
        learner: The learner actor.
        generators: The generator actors.
        gen_client: The generators' client (it remembers the latest version for restarted generators).
        log: Where notices go.
    """

    def __init__(self, cfg: RunConfig, learner, generators: list, gen_client: GeneratorClient,
                 log: Callable[[str], None] = print) -> None:
        self.cfg = cfg
        self.learner = learner
        self.generators = generators
        self.gen_client = gen_client
        self.log = log
        self.collective = cfg.weight_sync.transport == "collective"
        self.formations = 0

    async def start(self) -> None:
        """Form the collective group (no-op for the object store)."""
        if self.collective:
            await self.form_group()

    async def form_group(self) -> None:
        """The learner's rank 0 and every generator join one private process group."""
        from learner.learner_actor import free_port

        config = self.cfg.weight_sync.model_dump()
        # Every (re-)formation needs a fresh rendezvous: the old store may still hold the port.
        config["master_port"] = free_port() if self.formations or not config["master_port"] else config["master_port"]
        self.formations += 1
        world = 1 + len(self.generators)
        names = ["learner-rank0"] + [f"generator-{i}" for i in range(len(self.generators))]
        await asyncio.wait_for(asyncio.gather(
            self.learner.join_weight_sync.remote(config, world, names),
            *[g.join_weight_sync.remote(config, i + 1, world, names) for i, g in enumerate(self.generators)],
        ), self.cfg.weight_sync.timeout_s + 30)

    async def publish(self, version: int):
        """Send the learner's weights of `version` to every generator. Returns the object-store ref
        of the weights (for the teacher), or None when they travelled through the collective group."""
        if self.collective:
            await self._broadcast(version)
            return None
        weights_ref = self.learner.get_weights.remote()
        await self.gen_client.sync_all(weights_ref, version)
        return weights_ref

    async def sync_object_store(self, version: int) -> None:
        """Push the learner's current weights through the object store whatever the transport (resume)."""
        await self.gen_client.sync_all(self.learner.get_weights.remote(), version)

    async def _broadcast(self, version: int) -> None:
        """One collective sync of the new weights; a broken group (a generator restarted) is re-formed
        once and the sync retried, and a generator that still fails catches up via the object store."""
        timeout = self.cfg.weight_sync.timeout_s + 30
        for attempt in range(2):
            try:
                await asyncio.wait_for(asyncio.gather(
                    self.learner.broadcast_weights.remote(),
                    *[g.receive_weights.remote(version) for g in self.generators],
                ), timeout)
                break
            except Exception as exc:
                if attempt == 1:
                    raise RuntimeError(f"collective weight sync of version {version} failed twice: {exc}") from exc
                self.log(f"[weight sync] {type(exc).__name__}: {exc}; re-forming the group")
                await self.form_group()
        self.gen_client.publish(None, version)
