"""Cross-domain pathway hook: put a pathway's patient chart into a fresh EHR database.

`add_patient(domain_env, record)` validates `record` as an `EHRPatient` (with its admissions,
ICU stays, timestamped lab and vital-sign events and medication orders) and opens it in the
episode database, the way `open_chart` opens a task's patient. The record may carry
`encounter_time` ("YYYY-MM-DDTHH:MM"): the record clock (time stamped on orders, notes and
escalations); it must not precede the last charted event.
"""

from __future__ import annotations

from datetime import datetime

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment
from envs.core.pathway import episode_database, validate_pathway_patient

from .data_model import EHRDB, EHRPatient

DOMAIN = "ehr_management"


def _time(value: str, where: str, field: str) -> str:
    try:
        return datetime.strptime(str(value)[:16], "%Y-%m-%dT%H:%M").strftime("%Y-%m-%dT%H:%M")
    except ValueError:
        raise DataFileError(f"{where} field {field!r}: expected YYYY-MM-DDTHH:MM, got {value!r}") from None


def add_patient(domain_env: DomainEnvironment, record: dict) -> str:
    """Validate `record` against the EHR patient model and insert it; returns the patient id."""
    patient, clock, where = validate_pathway_patient(DOMAIN, record, EHRPatient)
    last = ""
    for a, adm in enumerate(patient.admissions):  # the tools parse every event time: check them now
        _time(adm.admit_time, where, f"admissions.{a}.admit_time")
        for kind in ("lab_events", "vital_events", "medication_orders"):
            for e, event in enumerate(getattr(adm, kind)):
                stamp = _time(
                    getattr(event, "start" if kind == "medication_orders" else "time"),
                    where,
                    f"admissions.{a}.{kind}.{e}",
                )
                last = max(last, stamp)
    db = episode_database(DOMAIN, domain_env, EHRDB)
    if patient.patient_id in db.patients:
        raise DataFileError(f"{where} field 'patient_id': already in the database")
    if clock is not None:
        clock = _time(clock, where, "encounter_time")
        if clock < last:
            raise DataFileError(
                f"{where} field 'encounter_time': {clock} precedes the last charted event ({last})"
            )
        db.clock = clock
    db.patients[patient.patient_id] = patient
    return patient.patient_id
