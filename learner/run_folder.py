"""A training run's folder: what a run writes there, and undoing a start that failed.

Used by both entry points of training (`hcgym train` and `python -m learner.train`, the cluster
job's), so a run that fails before its first learner step leaves nothing half-made.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, TypeVar

T = TypeVar("T")

METRICS_FILE = "metrics.jsonl"  # one line per learner step (learner/metrics.py)
CONFIG_FILE = "config.yaml"
# What a training run writes at the top of its folder (learner/train.py, metrics.py, sft.py, plot.py).
# Only these are ever removed after a failed start: `output_dir` may be a shared folder where
# other programs create files while the run starts.
RUN_ENTRIES = frozenset({CONFIG_FILE, "model", "checkpoints", "trajectories", METRICS_FILE, "validation.jsonl",
                         "validation", "tensorboard", "summary.json", "training_dynamics.png"})


@dataclass
class RunFolderSnapshot:
    """What a run folder held before `hcgym train` started, so a failed start can be undone."""

    run_dir: Path
    existed: bool
    entries: set[str] = field(default_factory=set)
    config_bytes: bytes | None = None  # config.yaml, which the new run overwrites first
    steps_recorded: int = 0

    @classmethod
    def take(cls, run_dir: Path) -> "RunFolderSnapshot":
        if not run_dir.is_dir():
            return cls(run_dir, existed=run_dir.exists())
        config = run_dir / CONFIG_FILE
        return cls(run_dir, True, {p.name for p in run_dir.iterdir()},
                   config.read_bytes() if config.is_file() else None, _steps_recorded(run_dir))


def _steps_recorded(run_dir: Path) -> int:
    try:
        with open(run_dir / METRICS_FILE, "rb") as handle:
            return sum(1 for line in handle if line.strip())
    except OSError:
        return 0


def _complete_policy(model_dir: Path) -> bool:
    """True when `model/` holds a finished initial policy (its record names a checkpoint with a
    config.json): a rerun with the same config reuses it instead of rebuilding (learner/sft.py)."""
    from learner.sft import POLICY_RECORD

    try:
        record = json.loads((model_dir / POLICY_RECORD).read_text(encoding="utf-8"))
        return (Path(record["policy_dir"]) / "config.json").is_file()
    except (OSError, ValueError, KeyError, TypeError):
        return False


def undo_failed_start(before: RunFolderSnapshot) -> str:
    """After a run failed, remove what it created if it had not finished a learner step yet.

    Removed: every top-level entry of the run folder the failed run created among those a run
    writes (`RUN_ENTRIES`: config.yaml, an empty or half-built model/, tensorboard/ ...), and the
    folder itself when it was new and ends up empty; config.yaml is restored when an earlier run had written one. Kept: whatever was
    there before, and a complete initial policy in model/ (rebuilding it can take minutes of SFT).
    A run that finished a step keeps its folder as it is (its checkpoints and metrics are real).

    Returns:
        One message saying exactly what was removed and what was left.
    """
    run_dir = before.run_dir
    if not run_dir.is_dir():
        return f"the run failed before creating {run_dir}"
    steps = _steps_recorded(run_dir)
    if steps > before.steps_recorded:
        return f"the run failed after recording {steps - before.steps_recorded} step(s); {run_dir} is left as it is"
    removed, kept = [], []
    for path in sorted(run_dir.iterdir()):
        if path.name in before.entries:
            continue
        if path.name not in RUN_ENTRIES:
            kept.append(f"{path.name} (not written by the run)")
            continue
        if path.name == "model" and path.is_dir() and _complete_policy(path):
            kept.append("model/ (the complete initial policy; a rerun with this config reuses it)")
            continue
        folder = path.is_dir() and not path.is_symlink()
        if folder:
            shutil.rmtree(path)
        else:
            path.unlink()
        removed.append(path.name + ("/" if folder else ""))
    config = run_dir / CONFIG_FILE
    if before.config_bytes is not None and config.is_file() and config.read_bytes() != before.config_bytes:
        config.write_bytes(before.config_bytes)
        kept.append(f"{CONFIG_FILE} (restored to the earlier run's)")
    if not before.existed and not any(run_dir.iterdir()):
        run_dir.rmdir()
        what = ", ".join(removed) + " and " if removed else ""
        return f"the run failed before its first step; removed {what}the folder {run_dir}, which it had created"
    parts = [f"the run failed before its first step; in {run_dir}"]
    parts.append("removed " + ", ".join(removed) if removed else "removed nothing")
    if kept:
        parts.append("kept " + "; ".join(kept))
    if before.entries:
        earlier = sorted(before.entries)
        more = f" and {len(earlier) - 10} more" if len(earlier) > 10 else ""
        parts.append("left what was there before: " + ", ".join(earlier[:10]) + more)
    return "; ".join(parts)


def run_undoing_failed_start(run_dir: Path, start: Callable[[], T], report: Callable[[str], None]) -> T:
    """`start()` (a training run writing to `run_dir`); on any failure, Ctrl-C included,
    `undo_failed_start` and its message to `report` before the error propagates."""
    before = RunFolderSnapshot.take(Path(run_dir))
    try:
        return start()
    except BaseException:
        report(undo_failed_start(before))
        raise
