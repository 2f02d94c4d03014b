"""`hcgym train`, `hcgym plot`, `hcgym replay`, `hcgym plan`, `hcgym model fetch` and `hcgym config reference`
(registered by `envs.cli`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable

from learner.run_folder import run_undoing_failed_start

def train_undoing_failed_start(cfg, *, resume: bool = False, log: Callable[[str], None] = print,
                               report: Callable[[str], None] | None = None) -> dict[str, Any]:
    """`learner.train.train`, and on any failure (Ctrl-C included) `undo_failed_start`, whose
    message goes to `report` (default: stderr) before the error propagates."""
    from learner.train import train

    return run_undoing_failed_start(Path(cfg.output_dir), lambda: train(cfg, resume=resume, log=log),
                                    report or (lambda text: print(f"hcgym train: {text}", file=sys.stderr)))


def _train(args: argparse.Namespace) -> int:
    from learner.train_args import config_from_args

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


def _config_reference(args: argparse.Namespace) -> int:
    from learner.config_reference import check_reference, render_reference, write_reference

    if args.check:
        problems = check_reference(args.output or "docs/config.md")
        for problem in problems:
            print(f"hcgym config reference: {problem}", file=sys.stderr)
        return 1 if problems else 0
    if args.output is None:
        sys.stdout.write(render_reference())
    else:
        print(write_reference(args.output))
    return 0


def _plan(args: argparse.Namespace) -> int:
    from learner.config import load_config
    from modeling.plan import format_plan, plan_run

    cfg = load_config(args.config, args.set)
    try:
        plan = plan_run(cfg, args.gpu)
    except ValueError as exc:
        print(f"hcgym plan: {exc}", file=sys.stderr)
        return 2
    print(plan.model_dump_json(indent=1) if args.json else format_plan(plan))
    if not plan.fits:
        print(f"hcgym plan: {args.config} does not fit on {plan.gpu}:\n  " + "\n  ".join(plan.problems),
              file=sys.stderr)
        return 1
    return 0


def register(subparsers) -> None:
    """Add the training subcommands to the `hcgym` parser."""
    from learner.train_args import build_arg_parser

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

    from modeling.plan import GPUS

    plan = subparsers.add_parser(
        "plan", help="memory per actor, GPUs, CPUs and checkpoint time of a config on a GPU kind",
        description="Print what a run config needs on a GPU kind, per actor (ZeRO-3 states per rank, activations, "
                    "the teacher's weights and EMA shadow, the generators' KV cache), the GPUs, CPUs and nodes, host "
                    "memory for offload, and the checkpoint size and write time (modeling/plan.py has the formulas). "
                    "Exits 1, naming what to change, when the config does not fit.")
    plan.add_argument("--config", required=True)
    plan.add_argument("--gpu", choices=sorted(GPUS), default=None, help="GPU kind (default: the config's cluster.gpu)")
    plan.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE")
    plan.add_argument("--json", action="store_true", help="print the plan as JSON")
    plan.set_defaults(func=_plan)

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

    config = subparsers.add_parser("config", help="the run config's schema")
    config_sub = config.add_subparsers(dest="config_command", required=True)
    reference = config_sub.add_parser(
        "reference", help="the reference page of every run-config setting (docs/config.md)",
        description="Render the run config's reference page from the config models: one section per top-level "
                    "section, a table per model (dotted key, type, default, description).")
    reference.add_argument("--output", default=None, help="write the page here (default: print it)")
    reference.add_argument("--check", action="store_true",
                           help="exit 1 naming each setting without a description and a page at --output "
                                "(default docs/config.md) that differs from the models")
    reference.set_defaults(func=_config_reference)
