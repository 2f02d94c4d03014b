"""The `hcgym train` / `python -m learner.train` arguments and the run config they make.

Kept apart from learner/train.py so that building the `hcgym` parser (every command, `hcgym tasks list`
included) does not import torch, Ray and the actors the driver needs.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable

from learner.config import RunConfig, load_config

DESCRIPTION = "The training driver: wires the actors from a `RunConfig` and runs GRPO / TT-OPD."


def build_arg_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="python -m learner.train", description=DESCRIPTION)
    parser.add_argument("--config", required=True, help="run config YAML (see configs/)")
    parser.add_argument("--max-steps", type=int, default=None, help="override trainer.max_steps")
    parser.add_argument("--output-dir", default=None, help="override output_dir (the run directory)")
    parser.add_argument("--resume", action="store_true", help="continue from the run directory's latest checkpoint")
    parser.add_argument("--seed", type=int, default=None, help="override seed")
    parser.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                        help="override any config key (repeatable)")
    parser.add_argument("--cpu-twin", action="store_true",
                        help="rehearse a GPU cluster config on this CPU machine: the model's tiny twin, CPU devices, "
                             "gloo, scaled lengths and batches, every other key as shipped (learner/cpu_twin.py "
                             "lists each override and its reason); the run folder gets a _cpu_twin suffix unless "
                             "--output-dir is given")
    return parser


def config_from_args(args: argparse.Namespace, log: Callable[[str], None] = print) -> RunConfig:
    overrides = list(args.set)
    if args.max_steps is not None:
        overrides.append(f"trainer.max_steps={args.max_steps}")
    if args.output_dir is not None:
        overrides.append(f"output_dir={args.output_dir}")
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    cfg = load_config(args.config, overrides)
    if getattr(args, "cpu_twin", False):
        from learner import cpu_twin

        output = Path(args.output_dir if args.output_dir is not None else cfg.output_dir.rstrip("/") + "_cpu_twin")
        model_dir = cpu_twin.build_cpu_twin_model(cfg, output.parent / ".cpu_twin_models" / cfg.name, log=log)
        cfg = cpu_twin.twin_config(cfg, model_dir, output_dir=output, source=f"{args.config} (--cpu-twin)")
        if args.max_steps is not None:  # the user's step count wins over the rehearsal's
            cfg = cfg.model_copy(update={"trainer": cfg.trainer.model_copy(update={"max_steps": args.max_steps})})
        log(f"[cpu twin] {args.config} with these overrides (every other key as shipped):\n{cpu_twin.describe()}")
    return cfg
