"""Entry point of the triage and emergency domain: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process (`BuiltDomain`); every episode gets its own copy.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import TriageDB
from .safety import TriageSafetyContext
from .tools import TriageTools

NAME = "triage_emergency"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, TriageDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def get_environment() -> DomainEnvironment:
    tools = TriageTools(DOMAIN.episode_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit,
                             safety_context=TriageSafetyContext(lambda: tools.db))
