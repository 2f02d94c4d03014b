"""Entry point of the EHR management domain: a fresh database and toolkit per episode."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment, DomainTaskStore, read_policy
from envs.core.paths import domain_build_dir
from envs.core.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import EHRDB
from .safety import EHRSafetyContext
from .tools import EHRTools

NAME = "ehr_management"
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


def focus_on_patient(env: DomainEnvironment, task: Task) -> None:
    """Keep only the task's patient in the episode database: the chart under care. It keeps WRITE
    snapshots small and makes `expected_db_hash` depend on that patient's record only."""
    db = env.toolkit.db
    if task.patient_id and task.patient_id in db.patients:
        env.toolkit.db = EHRDB(patients={task.patient_id: db.patients[task.patient_id]}, clock=db.clock,
                               next_order_number=db.next_order_number)


def get_environment() -> DomainEnvironment:
    db = EHRDB.model_validate_json(_db_json())
    tools = EHRTools(db)
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=_policy(), toolkit=toolkit, on_reset=focus_on_patient,
                             safety_context=EHRSafetyContext(lambda: tools.db))


def get_tasks(split: str | None = None) -> list[Task]:
    return _STORE.tasks(split)


def get_splits() -> dict[str, list[str]]:
    return _STORE.splits()
