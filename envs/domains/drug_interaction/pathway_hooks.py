"""Cross-domain pathway hook: put a pathway's patient into a fresh drug-interaction database.

The record is written the way `patients.json` is (medications and substance allergies by generic
or brand name, class allergies by ANSM class name); `add_patient` resolves every name against the
database (`logic.resolve_drug` / `logic.resolve_class`), validates the result as a
drug-interaction `Patient` and inserts it. An unknown drug or class is an error naming the field.

    {"patient_id": "PW-CP01", "name": "...", "age": 61, "sex": "male", "weight_kg": 84,
     "serum_creatinine_mg_dl": 1.0, "conditions": ["hypertension"],
     "allergies": [{"allergen": "penicillins", "kind": "class", "reaction": "...", "severity": "severe"}],
     "medications": [{"drug": "amlodipine", "dose": 5, "unit": "mg", "route": "PO", "frequency": "once daily"}]}
"""

from __future__ import annotations

from pydantic import ValidationError

from envs.core.db import DataFileError, format_validation_error
from envs.core.domain import DomainEnvironment
from envs.core.pathway import episode_database, pathway_record, record_label

from . import logic as L
from .data_model import Allergy, DrugInteractionDB, MedicationOrder, Patient, Provenance

DOMAIN = "drug_interaction"
PATHWAY_PROVENANCE = Provenance(
    package="authored",
    version="1",
    license="project (synthetic, authored by the Healthcare AI GYM team)",
    file="envs/domains/cross_domain/pathways.json",
)


def add_patient(domain_env: DomainEnvironment, record: dict) -> str:
    """Resolve, validate and insert a pathway patient; returns the patient id (upper case, as the
    domain's tools look patients up)."""
    record = pathway_record(DOMAIN, record)
    db = episode_database(DOMAIN, domain_env, DrugInteractionDB)
    label, where = record_label(DOMAIN, record)
    fields = {k: v for k, v in record.items() if k not in ("medications", "allergies", "provenance")}
    medications, allergies = [], []
    for i, med in enumerate(record.get("medications") or []):
        if not isinstance(med, dict) or not isinstance(med.get("drug"), str):
            raise DataFileError(f"{where} field 'medications.{i}.drug': a drug name is required")
        try:
            drug = L.resolve_drug(db, med["drug"])
        except L.LookupFailure as exc:
            raise DataFileError(f"{where} field 'medications.{i}.drug': {exc}") from None
        try:
            medications.append(
                MedicationOrder(
                    drug_id=drug.id, **{k: v for k, v in med.items() if k not in ("drug", "drug_id")}
                )
            )
        except ValidationError as exc:
            raise DataFileError(format_validation_error(exc, source=where, item=f"medications.{i}")) from None
    for i, allergy in enumerate(record.get("allergies") or []):
        if not isinstance(allergy, dict) or not isinstance(allergy.get("allergen"), str):
            raise DataFileError(f"{where} field 'allergies.{i}.allergen': an allergen name is required")
        kind = allergy.get("kind")
        try:
            if kind == "class":
                ids = {"class_id": L.resolve_class(db, allergy["allergen"]).id}
            elif kind == "substance":
                ids = {"drug_id": L.resolve_drug(db, allergy["allergen"]).id}
            else:
                raise DataFileError(
                    f"{where} field 'allergies.{i}.kind': 'substance' or 'class', got {kind!r}"
                )
        except L.LookupFailure as exc:
            raise DataFileError(f"{where} field 'allergies.{i}.allergen': {exc}") from None
        try:
            allergies.append(
                Allergy(**{k: v for k, v in allergy.items() if k not in ("drug_id", "class_id")}, **ids)
            )
        except ValidationError as exc:
            raise DataFileError(format_validation_error(exc, source=where, item=f"allergies.{i}")) from None
    fields["patient_id"] = str(fields.get("patient_id", "")).strip().upper() or None
    try:
        patient = Patient.model_validate(
            {
                **fields,
                "medications": medications,
                "allergies": allergies,
                "provenance": [PATHWAY_PROVENANCE.model_copy(update={"record": label})],
            }
        )
    except ValidationError as exc:
        raise DataFileError(
            format_validation_error(exc, source=f"{DOMAIN} patient record", item=label)
        ) from None
    if patient.patient_id in db.patients:
        raise DataFileError(f"{where} field 'patient_id': already in the database")
    db.patients[patient.patient_id] = patient
    return patient.patient_id
