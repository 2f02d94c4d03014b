"""Medical-QA domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The reference index is loaded once per process; each environment gets a fresh, small database
(the question is put into it on reset from the task the agent is shown).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from envs.core.domain import DomainEnvironment, DomainTaskStore, read_policy
from envs.core.paths import domain_build_dir
from envs.core.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit
from envs.domains.medical_qa.data_model import MedicalQADB, QAQuestion
from envs.domains.medical_qa.knowledge import load_knowledge
from envs.domains.medical_qa.tools import MedicalQATools

NAME = "medical_qa"
HERE = Path(__file__).parent
_stores: dict[Path, DomainTaskStore] = {}


@lru_cache(maxsize=4)
def _db_json(build_dir: Path) -> str:
    path = build_dir / "db.json"
    MedicalQADB.load(path)  # a clear error if the build is missing or malformed
    return path.read_text(encoding="utf-8")


@lru_cache(maxsize=1)
def _policy() -> str:
    return read_policy(HERE)


def _on_reset(env: DomainEnvironment, task: Task) -> None:
    """Put the task's question (stem and options, as shown to the agent) into the episode database."""
    env.toolkit.db.question = QAQuestion(question_id=task.id, stem=task.ticket, options=dict(task.options or {}),
                                         category=task.description.category)


def get_environment() -> DomainEnvironment:
    build = domain_build_dir(NAME)
    db = MedicalQADB.model_validate_json(_db_json(build))
    toolkit = CompositeToolkit(MedicalQATools(db, load_knowledge(str(build))), *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=_policy(), toolkit=toolkit, on_reset=_on_reset)


def _store() -> DomainTaskStore:
    build = domain_build_dir(NAME)
    if build not in _stores:
        _stores[build] = DomainTaskStore(NAME, HERE, build)
    return _stores[build]


def get_tasks(split: str | None = None) -> list[Task]:
    return _store().tasks(split)


def get_splits() -> dict[str, list[str]]:
    return _store().splits()
