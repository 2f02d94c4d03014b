"""A test hook that kills this process at a named point of a write sequence.

    HCGYM_FAULT_AT=metrics_written:2 python -m learner.train --config ...

makes the driver SIGKILL itself right after it appended step 2's row to metrics.jsonl, so a crash
test hits an exact point of the sequence instead of relying on the luck of timing. The value is
`POINT` (the first time the point is reached) or `POINT:STEP` (only at that learner step; for an
evaluation, the Nth flush). Unset (the default), `fault_point` only records the point in `REACHED`,
so a test can check the order in which a run passed them. A test running the driver in its own
process can also make something happen at a point (`at`: e.g. fill the disk right after step 1's
checkpoint became `latest`).

The driver's points at each learner step, in order (learner/train.py):

    checkpoint_saved      step_N/ fully written, `latest` not moved yet   (checkpoint steps only)
    validation_written    the validation pass wrote validation.jsonl and validation/step_N.parquet
                          (validation steps only)
    trajectories_written  trajectories/step_N.parquet written
    metrics_written       step N's metrics.jsonl row appended
    latest_marked         `latest` names step_N                            (checkpoint steps only)

A run whose last step is not a validation or a checkpoint step ends with its last validation
(validation_written), then its last checkpoint (checkpoint_saved, latest_marked).

An evaluation's (evals/runner.py), at each flush: `eval_trajectories_written` (between the
trajectories.parquet and results.parquet renames) and `eval_results_written`.
"""

from __future__ import annotations

import os
import signal
from typing import Callable

FAULT_ENV = "HCGYM_FAULT_AT"
REACHED: list[str] = []  # "point:step" in the order this process reached them
_ACTIONS: dict[str, Callable[[], None]] = {}


def at(where: str, action: Callable[[], None]) -> None:
    """Run `action()` once, in the thread that reaches `where` (`POINT` or `POINT:STEP`), right there."""
    _ACTIONS[where] = action


def clear_actions() -> None:
    """Forget the actions `at` registered that no point has run yet."""
    _ACTIONS.clear()


def fault_point(name: str, step: int | None = None) -> None:
    """Record `name` (at `step`) and SIGKILL this process when `HCGYM_FAULT_AT` names it."""
    where = name if step is None else f"{name}:{step}"
    REACHED.append(where)
    if len(REACHED) > 10_000:  # a long run or evaluation passes these points without end
        del REACHED[:5_000]
    if _ACTIONS:
        action = _ACTIONS.pop(where, None) or _ACTIONS.pop(name, None)
        if action is not None:
            action()
    wanted = os.environ.get(FAULT_ENV)
    if wanted and wanted in (name, where):
        os.kill(os.getpid(), signal.SIGKILL)
