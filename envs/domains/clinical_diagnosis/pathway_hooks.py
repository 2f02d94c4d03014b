"""Cross-domain pathway hook: put a pathway's patient into a fresh clinical-diagnosis database.

`add_patient(domain_env, record)` validates `record` as a clinical-diagnosis `Patient` and
inserts it. Coded findings must name HPO terms the phenotype index knows and held-back results
must be orderable tests of the laboratory catalogue (otherwise `generate_ddx` and `order_lab`
could never reach them). The record may carry `encounter_time` ("YYYY-MM-DDTHH:MM"): the clock
from which ordered results are timed.
"""

from __future__ import annotations

from datetime import datetime

from envs.core.db import DataFileError
from envs.core.domain import DomainEnvironment
from envs.core.pathway import episode_database, validate_pathway_patient

from . import knowledge
from .data_model import ClinicalDiagnosisDB, Patient

DOMAIN = "clinical_diagnosis"


def add_patient(domain_env: DomainEnvironment, record: dict) -> str:
    """Validate `record` against the clinical-diagnosis patient model and insert it; returns the id."""
    patient, clock, where = validate_pathway_patient(DOMAIN, record, Patient)
    index = knowledge.hpo_index()
    for i, finding in enumerate(patient.findings):
        if finding.hpo_id not in index.terms:
            raise DataFileError(f"{where} field 'findings.{i}.hpo_id': {finding.hpo_id!r} is not an HPO term")
    catalog = knowledge.lab_catalog()
    for test in patient.hidden_results:
        if catalog.resolve(test) != test:
            raise DataFileError(
                f"{where} field 'hidden_results.{test}': not an orderable test key of the "
                f"laboratory catalogue"
            )
    for i, finding in enumerate(patient.findings):
        if (
            finding.requires_test is not None
            and finding.requires_test not in patient.hidden_results
            and finding.requires_test not in {r.test for r in patient.lab_results}
        ):
            raise DataFileError(
                f"{where} field 'findings.{i}.requires_test': {finding.requires_test!r} is neither "
                f"resulted nor held back for this patient"
            )
    db = episode_database(DOMAIN, domain_env, ClinicalDiagnosisDB)
    if patient.patient_id in db.patients:
        raise DataFileError(f"{where} field 'patient_id': already in the database")
    if clock is not None:
        try:
            db.clock = datetime.strptime(str(clock), "%Y-%m-%dT%H:%M").strftime("%Y-%m-%dT%H:%M")
        except ValueError:
            raise DataFileError(
                f"{where} field 'encounter_time': expected YYYY-MM-DDTHH:MM, got {clock!r}"
            ) from None
    db.patients[patient.patient_id] = patient
    return patient.patient_id
