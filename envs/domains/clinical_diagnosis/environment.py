"""Entry point of the clinical-diagnosis domain: `get_environment()`, `get_tasks(split)`, `get_splits()`.

The built database is parsed once per process (`BuiltDomain`); every episode gets its own copy.
"""

from __future__ import annotations

from pathlib import Path

from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.shared import shared_toolkits
from envs.core.tools import CompositeToolkit

from .data_model import ClinicalDiagnosisDB
from .safety import ClinicalDiagnosisSafetyContext
from .tools import ClinicalDiagnosisTools

NAME = "clinical_diagnosis"
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, ClinicalDiagnosisDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits


def get_environment() -> DomainEnvironment:
    tools = ClinicalDiagnosisTools(DOMAIN.episode_db())
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    # The context reads the toolkit's current database (a failed WRITE restores a snapshot object).
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit,
                             safety_context=ClinicalDiagnosisSafetyContext(lambda: tools.db))
