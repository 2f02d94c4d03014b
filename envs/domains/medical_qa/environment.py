"""Medical-QA domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process (`BuiltDomain`) and the reference index loaded once;
each environment gets a fresh, small database (the question is put into it on reset from the task
the agent is shown).
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.core.paths import domain_build_dir
from envs.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import MedicalQADB, QAQuestion
from .knowledge import load_knowledge
from .tools import MedicalQATools

NAME = "medical_qa"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, MedicalQADB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def _on_reset(env: DomainEnvironment, task: Task) -> None:
    """Put the task's question (stem and options, as shown to the agent) into the episode database."""
    env.toolkit.db.question = QAQuestion(question_id=task.id, stem=task.ticket, options=dict(task.options or {}),
                                         category=task.description.category)


def get_environment() -> DomainEnvironment:
    db = DOMAIN.episode_db()
    toolkit = CompositeToolkit(MedicalQATools(db, load_knowledge(str(domain_build_dir(NAME)))), *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit, on_reset=_on_reset)
