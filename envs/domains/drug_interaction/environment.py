"""Entry point of the drug-interaction domain: a fresh database and toolkit per episode, and its tasks.

The built database (`hcgym data build`) is parsed once per process; each `get_environment()`
forks it: the read-only reference tables are shared, the patient state is copied.
"""

from __future__ import annotations

import threading
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment, DomainTaskStore, read_policy
from envs.core.paths import domain_build_dir
from envs.core.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import DrugInteractionDB
from .safety import DrugInteractionSafetyContext
from .tools import DrugInteractionTools
from .translate import fold

NAME = "drug_interaction"
HERE = Path(__file__).resolve().parent

_lock = threading.Lock()
_template: tuple[Path, float, DrugInteractionDB, bytes] | None = None
_policy: str | None = None
_stores: dict[Path, DomainTaskStore] = {}


def database_path() -> Path:
    return domain_build_dir(NAME) / "db.json"


def _template_db() -> tuple[DrugInteractionDB, bytes]:
    """The parsed database and its initial state JSON, reloaded only when the file (or
    HCGYM_DATA_DIR) changes. The template itself is never handed out, only forks of it."""
    global _template
    path = database_path()
    if not path.exists():
        raise DataFileError(f"{path}: drug_interaction database not built; run `hcgym data build`")
    stamp = path.stat().st_mtime
    with _lock:
        if _template is None or _template[0] != path or _template[1] != stamp:
            db = DrugInteractionDB.load(path)
            db.reference_hash()
            _template = (path, stamp, db, db.state_json())
        return _template[2], _template[3]


def load_db() -> DrugInteractionDB:
    """A fresh database for one episode."""
    template, state = _template_db()
    return template.with_state(state)


def drug_reference_source() -> tuple[DrugInteractionDB, DrugInteractionSafetyContext]:
    """A database fork (used read-only) and this domain's safety context over it: what the shared drug
    reference (`envs/domains/drug_reference.py`) reads, through `envs.registry`, to answer drug facts
    for other domains. Raises `DataFileError` when the database is not built."""
    db = load_db()
    return db, DrugInteractionSafetyContext(lambda: db)


def drug_name_key(name: str) -> str:
    """The key of `DrugInteractionDB.name_index` for a drug name (the folding the build indexed with)."""
    return fold(name)


def get_environment() -> DomainEnvironment:
    global _policy
    if _policy is None:
        _policy = read_policy(HERE)
    tools = DrugInteractionTools(load_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=_policy, toolkit=toolkit,
                             safety_context=DrugInteractionSafetyContext(lambda: tools.db))


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
