"""Cross-domain pathway hook (`envs.domains.cross_domain`): put the pathway's patient into this domain's episode."""

from __future__ import annotations

from pydantic import ValidationError

from envs.core.db import DataFileError, format_validation_error
from envs.core.domain import DomainEnvironment

from .data_model import Patient


def add_patient(env: DomainEnvironment, record: dict) -> str:
    """Validate a patient record of this domain and insert it into the fresh episode database; returns its id."""
    try:
        patient = Patient.model_validate(record)
    except ValidationError as exc:
        raise DataFileError(format_validation_error(exc, source="pathway patient record (clinical_diagnosis)")) from None
    env.toolkit.db.patients[patient.patient_id] = patient
    return patient.patient_id
