"""The domain registry: domains load lazily, and a domain that fails to import says why.

The reference implementation silently skipped domains whose import failed; here the error
names the domain and its cause.
"""

from __future__ import annotations

import importlib
from functools import lru_cache
from types import ModuleType

from envs.core.domain import DomainEnvironment
from envs.core.task import Task

# Every domain folder under envs/domains/ with an environment.py. Add a line to register one.
DOMAINS: dict[str, str] = {
    "drug_interaction": "envs.domains.drug_interaction.environment",
    "clinical_diagnosis": "envs.domains.clinical_diagnosis.environment",
    "triage_emergency": "envs.domains.triage_emergency.environment",
    "ehr_management": "envs.domains.ehr_management.environment",
    "medical_qa": "envs.domains.medical_qa.environment",
    "psychiatry": "envs.domains.psychiatry.environment",
    "obstetrics": "envs.domains.obstetrics.environment",
    "radiology_report": "envs.domains.radiology_report.environment",
    "visual_diagnosis": "envs.domains.visual_diagnosis.environment",
    "cross_domain": "envs.domains.cross_domain.environment",
}


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
