"""Build the obstetrics database and generated tasks under `domain_build_dir("obstetrics")`.

    build(offline=False, force=False) -> dict

Inputs: our synthetic patients (`generate.py`, seeded; CTG series synthesised and checked against
the interpreter), our authored patients (`patients_authored.json`), the authored obstetric
formulary (`formulary.json`) with maximum single doses from the drugdose package where it lists
the drug. Deterministic; skipped when the manifest of inputs is unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path

from envs import coherence
from envs.core import splits as split_helpers
from envs.core.domain import inputs_fingerprint, skip_if_built, write_manifest, write_task_dicts
from envs.core.paths import domain_build_dir
from envs.data.registry import SOURCES, open_package
from envs.domains.obstetrics import generate as G
from envs.domains.obstetrics.data_model import DrugInteraction, ObstetricDrug, ObstetricsDB, Patient

HERE = Path(__file__).parent
NAME = "obstetrics"
SEED = 4411
PACKAGES = ["drugdose"]
SPLIT_SIZES = {"validation": 6, "test": 26}


def _fingerprint() -> str:
    files = [HERE / name for name in ("build.py", "generate.py", "ctg.py", "rules.py", "data_model.py", "formulary.json",
                                      "patients_authored.json")]
    # the shared split assignment, and the shared tables the generator draws from (symptom words)
    shared = [Path(split_helpers.__file__), Path(coherence.__file__)]
    return inputs_fingerprint(files + shared, *(f"{p}=={SOURCES[p].version}" for p in PACKAGES))


def _formulary(offline: bool) -> dict[str, ObstetricDrug]:
    spec = json.loads((HERE / "formulary.json").read_text(encoding="utf-8"))["drugs"]
    archive = open_package(SOURCES["drugdose"], offline=offline)
    dose = {d["name"]: d for d in json.loads(archive.read_text("drugdose/data/drugs.json"))}
    out = {}
    for key, s in sorted(spec.items()):
        source = {"source": "authored (ACOG practice bulletins, labelling)"}
        max_mg = s["max_single_dose_mg"]
        ref = dose.get(s["drugdose_name"] or "")
        if ref is not None:
            caps = [r.get("max_single_dose_mg") for r in ref["routes"] if r["route"] in s["routes"] and r.get("max_single_dose_mg")]
            if caps:
                max_mg = max(caps)
                source = {**SOURCES["drugdose"].provenance, "record": ref["name"], "usual_dose": "authored"}
        out[key] = ObstetricDrug(name=s["name"], routes=s["routes"], usual_dose=s["usual_dose"], max_single_dose_mg=max_mg,
                                 indications=s["indications"], contraindications=s["contraindications"], source=source)
    return out


def build(offline: bool = False, force: bool = False) -> dict:
    out = domain_build_dir(NAME)
    fingerprint = _fingerprint()
    if (done := skip_if_built(out, fingerprint, force)) is not None:
        return done
    patients, tasks = G.generate(SEED)
    authored = [Patient.model_validate(p) for p in json.loads((HERE / "patients_authored.json").read_text(encoding="utf-8"))]
    all_patients = {p.patient_id: p for p in [*patients, *authored]}
    if len(all_patients) != len(patients) + len(authored):
        raise ValueError("obstetrics: duplicate patient ids between generated and authored patients")
    interactions = [DrugInteraction(**i) for i in json.loads((HERE / "formulary.json").read_text(encoding="utf-8"))["interactions"]]
    db = ObstetricsDB(today=G.TODAY.isoformat(), patients=all_patients, formulary=_formulary(offline), interactions=interactions)
    db.dump(out / "db.json")
    splits = split_helpers.round_robin_type_splits(tasks, SPLIT_SIZES, SEED, NAME)
    summary = {"patients": len(all_patients), **write_task_dicts(out, tasks, splits)}
    write_manifest(out, fingerprint, summary, ["db.json", "tasks.json", "split_tasks.json"],
                   packages={p: SOURCES[p].provenance for p in PACKAGES})
    return summary
