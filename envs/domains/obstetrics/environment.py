"""Obstetrics domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process; every episode gets a fork that shares the
read-only reference tables and has its own copy of the episode state.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import ObstetricsDB
from .safety import ObstetricsSafetyContext
from .tools import ObstetricsTools

NAME = "obstetrics"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, ObstetricsDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def get_environment() -> DomainEnvironment:
    tools = ObstetricsTools(DOMAIN.episode_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit,
                             safety_context=ObstetricsSafetyContext(lambda: tools.db))
