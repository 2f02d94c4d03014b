"""Entry point of the drug-interaction domain: `get_environment()`, `get_tasks(split)`, `get_splits()`,
and the read-only access the shared drug reference (`envs/domains/drug_reference.py`) uses.

The built database (`hcgym data build`) is parsed once per process (`BuiltDomain`); each episode
forks it: the read-only reference tables are shared, the patient state is copied.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.core.paths import domain_build_dir
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import DrugInteractionDB
from .safety import DrugInteractionSafetyContext
from .tools import DrugInteractionTools
from .translate import fold

NAME = "drug_interaction"
DOMAIN = BuiltDomain(NAME, Path(__file__).resolve().parent, DrugInteractionDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def database_path() -> Path:
    return domain_build_dir(NAME) / "db.json"


def load_db() -> DrugInteractionDB:
    """A fresh database for one episode."""
    return DOMAIN.episode_db()


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
    tools = DrugInteractionTools(load_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit,
                             safety_context=DrugInteractionSafetyContext(lambda: tools.db))
