"""Visual-diagnosis domain entry point: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process; every episode gets a fork that shares the
read-only reference tables and has its own copy of the episode state.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.core.paths import domain_build_dir
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import VisualDB
from .tools import VisualTools

NAME = "visual_diagnosis"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, VisualDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def get_environment() -> DomainEnvironment:
    tools = VisualTools(DOMAIN.episode_db(), domain_build_dir(NAME))
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit)
