"""Checks of a run config beyond the models' own rules.

Pydantic's lax mode turns `true` and `"3"` into numbers and takes NaN and infinity; the number
checks refuse those with the key path. The reference checks refuse domains, splits and (for a run
on this machine) local paths that do not exist.
"""

from __future__ import annotations

import math
import os
import types
import typing
from pathlib import Path
from typing import Any, Literal, Union

from pydantic import BaseModel

from learner.config.schema import RunConfig

# ---------------------------------------------------------------------------------------------
# Checks pydantic's lax mode does not make: booleans and strings as numbers, non-finite numbers
# ---------------------------------------------------------------------------------------------


def _scalar_kinds(annotation: Any) -> set[type]:
    """The scalar types (int, float, bool, str) a field annotation accepts; Literal[1, 2] counts as int."""
    origin = typing.get_origin(annotation)
    if origin in (Union, types.UnionType):
        return set().union(*(_scalar_kinds(a) for a in typing.get_args(annotation)))
    if origin is Literal:
        return {type(v) for v in typing.get_args(annotation)}
    if annotation is Any:
        return {int, float, bool, str}
    return {annotation} if annotation in (int, float, bool, str) else set()


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model a field holds (`Model` or `Model | None`), else None."""
    candidates = typing.get_args(annotation) if typing.get_origin(annotation) in (Union, types.UnionType) else (annotation,)
    for candidate in candidates:
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def _number_problems(annotation: Any, value: Any, path: str) -> list[str]:
    """`path: problem` for a boolean or string given where a number is expected, and for NaN or
    infinity anywhere a number is expected, descending into sections, lists and mappings."""
    model = _model_of(annotation)
    if model is not None:
        if not isinstance(value, dict):
            return []  # pydantic names the wrong type
        problems: list[str] = []
        for key, item in value.items():
            field = model.model_fields.get(key) if isinstance(key, str) else None
            if field is not None:  # unknown keys: pydantic reports them
                problems += _number_problems(field.annotation, item, f"{path}.{key}" if path else key)
        return problems
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is dict and isinstance(value, dict) and len(args) == 2:
        return [p for key, item in value.items() for p in _number_problems(args[1], item, f"{path}.{key}")]
    if origin in (list, tuple) and isinstance(value, (list, tuple)) and args:
        fixed = origin is tuple and not (len(args) == 2 and args[1] is Ellipsis)
        problems = []
        for index, item in enumerate(value):
            if fixed and index >= len(args):
                break  # pydantic names the wrong length
            problems += _number_problems(args[index] if fixed else args[0], item, f"{path}[{index}]")
        return problems
    # Annotated[float, Field(...)] inside a tuple: the metadata is not a type, the first arg is.
    if origin is typing.Annotated:
        return _number_problems(args[0], value, path)
    kinds = _scalar_kinds(annotation)
    numeric = bool(kinds & {int, float})
    if isinstance(value, bool):
        if numeric and bool not in kinds:
            wanted = "an integer" if float not in kinds else "a number"
            return [f"{path}: expected {wanted}, got a boolean ({str(value).lower()})"]
    elif isinstance(value, float) and not math.isfinite(value):
        if numeric:
            return [f"{path}: must be a finite number (got {value})"]
    elif isinstance(value, str) and numeric and str not in kinds:
        return [f"{path}: expected a number, got the string {value[:60]!r} (write it without quotes)"]
    return []


# ---------------------------------------------------------------------------------------------
# References: domains, splits and local paths the config names
# ---------------------------------------------------------------------------------------------


def _runs_locally(cfg: RunConfig) -> bool:
    """True when the driver starts its own Ray cluster on this machine. Configs for a remote
    cluster name paths on its nodes (`~/.venv-vllm/bin/python`), which need not exist here."""
    return cfg.ray.address in (None, "local") and not (cfg.ray.address is None and os.environ.get("RAY_ADDRESS"))


def _domain_splits(name: str, module_path: str | None) -> set[str] | None:
    """The split names a domain declares, or None when they cannot be known yet (data not built).

    Raises:
        ImportError: the domain's module fails to import.
    """
    import importlib

    from envs import registry
    from envs.core.db import DataFileError

    module = importlib.import_module(module_path) if module_path else registry.domain_module(name)
    if not hasattr(module, "get_splits"):
        return None
    try:
        return set(module.get_splits())
    except (DataFileError, FileNotFoundError):
        return None  # not built yet: loading the tasks reports it, naming the files


def _reference_problems(cfg: RunConfig) -> list[str]:
    """`key.path: problem` for every domain, split or local path the config names that does not exist."""
    import importlib.util

    from envs import registry

    problems: list[str] = []
    data = cfg.data
    for name, module in data.domain_modules.items():
        registered = registry.DOMAINS.get(name)
        if registered is not None and registered != module:
            problems.append(f"data.domain_modules.{name}: {name!r} is already the registered domain module "
                            f"{registered!r}, not {module!r}")
            continue
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            problems.append(f"data.domain_modules.{name}: module {module!r} not found")
    splits_needed = [("data.train_split", data.train_split)]
    if cfg.trainer.val_interval or cfg.trainer.val_at_start:
        splits_needed.append(("data.val_split", data.val_split))
    for index, name in enumerate(data.domains):
        key = f"data.domains[{index}]"
        if name in data.domain_modules:
            if any(p.startswith(f"data.domain_modules.{name}:") for p in problems):
                continue
            module_path = data.domain_modules[name]
        elif name in registry.DOMAINS:
            module_path = None
        else:
            problems.append(f"{key}: unknown domain {name!r}; registered domains: {', '.join(registry.list_domains())} "
                            f"(or map it to its module in data.domain_modules)")
            continue
        try:
            declared = _domain_splits(name, module_path)
        except Exception as exc:  # ImportError, DomainLoadError, a domain module's own failure
            problems.append(f"{key}: domain {name!r} failed to load: {type(exc).__name__}: {str(exc)[:300]}")
            continue
        for split_key, split in splits_needed:
            if declared is not None and split not in declared:
                problems.append(f"{split_key}: domain {name!r} has no split {split!r} (it has: {', '.join(sorted(declared))})")
    if _runs_locally(cfg):
        problems += _local_path_problems(cfg)
    return problems


def _local_path_problems(cfg: RunConfig) -> list[str]:
    problems = []
    model = cfg.model
    if model.kind == "pretrained" and model.path:
        from modeling.hf_checkpoint import is_hub_id

        local = Path(model.path).expanduser()
        if local.exists():
            if not (local / "config.json").is_file():
                problems.append(f"model.path: {model.path!r} has no config.json (not a Hugging Face checkpoint folder)")
        elif not is_hub_id(model.path):
            problems.append(f"model.path: {model.path!r} does not exist and is not a hub id of the form 'org/name'")
        # A hub id is resolved in the cache when the run starts (`hcgym model fetch ID` fills it).
    reference = cfg.learner.reference_model_dir
    if reference is not None and not (Path(reference).expanduser() / "config.json").is_file():
        problems.append(f"learner.reference_model_dir: {reference!r} is not a checkpoint folder with a config.json")
    if cfg.kb.path is not None and not Path(cfg.kb.path).expanduser().is_dir():
        problems.append(f"kb.path: {cfg.kb.path!r} is not a directory (build one with `hcgym kb build`)")
    elif cfg.kb.service and cfg.kb.shards.actors:
        from kb_service.kb import KBError, default_kb_path
        from kb_service.shard_actors import ShardLayoutError, shard_groups

        kb_path = Path(cfg.kb.path).expanduser() if cfg.kb.path is not None else default_kb_path()
        if (kb_path / "manifest.json").is_file():  # a KB not built yet is reported when the service starts
            try:
                shard_groups(kb_path, cfg.kb.shards.actors)
            except (KBError, ShardLayoutError) as exc:
                problems.append(f"kb.shards.actors: {exc}")
    python = cfg.generator.python_executable
    if python not in (None, "auto"):
        path = Path(python).expanduser()
        if not (path.is_file() and os.access(path, os.X_OK)):
            problems.append(f"generator.python_executable: {python!r} is not an executable file")
    output = Path(cfg.output_dir).expanduser()
    if output.exists() and not output.is_dir():
        problems.append(f"output_dir: {cfg.output_dir!r} exists and is not a directory")
    return problems
