"""The driver's side of the TT-OPD teacher: submit finished groups, fetch their scores for a learner
step, apply the EMA / hard-copy schedule, and recover a teacher that Ray restarted.

Fault recovery: Ray restarts a dead teacher with its constructor's weights. The client keeps what
it needs to rebuild the EMA state the teacher had: a confirmed snapshot (None = the constructor's
weights) and the updates applied after it, replayed in order; the snapshot requested after the
latest update replaces both once it exists. Groups submitted but not yet fetched are re-submitted.

With the collective weight sync (`weight_sync.transport: collective`) no full state dict of the
teacher or the student goes through the object store: the teacher's updates arrive in the weight-sync
group's buckets (learner/weight_publisher.py), and no EMA snapshot is kept. A restarted teacher is
then recovered by adopting the student's current weights at the driver's teacher version (the EMA
history is lost; counted as `teacher_recoveries_inexact`). An update that cannot go through the group
falls back to the object store; `teacher_sync_object_store` (count) and `..._bytes` measure that path,
`teacher_sync_collective_bytes` the streamed one.

Retries live here, beside `actors.generator.GeneratorClient`'s: a step is retried (up to five times)
when the teacher died before or during the fetch, an update up to three times.
"""

from __future__ import annotations

import asyncio
from typing import Any, Callable

from actors.types import PendingTeacherBatch, RolloutSample, TeacherOutput
from learner.batching import Group
from learner.config import RunConfig
from modeling.config_models import teacher_update_action

STEP_ATTEMPTS = 5
UPDATE_ATTEMPTS = 3


def object_store_bytes(ref) -> int:
    """Size of an object in Ray's object store (what an object-store update moves), 0 if unknown."""
    import ray

    try:
        return int(ray.experimental.get_object_locations([ref])[ref]["object_size"] or 0)
    except Exception:  # noqa: BLE001  (a metric only: never fail a step over it)
        return 0


class TeacherClient:
    """Talks to one `TeacherActor` for the driver.

    Args:
        handle: The teacher actor.
        learner: The learner actor (the step runs there; it waits on the teacher's fetch itself).
        cfg: The run config.
        counters: The run's counter dict (`teacher_recoveries`, `teacher_stale_outputs` are added).
        log: Where notices go.
    """

    def __init__(self, handle, learner, cfg: RunConfig, counters: dict[str, int],
                 log: Callable[[str], None] = print) -> None:
        self.handle = handle
        self.learner = learner
        self.cfg = cfg
        self.log = log
        self.counters = counters
        self.collective = cfg.weight_sync.transport == "collective"
        for key in ("teacher_recoveries", "teacher_sync_object_store", "teacher_sync_object_store_bytes",
                    "teacher_sync_collective_bytes"):
            self.counters.setdefault(key, 0)
        self.version = 0                      # teacher version after the latest confirmed update
        self.base_ref = None                  # recovery snapshot (None = the constructor's weights)
        self.replay: list[tuple[Any, int]] = []   # (weights ref, step) applied after the snapshot
        self.snapshot_pending = None          # snapshot requested after the latest update
        self.outstanding: dict[int, Group] = {}   # submitted, not yet fetched

    # -- scoring ---------------------------------------------------------------------------------
    def submit(self, group: Group) -> None:
        """Queue a finished group for teacher scoring; the teacher computes while rollouts go on."""
        group.teacher_submit_ref = self.handle.submit.remote(group.samples)
        group.teacher_submitted = True
        group.teacher_floor = self.version
        self.outstanding[group.seq] = group

    async def train_step(self, groups: list[Group], samples: list[RolloutSample], step: int
                         ) -> tuple[dict[str, float], dict[str, TeacherOutput]]:
        """One learner step whose teacher log-probs are fetched while the learner already runs.

        The fetch's ref goes to the learner inside a list: the learner does its reference and
        pi_old forwards first and blocks on the teacher only for what is not scored yet. A teacher
        that died (fetch fails, or the step's samples are unknown to it) is recovered and the step
        retried; nothing was updated, the learner resolves the teacher before its backward.

        Returns:
            (learner metrics, {sample id: TeacherOutput}).
        """
        from ray.exceptions import RayActorError

        for group in groups:
            if not group.teacher_submitted:
                self.submit(group)  # a fill group (filtered when it finished)
        ids = [s.sample_id for g in groups for s in g.samples]
        floors = {s.sample_id: g.teacher_floor for g in groups for s in g.samples}
        timeout = self.cfg.trainer.teacher_timeout_s
        for _ in range(STEP_ATTEMPTS):
            try:
                # Threaded actor: a fetch may overtake a submit sent just before it; wait for those.
                await asyncio.gather(*[g.teacher_submit_ref for g in groups])
                # A teacher restarted since its last update scores with its initial weights: restore first.
                if await self.handle.teacher_version.remote() != self.version:
                    await self.recover("teacher version behind the driver's")
                    continue
            except RayActorError as exc:
                await self.recover(f"{type(exc).__name__} before fetch")
                continue
            fetch_ref = self.handle.fetch.remote(ids, timeout)
            try:
                metrics = await self.learner.train_step.remote(samples, PendingTeacherBatch(fetch_ref), step)
            except Exception as exc:
                try:
                    await fetch_ref
                except (RayActorError, KeyError) as teacher_exc:
                    await self.recover(f"{type(teacher_exc).__name__} during fetch")
                    continue
                raise exc
            fetched = await fetch_ref
            old = [o for o in fetched.outputs if o.teacher_version < floors[o.sample_id]]
            if old:
                # Scored by a restarted teacher in the instant before the version check: counted and
                # logged, the step has used them.
                self.counters["teacher_stale_outputs"] = self.counters.get("teacher_stale_outputs", 0) + len(old)
                self.log(f"[teacher] {len(old)} outputs of step {step} came from teacher version "
                         f"{old[0].teacher_version} < {floors[old[0].sample_id]}")
            for group in groups:
                self.outstanding.pop(group.seq, None)
            return metrics, {o.sample_id: o for o in fetched.outputs}
        raise RuntimeError(f"teacher failed to serve step {step} {STEP_ATTEMPTS} times")

    # -- updates ---------------------------------------------------------------------------------
    async def update(self, step: int, weights_ref=None, streamed: dict[str, Any] | None = None) -> str:
        """EMA / hard copy after learner step `step` (Algorithm 1), awaited so that work admitted
        afterwards is scored by the updated teacher. Returns the action ("none", "ema", "hard_copy").

        Args:
            step: The learner step just taken.
            weights_ref: The step's weights in the object store (None: fetched from the learner).
            streamed: The teacher's `receive_update` result when the collective group already
                delivered and applied the update; only confirmed here.
        """
        action = teacher_update_action(step, self.cfg.teacher)
        if streamed is not None:
            self.counters["teacher_sync_collective_bytes"] += int(streamed.get("bytes", 0))
            if action != "none":
                self._confirmed(streamed, action, step)
            return action
        if action == "none":
            return action
        if weights_ref is None:
            weights_ref = self.learner.get_weights.remote()
        if not self.collective:
            self._confirm_snapshot()
        for attempt in range(UPDATE_ATTEMPTS):
            try:
                result = await self.handle.update.remote(weights_ref, step)
                break
            except Exception as exc:
                from ray.exceptions import RayActorError

                if not isinstance(exc, RayActorError) or attempt == UPDATE_ATTEMPTS - 1:
                    raise
                await self.recover(f"{type(exc).__name__} during update")
        self._confirmed(result, action, step)
        self.counters["teacher_sync_object_store"] += 1
        self.counters["teacher_sync_object_store_bytes"] += object_store_bytes(weights_ref)
        if not self.collective:  # recovery state: full state dicts, kept only on the object-store path
            self.replay.append((weights_ref, step))
            self.snapshot_pending = self.handle.get_state.remote()
        return action

    def sync_metrics(self) -> dict[str, float]:
        """Cumulative teacher-sync figures for the step record."""
        return {k: float(self.counters[k]) for k in ("teacher_sync_object_store", "teacher_sync_object_store_bytes",
                                                     "teacher_sync_collective_bytes")}

    async def group_member(self):
        """The teacher's handle if it may join the collective weight-sync group now (it answers; a
        restarted one is recovered first), else None: it is then updated through the object store."""
        try:
            current = await asyncio.wait_for(self.handle.teacher_version.remote(), 30)
        except Exception:  # dead or still restarting: left out of this group
            return None
        if current != self.version:
            await self.recover("restarted before joining the weight-sync group")
        return self.handle

    def _confirmed(self, result: dict[str, Any], action: str, step: int) -> None:
        if result["action"] != action:
            raise RuntimeError(f"teacher applied {result['action']!r} at step {step}, driver expected {action!r}")
        self.version = int(result["teacher_version"])

    # -- fault recovery --------------------------------------------------------------------------
    def _confirm_snapshot(self) -> None:
        """Promote the latest post-update teacher state to the recovery base once it exists."""
        import ray

        ref = self.snapshot_pending
        if ref is None or not ray.wait([ref], timeout=0)[0]:
            return
        try:
            ray.get(ref, timeout=0)
        except Exception:  # the teacher died before producing it: keep base + replay
            self.snapshot_pending = None
            return
        self.base_ref, self.replay, self.snapshot_pending = ref, [], None

    async def recover(self, why: str) -> None:
        """Ray restarted the teacher with its initial weights: restore the EMA state it had (the last
        confirmed snapshot plus the updates since, replayed in order), then re-submit every group
        whose scores it may have lost."""
        self.counters["teacher_recoveries"] += 1
        self.log(f"[teacher] recovering ({why}): restoring teacher version {self.version}")
        current = -1
        for _ in range(600):
            try:
                current = await asyncio.wait_for(self.handle.teacher_version.remote(), 30)
                break
            except Exception:
                await asyncio.sleep(0.5)
        if current != self.version and self.collective:
            # No snapshot in collective mode: start again from the student's current weights.
            weights_ref = self.learner.get_weights.remote()
            await self.handle.adopt.remote(weights_ref, self.version)
            self.counters["teacher_recoveries_inexact"] = self.counters.get("teacher_recoveries_inexact", 0) + 1
            self.counters["teacher_sync_object_store"] += 1
            self.counters["teacher_sync_object_store_bytes"] += object_store_bytes(weights_ref)
            self.log(f"[teacher] restarted teacher adopted the student's weights at version {self.version} "
                     "(collective weight sync keeps no EMA snapshot)")
        elif current != self.version:  # restarted: its weights are the constructor's
            if self.base_ref is not None:
                await self.handle.set_state.remote(self.base_ref)
            for weights_ref, step in self.replay:
                await self.handle.update.remote(weights_ref, step)
        restored = await self.handle.teacher_version.remote()
        if restored != self.version:
            raise RuntimeError(f"teacher recovery restored version {restored}, expected {self.version}")
        for group in list(self.outstanding.values()):
            self.submit(group)

    # -- checkpoints -----------------------------------------------------------------------------
    async def save(self, directory: str) -> None:
        await self.handle.save.remote(directory)

    async def restore(self, directory: str, expected_version: int) -> None:
        """Load the teacher's part of a checkpoint; a teacher restarted later comes back to this state."""
        await self.handle.load.remote(directory)
        self.version = int(await self.handle.teacher_version.remote())
        if self.version != expected_version:
            raise RuntimeError(f"{directory}: teacher version {self.version} != driver's {expected_version}")
        if not self.collective:
            self.base_ref = self.handle.get_state.remote()
