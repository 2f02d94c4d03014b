"""What every domain's cross-domain pathway hook (`pathway_hooks.add_patient`) does first: check the
record is an object, take its `encounter_time` (the pathway's clock), validate the rest as the
domain's patient model, and check the episode's database is the domain's own."""

from __future__ import annotations

from typing import Any, NamedTuple, TypeVar

from pydantic import BaseModel, ValidationError

from envs.core.db import DataFileError, format_validation_error

Model = TypeVar("Model", bound=BaseModel)
Database = TypeVar("Database")


class PathwayPatient(NamedTuple):
    patient: Any            # the validated patient model
    clock: Any              # the record's `encounter_time`, None without one
    where: str              # "<domain> patient record [<id>]", how errors name the record


def pathway_record(domain: str, record: Any) -> dict[str, Any]:
    """`record` as a dict copy; anything but an object is a `DataFileError` naming the domain."""
    if not isinstance(record, dict):
        raise DataFileError(f"{domain} patient record: expected an object, got {type(record).__name__}")
    return dict(record)


def record_label(domain: str, record: dict[str, Any]) -> tuple[str, str]:
    """(patient id or "<no patient_id>", "<domain> patient record [<id>]") for error messages."""
    label = str(record.get("patient_id") or "<no patient_id>")
    return label, f"{domain} patient record [{label}]"


def validate_pathway_patient(domain: str, record: Any, model: type[Model]) -> PathwayPatient:
    """The record's `encounter_time` taken out and the rest validated as `model`; a field error is a
    `DataFileError` naming the domain, the patient id and the field."""
    fields = pathway_record(domain, record)
    clock = fields.pop("encounter_time", None)
    label, where = record_label(domain, fields)
    try:
        patient = model.model_validate(fields)
    except ValidationError as exc:
        raise DataFileError(format_validation_error(exc, source=f"{domain} patient record", item=label)) from None
    return PathwayPatient(patient, clock, where)


def episode_database(domain: str, domain_env: Any, database_class: type[Database]) -> Database:
    """The episode's database, which must be the domain's own (`database_class`)."""
    db = domain_env.toolkit.db
    if not isinstance(db, database_class):
        raise DataFileError(f"{domain}: the environment's database is {type(db).__name__}, not {database_class.__name__}")
    return db
