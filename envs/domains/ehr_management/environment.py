"""Entry point of the EHR management domain: a fresh database and toolkit per episode.

The built `db.json` (authored ICU patients and Synthea timelines) is indexed once per process
(`store.PatientStore`: byte offsets per patient). An episode's database starts empty; on reset
(`open_chart`) it receives a fresh copy of the task's patient only: the chart under care. Tasks
imported from MIMIC-III / eICU extracts (`envs.converters.ehr`) carry their patient in
`task.metadata["ehr_patient"]`, which `open_chart` validates and inserts instead. Other charts
are readable through the tools without entering the episode state (see `EHRTools`).
"""

from __future__ import annotations

from pathlib import Path

from envs.core.db import DataFileError
from envs.core.domain import BuiltDomain, DomainEnvironment
from envs.core.paths import domain_build_dir
from envs.shared import shared_toolkits
from envs.core.task import Task
from envs.core.tools import CompositeToolkit

from .data_model import EHRDB, EHRPatient
from .safety import EHRSafetyContext
from .store import PatientStore, patient_store
from .tools import EHRTools

NAME = "ehr_management"
# Policy, tasks and splits; the episode database comes from the indexed `PatientStore` instead of
# `DOMAIN.episode_db()` (a full copy of ~2,700 charts per episode would dominate reset).
DOMAIN = BuiltDomain(NAME, Path(__file__).parent, EHRDB)
get_tasks = DOMAIN.get_tasks
get_splits = DOMAIN.get_splits
#: Where an imported task carries its patient record (an `EHRPatient` as a dict).
IMPORTED_PATIENT_KEY = "ehr_patient"


def database_path() -> Path:
    return domain_build_dir(NAME) / "db.json"


def store() -> PatientStore:
    return patient_store(database_path())


def task_patient(task: Task) -> EHRPatient | None:
    """The patient record an imported task carries, validated (None when the task carries none)."""
    record = task.metadata.get(IMPORTED_PATIENT_KEY) if isinstance(task.metadata, dict) else None
    if record is None:
        return None
    try:
        return EHRPatient.model_validate(record)
    except ValueError as exc:
        raise DataFileError(f"task {task.id!r}: metadata[{IMPORTED_PATIENT_KEY!r}] is not a valid EHR patient: {exc}") from None


def open_chart(env: DomainEnvironment, task: Task) -> None:
    """Put the task's patient into the episode database: the record an imported task carries, else
    a fresh copy from the built database. Keeps WRITE snapshots small and makes
    `expected_db_hash` depend on that chart only."""
    tools: EHRTools = env.extras["ehr_tools"]
    patient = task_patient(task)
    if patient is None and task.patient_id and tools.store is not None and task.patient_id in tools.store:
        patient = tools.store.load(task.patient_id)
    if patient is not None:
        tools.db.patients[patient.patient_id] = patient


#: Former name of `open_chart`.
focus_on_patient = open_chart


def get_environment() -> DomainEnvironment:
    records = store()
    tools = EHRTools(records.empty_db(), records)
    toolkit = CompositeToolkit(tools, *shared_toolkits())
    return DomainEnvironment(name=NAME, policy=DOMAIN.policy(), toolkit=toolkit, on_reset=open_chart,
                             safety_context=EHRSafetyContext(tools.chart), extras={"ehr_tools": tools})
