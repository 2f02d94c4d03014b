"""Supply chain of the data build: every registry file is pinned to one wheel by exact name and
sha256, checked before anything is read from it; wheels only; and every pickle read from a package
goes through the one restricted unpickler (a crafted pickle is refused by each reader, and its code
never runs)."""

from __future__ import annotations

import bz2
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest

from envs.data import registry
from envs.data.registry import SOURCES, Archive, DataSourceError, PackageHashMismatch, PackageSource, fetch

VOCAB_MEMBER = "drug_named_entity_recognition/drug_ner_dictionary.pkl.bz2"
SMALL = SOURCES["labunits"]  # an 8 KB wheel: cheap to copy and tamper with


@pytest.fixture(scope="module")
def small_wheel() -> Path:
    """The pinned labunits wheel from the default cache (downloaded once if missing)."""
    return fetch(SMALL)


@pytest.fixture(autouse=True)
def _forget_verified(monkeypatch):
    # Files checked by another test must be checked again here.
    monkeypatch.setattr(registry, "_VERIFIED", set())


# -- pins ----------------------------------------------------------------------------------------
def test_every_source_is_pinned_to_one_wheel_and_the_cached_files_match_their_pins():
    cache = registry.package_cache_dir()
    checked = 0
    for source in SOURCES.values():
        assert source.wheel.endswith(".whl") and len(source.sha256) == 64, source
        cached = cache / source.wheel
        if cached.is_file():
            assert registry.file_sha256(cached) == source.sha256, source.name
            checked += 1
    # The builders' packages are in the cache on any machine that ran `hcgym data build`.
    assert checked >= 11 or not cache.exists(), f"only {checked} pinned wheels in {cache}"


@pytest.mark.parametrize(("wheel", "sha256", "what"), [
    ("labunits-0.2.1.tar.gz", "0" * 64, "wheel must be"),
    ("labunits-0.2.10-py3-none-any.whl", "0" * 64, "wheel must be"),
    ("labunits-0.2.1-py3-none-any.whl", "abc", "sha256 must be"),
    ("labunits-0.2.1-py3-none-any.whl", "A" * 64, "sha256 must be"),
])
def test_a_source_without_an_exact_wheel_and_hash_is_refused(wheel, sha256, what):
    with pytest.raises(ValueError, match=f"labunits==0.2.1: {what}"):
        PackageSource("labunits", "0.2.1", "MIT", wheel, sha256)


def test_an_intact_copy_in_a_cache_is_accepted(tmp_path, small_wheel):
    shutil.copy(small_wheel, tmp_path / SMALL.wheel)
    assert fetch(SMALL, tmp_path, offline=True) == tmp_path / SMALL.wheel


def test_a_tampered_cached_wheel_is_refused_naming_package_file_and_both_hashes(tmp_path, small_wheel):
    tampered = tmp_path / SMALL.wheel
    data = bytearray(small_wheel.read_bytes())
    data[len(data) // 2] ^= 0xFF
    tampered.write_bytes(bytes(data))
    actual = registry.file_sha256(tampered)
    with pytest.raises(PackageHashMismatch) as err:
        fetch(SMALL, tmp_path, offline=True)
    message = str(err.value)
    for part in ("labunits==0.2.1", str(tampered), actual, SMALL.sha256):
        assert part in message, (part, message)
    assert tampered.read_bytes() == bytes(data)  # left in place for the user to inspect and delete


def test_a_tampered_wheel_is_refused_before_it_is_opened(tmp_path, small_wheel, monkeypatch):
    tampered = tmp_path / "packages" / SMALL.wheel
    tampered.parent.mkdir()
    tampered.write_bytes(small_wheel.read_bytes() + b"appended")
    monkeypatch.setenv("HCGYM_DATA_DIR", str(tmp_path))
    opened: list[Path] = []
    monkeypatch.setattr(registry, "Archive", lambda path: opened.append(path))
    with pytest.raises(PackageHashMismatch, match="labunits==0.2.1"):
        registry.open_package(SMALL, offline=True)
    assert opened == []


def test_the_cache_is_matched_by_exact_file_name_not_by_prefix(tmp_path, small_wheel):
    # The old prefix match took `labunits-0.2.10...` (or any file starting `labunits-0.2.1`) for 0.2.1.
    shutil.copy(small_wheel, tmp_path / "labunits-0.2.10-py3-none-any.whl")
    shutil.copy(small_wheel, tmp_path / "labunits-0.2.1.tar.gz")
    assert registry.cached_archive(SMALL, tmp_path) is None
    with pytest.raises(DataSourceError, match="labunits-0.2.1-py3-none-any.whl.*not in the cache"):
        fetch(SMALL, tmp_path, offline=True)


# -- downloads: wheels only, checked before they enter the cache -----------------------------------
def _fake_pip(write: dict[str, bytes], commands: list[list[str]]):
    """Stands in for the registry: `pip download -d DIR` writes these files into DIR."""

    def run(cmd, **kwargs):
        commands.append(cmd)
        folder = Path(cmd[cmd.index("-d") + 1])
        for name, data in write.items():
            (folder / name).write_bytes(data)

        class Done:
            returncode, stdout, stderr = 0, "", ""
        return Done()
    return run


def test_a_download_asks_for_wheels_only_and_is_checked_before_it_enters_the_cache(tmp_path, small_wheel,
                                                                                    monkeypatch):
    commands: list[list[str]] = []
    monkeypatch.setattr(registry.subprocess, "run", _fake_pip({SMALL.wheel: small_wheel.read_bytes()}, commands))
    assert fetch(SMALL, tmp_path) == tmp_path / SMALL.wheel
    assert "--only-binary=:all:" in commands[0] and "--no-deps" in commands[0], commands[0]
    assert commands[0][-1] == "labunits==0.2.1"
    assert sorted(p.name for p in tmp_path.iterdir()) == [SMALL.wheel]  # the staging folder is gone


def test_a_tampered_download_never_enters_the_cache(tmp_path, small_wheel, monkeypatch):
    commands: list[list[str]] = []
    monkeypatch.setattr(registry.subprocess, "run",
                        _fake_pip({SMALL.wheel: small_wheel.read_bytes()[:-10]}, commands))
    with pytest.raises(PackageHashMismatch, match="labunits==0.2.1"):
        fetch(SMALL, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_a_download_that_is_not_the_pinned_wheel_is_an_error_naming_what_came(tmp_path, monkeypatch):
    commands: list[list[str]] = []
    monkeypatch.setattr(registry.subprocess, "run", _fake_pip({"labunits-0.2.1.tar.gz": b"sdist"}, commands))
    with pytest.raises(DataSourceError, match=r"labunits-0.2.1-py3-none-any.whl.*wheels only.*labunits-0.2.1.tar.gz"):
        fetch(SMALL, tmp_path)
    assert list(tmp_path.iterdir()) == []


# -- pickles from packages -------------------------------------------------------------------------
class _RunsCode:
    """A pickle that calls os.system on load, as a crafted package file would."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        import os

        return (os.system, (f"touch {self.marker}",))


def _package_with_vocabulary(path: Path, vocabulary: object) -> Archive:
    with zipfile.ZipFile(path, "w") as wheel:
        wheel.writestr(VOCAB_MEMBER, bz2.compress(pickle.dumps(vocabulary)))
    return Archive(path)


def _readers():
    from envs.data.reference_parsers import load_drug_vocabulary
    from envs.domains.drug_interaction.ingest import read_vocabulary
    from kb_service.sources.drugs import load_vocabulary

    return {"medical_qa.reference": load_drug_vocabulary, "drug_interaction.ingest": read_vocabulary,
            "kb_service.sources.drugs": load_vocabulary}


@pytest.mark.parametrize("reader", ["medical_qa.reference", "drug_interaction.ingest", "kb_service.sources.drugs"])
def test_a_crafted_pickle_in_a_package_is_refused_by_every_reader_and_runs_nothing(tmp_path, reader):
    marker = tmp_path / "pwned"
    vocabulary = {"drug_variant_to_canonical": {"x": ["x"]}, "drug_canonical_to_data": {"x": _RunsCode(marker)},
                  "drug_variant_to_variant_data": {}}
    refused = pytest.raises(DataSourceError, match=r"evil-1\.0-py3-none-any\.whl:.*drug_ner_dictionary.*system")
    with _package_with_vocabulary(tmp_path / "evil-1.0-py3-none-any.whl", vocabulary) as archive, refused:
        _readers()[reader](archive)
    assert not marker.exists()


@pytest.mark.parametrize("reader", ["medical_qa.reference", "drug_interaction.ingest", "kb_service.sources.drugs"])
def test_a_plain_vocabulary_pickle_reads_through_every_reader(tmp_path, reader):
    vocabulary = {"drug_variant_to_canonical": {"coumadin": ["warfarin"]},
                  "drug_canonical_to_data": {"warfarin": {"name": "Warfarin", "synonyms": {"coumadin"}}},
                  "drug_variant_to_variant_data": {"coumadin": {"is_brand": True}}}
    with _package_with_vocabulary(tmp_path / "plain-1.0-py3-none-any.whl", vocabulary) as archive:
        result = _readers()[reader](archive)
    if reader == "drug_interaction.ingest":
        assert result.lookup["warfarin"] == "warfarin" and "coumadin" in result.brands
    else:
        assert result == vocabulary


def test_a_damaged_compressed_member_is_a_data_source_error_naming_it(tmp_path):
    path = tmp_path / "broken-1.0-py3-none-any.whl"
    with zipfile.ZipFile(path, "w") as wheel:
        wheel.writestr(VOCAB_MEMBER, b"not bz2 at all")
    with Archive(path) as archive, pytest.raises(DataSourceError, match=r"broken-1\.0.*drug_ner_dictionary.*bz2"):
        archive.read_pickle(VOCAB_MEMBER)
