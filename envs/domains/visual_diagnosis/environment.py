"""Visual-diagnosis domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process; every episode gets a fork that shares the
read-only patients and reference tables and has its own (empty) clinical records.
"""

from __future__ import annotations

import threading
from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment, DomainTaskStore, read_policy
from envs.core.paths import domain_build_dir
from envs.core.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import VisualDB
from .tools import VisualTools

NAME = "visual_diagnosis"
HERE = Path(__file__).parent
_lock = threading.Lock()
_templates: dict[Path, tuple[float, VisualDB]] = {}
_stores: dict[Path, DomainTaskStore] = {}


def _template() -> VisualDB:
    path = domain_build_dir(NAME) / "db.json"
    if not path.exists():
        raise DataFileError(f"{path}: visual_diagnosis database not built (run `hcgym data build {NAME}`)")
    stamp = path.stat().st_mtime
    with _lock:
        cached = _templates.get(path)
        if cached is None or cached[0] != stamp:
            db = VisualDB.load(path)
            db.reference_hash()
            _templates[path] = (stamp, db)
        return _templates[path][1]


@lru_cache(maxsize=1)
def _policy() -> str:
    return read_policy(HERE)


def get_environment() -> DomainEnvironment:
    tools = VisualTools(_template().fork(), domain_build_dir(NAME))
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=_policy(), toolkit=toolkit)


def _store() -> DomainTaskStore:
    build = domain_build_dir(NAME)
    with _lock:
        if build not in _stores:
            _stores[build] = DomainTaskStore(NAME, HERE, build)
        return _stores[build]


def get_tasks(split: str | None = None) -> list[Task]:
    return _store().tasks(split)


def get_splits() -> dict[str, list[str]]:
    return _store().splits()
