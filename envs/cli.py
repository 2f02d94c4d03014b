"""The `hcgym` command line.

Subcommands live next to the code they drive: each package may define `cli.register(subparsers)`
(see COMMAND_MODULES); this module only assembles them.
"""

from __future__ import annotations

import argparse
import importlib
import sys

import envs  # noqa: F401  (runtime defaults, env registration)

COMMAND_MODULES = [
    "envs.cli_commands",
    "kb_service.cli",
    "learner.cli",
    "evals.cli",
    "viewer.cli",
    "envs.serve.cli",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hcgym", description="Healthcare AI GYM command line.")
    sub = parser.add_subparsers(dest="command", required=True)
    for module_name in COMMAND_MODULES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:  # that package has no commands yet
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (ValueError, LookupError, RuntimeError, OSError) as exc:
        print(f"hcgym {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
