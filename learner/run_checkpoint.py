"""The driver's part of a run checkpoint (`driver.json`: step, data position, groups to re-admit,
counters) and the save / restore of a whole checkpoint across the learner, the teacher and the driver.
The layout is in modeling/checkpoint.py."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any, Callable

from envs.core.files import as_disk_full
from learner.batching import BatchScheduler
from modeling.checkpoint import (CheckpointError, checkpoint_dir, latest_checkpoint, mark_latest, prune_checkpoints,
                                read_json, write_json_atomic)
from learner.faults import fault_point
from learner.teacher_client import TeacherClient

DRIVER_STATE = "driver.json"
# What `restore_run_checkpoint` reads from driver.json before touching any actor: a file lacking one
# fails naming the file and the key, not with a bare KeyError halfway through the restore.
DRIVER_STATE_KEYS: dict[str, type | tuple[type, ...]] = {
    "step": int, "teacher_version": int, "counters": dict, "sampler": dict, "next_seq": int, "consume_seq": int,
    "readmit": list,
}


async def save_run_checkpoint(run_dir: Path, step: int, learner, teacher: TeacherClient | None,
                              scheduler: BatchScheduler, counters: dict[str, int], ledger: dict[str, Any],
                              keep_last: int, *, mark: bool = True) -> Path:
    """Write `RUN_DIR/checkpoints/step_N/` (learner, teacher, driver.json), then (with `mark`) mark
    it `latest`. The driver passes `mark=False` and calls `commit_run_checkpoint` once everything
    else the step produced (trajectories, validation, its metrics row) is on disk: a crash before
    that resumes from the previous checkpoint and redoes the step, so nothing of it is lost.

    A step folder left by an earlier attempt that never became `latest` (a driver or a learner
    killed mid-save, then resumed from an older checkpoint) is removed first, so none of its
    leftovers (temporary files of an interrupted write, parts of another attempt) ends up in this one.

    Raises:
        DiskFullError: naming the file (or the step folder) when the disk filled; the partial
            step folder is removed and `latest` is left as it was.
    """
    directory = checkpoint_dir(run_dir, step)
    latest = latest_checkpoint(run_dir)
    if latest is not None and latest.name == directory.name:
        # A resumed run that ends at the step it restored: that checkpoint is complete and already
        # `latest`; rewriting it in place would leave no complete checkpoint while it is written.
        return directory
    if directory.exists():
        shutil.rmtree(directory)
    try:
        directory.mkdir(parents=True)
        await learner.save_checkpoint.remote(str(directory))
        if teacher is not None:
            await teacher.save(str(directory))
        write_json_atomic(directory / DRIVER_STATE, {
            "step": step, "teacher_version": teacher.version if teacher is not None else 0,
            **scheduler.state_dict(), "counters": counters, "ledger": ledger,
        })
    except Exception as exc:
        # The learner writes through torch / safetensors, whose errors on a full disk name neither
        # the file nor the cause ("basic_ios::clear: iostream error"); the driver checks the disk.
        full = as_disk_full(exc, directory)
        if full is None:
            raise
        # Never `latest`, so never read: removed, which also gives its space back.
        shutil.rmtree(directory, ignore_errors=True)
        kept = f"`latest` still names {latest.name}" if latest is not None else "the run has no checkpoint yet"
        raise full.with_hint(f"The checkpoint of step {step} was not written (its partial folder {directory} "
                             f"is removed); {kept}") from exc
    fault_point("checkpoint_saved", step)
    if mark:
        commit_run_checkpoint(run_dir, step, keep_last)
    return directory


def commit_run_checkpoint(run_dir: Path, step: int, keep_last: int) -> None:
    """Make the written checkpoint of `step` the one a resume starts from, then prune old ones."""
    mark_latest(run_dir, step)
    fault_point("latest_marked", step)
    prune_checkpoints(run_dir, keep_last)


async def restore_run_checkpoint(run_dir: Path, learner, teacher: TeacherClient | None, scheduler: BatchScheduler,
                                 counters: dict[str, int], log: Callable[[str], None]) -> tuple[int, Path] | None:
    """Load the latest checkpoint into the learner, the teacher and the scheduler.

    Returns:
        (step, directory), or None when the run has no checkpoint yet.
    """
    directory = latest_checkpoint(run_dir)
    if directory is None:
        log(f"[resume] {run_dir} has no checkpoint yet: starting from step 0")
        return None
    driver_file = directory / DRIVER_STATE
    state = read_json(driver_file, required=DRIVER_STATE_KEYS)
    step = state["step"]
    if step < 1:
        raise CheckpointError(f"{driver_file}: key 'step' should be >= 1, got {step}")
    learner_state = await learner.load_checkpoint.remote(str(directory))
    if int(learner_state["step"]) != step:
        raise RuntimeError(f"{directory}: learner step {learner_state['step']} != driver step {step}")
    try:
        scheduler.load_state_dict(state, version=step)
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{driver_file}: malformed data position ({type(exc).__name__}: {exc})") from None
    counters.update(state["counters"])
    if teacher is not None:
        await teacher.restore(str(directory), int(state["teacher_version"]))
    return step, directory
