"""`hcgym train`, `hcgym plot`, `hcgym replay` and `hcgym model fetch` (registered by `envs.cli`)."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

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


def train_undoing_failed_start(cfg, *, resume: bool = False, log: Callable[[str], None] = print,
                               report: Callable[[str], None] | None = None) -> dict[str, Any]:
    """`learner.train.train`, and on any failure (Ctrl-C included) `undo_failed_start`, whose
    message goes to `report` (default: stderr) before the error propagates."""
    from learner.train import train

    before = RunFolderSnapshot.take(Path(cfg.output_dir))
    try:
        return train(cfg, resume=resume, log=log)
    except BaseException:
        message = undo_failed_start(before)
        (report or (lambda text: print(f"hcgym train: {text}", file=sys.stderr)))(message)
        raise


def _train(args: argparse.Namespace) -> int:
    from learner.train import config_from_args

    summary = train_undoing_failed_start(config_from_args(args), resume=args.resume)
    print(json.dumps({"steps": summary["steps"], "wall_s": round(summary["wall_s"], 1), "run_dir": summary["run_dir"],
                      "last_validation": summary["last_validation"]}, indent=1))
    return 0


def _plot(args: argparse.Namespace) -> int:
    from learner.plot import plot_runs

    out = plot_runs(args.run_dirs, output=args.output, labels=args.label or None)
    print(out)
    return 0


def _replay(args: argparse.Namespace) -> int:
    from learner.config import load_config
    from learner.train import replay_loss

    cfg = load_config(args.config, args.set)
    metrics = replay_loss(args.trajectories, args.model_dir, cfg)
    print(json.dumps(metrics, indent=1, sort_keys=True))
    return 0


def _model_fetch(args: argparse.Namespace) -> int:
    from modeling.hf_checkpoint import fetch_model

    path = fetch_model(args.model_id, revision=args.revision, cache_dir=args.cache_dir)
    print(path)
    return 0


def register(subparsers) -> None:
    """Add the training subcommands to the `hcgym` parser."""
    from learner.train import build_arg_parser

    train = subparsers.add_parser("train", help="train a policy with GRPO / TT-OPD on local or remote Ray",
                                  description="Train from a run config (configs/*.yaml).")
    build_arg_parser(train)
    train.set_defaults(func=_train)

    plot = subparsers.add_parser("plot", help="training-dynamics figure of one or more runs",
                                 description="Write RUN_DIR/training_dynamics.png (validation accuracy, KL, "
                                             "response length, turns per episode); several runs are overlaid.")
    plot.add_argument("run_dirs", nargs="+", metavar="RUN_DIR")
    plot.add_argument("--output", default=None, help="PNG path (default: FIRST_RUN_DIR/training_dynamics.png)")
    plot.add_argument("--label", action="append", default=[], help="legend label per run (repeatable, in order)")
    plot.set_defaults(func=_plot)

    replay = subparsers.add_parser("replay", help="recompute the loss of stored trajectories (debugging)",
                                   description="Replay a trajectories Parquet file into the learner's loss.")
    replay.add_argument("trajectories", help="RUN_DIR/trajectories/step_XXXXXX.parquet")
    replay.add_argument("--config", required=True)
    replay.add_argument("--model-dir", required=True, help="weights to evaluate (e.g. RUN_DIR/model/sft)")
    replay.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    replay.set_defaults(func=_replay)

    model = subparsers.add_parser("model", help="model checkpoints (the Hugging Face cache)")
    model_sub = model.add_subparsers(dest="model_command", required=True)
    fetch = model_sub.add_parser(
        "fetch", help="download a hub model into the Hugging Face cache (needs hub access)",
        description="Download config, tokenizer and safetensors weights of a hub model into the Hugging Face "
                    "cache (HF_HUB_CACHE, else HF_HOME/hub), where `model.path: ORG/NAME` finds it offline. "
                    "Prints the snapshot folder.")
    fetch.add_argument("model_id", metavar="ID", help="hub model id, e.g. Qwen/Qwen3.5-9B")
    fetch.add_argument("--revision", default=None, help="branch, tag or commit (default: main)")
    fetch.add_argument("--cache-dir", default=None, help="cache folder (default: the Hugging Face hub cache)")
    fetch.set_defaults(func=_model_fetch)
