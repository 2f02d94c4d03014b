"""Cross-domain pathway hook: put a pathway's patient into a fresh triage database.

`add_patient(domain_env, record)` validates `record` as an `EDPatient` and inserts it. The record
may also carry `encounter_time` ("YYYY-MM-DDTHH:MM"): the department clock of the encounter (the
time stamped on medications given at triage), so the pathway's phases share one timeline.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment
from envs.core.pathway import episode_database, record_label, validate_pathway_patient

from .data_model import EDPatient, TriageDB

DOMAIN = "triage_emergency"


def encounter_clock(value: Any, domain: str, patient_id: str) -> str:
    """A validated "YYYY-MM-DDTHH:MM" encounter time, or a DataFileError naming the field."""
    try:
        return datetime.strptime(str(value), "%Y-%m-%dT%H:%M").strftime("%Y-%m-%dT%H:%M")
    except ValueError:
        raise DataFileError(
            f"{domain} patient record {patient_id!r} field 'encounter_time': expected "
            f"YYYY-MM-DDTHH:MM, got {value!r}"
        ) from None


def add_patient(domain_env: DomainEnvironment, record: dict) -> str:
    """Validate `record` against the triage patient model and insert it; returns the patient id."""
    patient, clock, _ = validate_pathway_patient(DOMAIN, record, EDPatient)
    label, _ = record_label(DOMAIN, record)
    db = episode_database(DOMAIN, domain_env, TriageDB)
    if patient.patient_id in db.patients:
        raise DataFileError(f"{DOMAIN} patient record {label!r} field 'patient_id': already in the database")
    if clock is not None:
        db.clock = encounter_clock(clock, DOMAIN, label)
    db.patients[patient.patient_id] = patient
    return patient.patient_id
