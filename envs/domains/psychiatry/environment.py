"""Psychiatry domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process; every episode gets a fork that shares the
read-only reference tables and has its own copy of the episode state.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import PsychiatryDB
from .safety import PsychiatrySafetyContext
from .tools import PsychiatryTools

NAME = "psychiatry"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, PsychiatryDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def get_environment() -> DomainEnvironment:
    tools = PsychiatryTools(DOMAIN.episode_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit,
                             safety_context=PsychiatrySafetyContext(lambda: tools.db))
