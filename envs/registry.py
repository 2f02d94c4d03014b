"""The domain registry: domains load lazily, and a domain that fails to import says why.

The reference implementation silently skipped domains whose import failed; here the error
names the domain and its cause.
"""

from __future__ import annotations

import importlib
from functools import lru_cache
from pathlib import Path
from types import ModuleType

from envs.core.domain import DomainEnvironment
from envs.core.task import Task

#: Where the built-in domains live: every folder here with an `environment.py` is a domain, named
#: after its folder (its `build.py`, if any, is its data builder: `envs.data.build`).
DOMAINS_DIR = Path(__file__).resolve().parent / "domains"


def discover_domains(root: Path = DOMAINS_DIR, package: str = "envs.domains") -> dict[str, str]:
    """{domain name: environment module} for every folder of `root` with an `environment.py`, by name."""
    return {path.parent.name: f"{package}.{path.parent.name}.environment"
            for path in sorted(root.glob("*/environment.py")) if not path.parent.name.startswith(("_", "."))}


DOMAINS: dict[str, str] = discover_domains()


class DomainLoadError(ImportError):
    """A registered domain failed to import or build its environment."""


def list_domains() -> list[str]:
    return list(DOMAINS)


@lru_cache(maxsize=None)
def domain_module(name: str) -> ModuleType:
    if name not in DOMAINS:
        raise KeyError(f"unknown domain {name!r}; registered domains: {', '.join(DOMAINS)}")
    try:
        return importlib.import_module(DOMAINS[name])
    except Exception as exc:  # name the domain and keep the cause chained
        raise DomainLoadError(f"domain {name!r} failed to import ({DOMAINS[name]}): {type(exc).__name__}: {exc}") from exc


def get_environment(name: str) -> DomainEnvironment:
    return domain_module(name).get_environment()


def get_tasks(name: str, split: str | None = None) -> list[Task]:
    return domain_module(name).get_tasks(split)


def get_splits(name: str) -> dict[str, list[str]]:
    """{split name: [task ids]} of a domain (`get_splits()` of its environment module)."""
    module = domain_module(name)
    if hasattr(module, "get_splits"):
        return module.get_splits()
    return {split: [t.id for t in get_tasks(name, split)] for split in ("train", "test")}
