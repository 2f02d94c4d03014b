"""Entry point of the clinical-diagnosis domain: a fresh database and toolkit per episode."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment, DomainTaskStore, read_policy
from envs.core.paths import domain_build_dir
from envs.core.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import ClinicalDiagnosisDB
from .safety import ClinicalDiagnosisSafetyContext
from .tools import ClinicalDiagnosisTools

NAME = "clinical_diagnosis"
HERE = Path(__file__).parent


@lru_cache(maxsize=1)
def _db_json() -> str:
    path = domain_build_dir(NAME) / "db.json"
    if not path.exists():
        raise DataFileError(f"{path}: database not built (run `hcgym data build {NAME}`)")
    return path.read_text(encoding="utf-8")


@lru_cache(maxsize=1)
def _policy() -> str:
    return read_policy(HERE)


_STORE = DomainTaskStore(NAME, HERE, domain_build_dir(NAME))


def get_environment() -> DomainEnvironment:
    db = ClinicalDiagnosisDB.model_validate_json(_db_json())
    tools = ClinicalDiagnosisTools(db)
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    # The context reads the toolkit's current database (a failed WRITE restores a snapshot object).
    return DomainEnvironment(name=NAME, policy=_policy(), toolkit=toolkit,
                             safety_context=ClinicalDiagnosisSafetyContext(lambda: tools.db))


def get_tasks(split: str | None = None) -> list[Task]:
    return _STORE.tasks(split)


def get_splits() -> dict[str, list[str]]:
    return _STORE.splits()
